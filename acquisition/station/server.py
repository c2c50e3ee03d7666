"""The station's HTTP face: the page, its static files, a JSON API and server-sent events.

Every request carries the session token (query ``token=`` or header ``X-Station-Token``; the
page's own files may come with the HttpOnly SameSite cookie set with the page instead); without it
the answer is 403 and nothing else is looked at. Routes:

==========================  ====================================================================
``GET /``                   the page
``GET /static/NAME``        the page's files (``plotly.min.js`` from the installed plotly)
``GET /api/state``          the small state (phase, point, counts, verdict, messages, versions)
``GET /api/blob/NAME``      plot data: ``hit``, ``frf``, ``setup``, ``geometry``
``GET /api/events``         server-sent events: ``state`` on every change, a comment every 10 s
``POST /api/lease``         ``{"client": ID, "take": bool}``: ask for (or take) control; 200 with
                            ``{"control": bool, "controller": ID}`` (false: another tab has it)
``POST /api/action``        ``{"client": ID, "action": NAME, ...}``: 409 when not possible now,
                            another tab controls, or the hit/point the action names is not the one
                            on now; 400 unknown action, malformed request, target not named
``POST /api/setup/check``   ``{"setup": {...}, "windows": {...}}``: 200 or 422 with the problem
``GET /favicon.ico``        204 (no token needed: browsers ask for it on their own)
==========================  ====================================================================

Connections are bounded: a client has ``REQUEST_DEADLINE_S`` to send each request's head and body
(408, or the connection closed, after that), and at most ``MAX_CONNECTIONS`` are served at once.
When that many are open, the one that has waited longest for its next request (an idle or
half-sent one) is closed to make room; when every one is busy (event streams, requests being
answered) the new one gets 503 naming the limit.
"""
from __future__ import annotations

import hmac
import io
import json
import logging
import secrets
import socket
import sys
import threading
import time
from collections.abc import Callable
from http.cookies import CookieError, SimpleCookie
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

from analysis.input_limits import NESTING_LIMIT, too_deeply_nested

from .engine import ActionRefused, StationEngine

__all__ = ["STATIC_DIR", "StationServer", "new_token"]

log = logging.getLogger(__name__)

STATIC_DIR = Path(__file__).resolve().parent / "static"
MAX_BODY = 64 * 1024
_TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8",
          ".css": "text/css; charset=utf-8", ".png": "image/png", ".svg": "image/svg+xml"}
#: the page's own files come with this cookie (set with the page), the API with the token header
_COOKIE = "impactlab_station"
#: seconds between keep-alive comments on an idle event stream
SSE_KEEPALIVE_S = 10.0
#: connections the listening socket queues while the handler threads accept (the standard library's 5
#: reset clients when a few tabs and scripts connect at once)
LISTEN_BACKLOG = 128
#: most connections served at once (each holds a thread): a few tabs (an event stream and a request or
#: two each) and scripts fit many times over
MAX_CONNECTIONS = 64
#: seconds a client has to send a request's head and body, counted from when the server waits for it
REQUEST_DEADLINE_S = 10.0
#: seconds one write to a client may block (a client that stopped reading is dropped)
SEND_TIMEOUT_S = 30.0
#: what a malformed request body makes the engine's checks raise beyond their own errors (answered 422)
_BAD_VALUES = (TypeError, ValueError, KeyError, AttributeError, OverflowError, IndexError, RecursionError)


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number; give a finite number")


def new_token() -> str:
    return secrets.token_urlsafe(24)


class StationServer(ThreadingHTTPServer):
    """``StationServer((host, port), engine, token, plotly_js)``; ``url`` is the page's address."""

    daemon_threads = True
    allow_reuse_address = True
    request_queue_size = LISTEN_BACKLOG

    def __init__(self, address: tuple, engine: StationEngine, token: str,
                 plotly_js: Callable[[], Path] | None = None, *, max_connections: int = MAX_CONNECTIONS,
                 request_deadline_s: float = REQUEST_DEADLINE_S) -> None:
        self.engine = engine
        self.token = token
        self.plotly_js = plotly_js
        self.closing = threading.Event()
        self.max_connections = int(max_connections)
        self.request_deadline_s = float(request_deadline_s)
        self._conn_lock = threading.Lock()
        #: open connection -> since when (time.monotonic) it waits for a request head; None while it is served
        self._conns: dict[socket.socket, float | None] = {}
        if ":" in str(address[0]):  # an IPv6 address such as ::1
            self.address_family = socket.AF_INET6
        super().__init__(address, _Handler)

    def handle_error(self, request: Any, client_address: Any) -> None:
        """One log line, never a traceback: a client that resets or drops its connection is routine;
        anything else is logged with its type and message."""
        exc = sys.exc_info()[1]
        who = client_address[0] if isinstance(client_address, tuple) and client_address else client_address
        if isinstance(exc, (ConnectionError, TimeoutError)):
            log.info("client %s dropped the connection (%s)", who, type(exc).__name__)
        else:
            log.warning("request from %s failed: %s: %s", who, type(exc).__name__, exc)

    # -- the connection bound ---------------------------------------------------------------------
    def process_request(self, request: Any, client_address: Any) -> None:
        """Serve the connection in a thread of its own while fewer than ``max_connections`` are open;
        past that, close the longest-waiting idle or half-sent one, else answer 503."""
        with self._conn_lock:
            room = len(self._conns) < self.max_connections or self._evict_one()
            if room:
                self._conns[request] = time.monotonic()
        if not room:
            self._refuse(request, client_address)
            return
        try:
            super().process_request(request, client_address)
        except RuntimeError as exc:  # no thread to be had
            with self._conn_lock:
                self._conns.pop(request, None)
            log.warning("cannot serve %s: %s", client_address, exc)
            self._refuse(request, client_address)

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        try:
            super().process_request_thread(request, client_address)
        finally:
            with self._conn_lock:
                self._conns.pop(request, None)

    def mark_waiting(self, connection: socket.socket, waiting: bool) -> None:
        """Note that ``connection`` waits for its next request (``waiting``) or is being served."""
        with self._conn_lock:
            if connection in self._conns:
                self._conns[connection] = time.monotonic() if waiting else None

    def _evict_one(self) -> bool:
        """Close the connection that has waited longest for a request (lock held); False when none waits."""
        waiting = [(since, id(c), c) for c, since in self._conns.items() if since is not None]
        if not waiting:
            return False
        since, _, victim = min(waiting)
        del self._conns[victim]
        try:
            victim.shutdown(socket.SHUT_RDWR)  # its thread reads the end of the stream and finishes
        except OSError:
            pass
        log.info("closed a connection idle or half-sent for %.1f s to serve a new one (%d connections at most)",
                 time.monotonic() - since, self.max_connections)
        return True

    def _refuse(self, request: socket.socket, client_address: Any) -> None:
        """503 on a connection over the bound, written from the accepting thread (a few hundred bytes)."""
        who = client_address[0] if isinstance(client_address, tuple) and client_address else client_address
        log.warning("refused a connection from %s: %d connections are being served", who, self.max_connections)
        body = json.dumps({"error": f"the station serves {self.max_connections} connections at once and all are "
                                    "busy: close other tabs or scripts of this station and try again"}).encode()
        head = (f"HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\nContent-Length: {len(body)}"
                "\r\nRetry-After: 1\r\nConnection: close\r\n\r\n").encode()
        try:
            request.settimeout(0.2)
            try:
                request.recv(MAX_BODY)  # the request, if it came: closing with it unread would reset the answer
            except TimeoutError:
                pass
            request.sendall(head + body)
        except OSError:
            pass
        self.shutdown_request(request)

    @property
    def url(self) -> str:
        host, port = str(self.server_address[0]), int(self.server_address[1])
        shown = f"[{host}]" if ":" in host else host
        return f"http://{shown}:{port}/?token={self.token}"

    def shutdown(self) -> None:
        self.closing.set()
        with self.engine.state.cond:
            self.engine.state.cond.notify_all()
        super().shutdown()


class _DeadlineReader(io.RawIOBase):
    """A connection's incoming bytes, each read bounded by the ``deadline`` (time.monotonic) of the
    request being read: a client that sends slowly cannot hold its thread past it."""

    def __init__(self, sock: socket.socket) -> None:
        super().__init__()
        self._sock = sock
        self.deadline = time.monotonic()

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        remaining = self.deadline - time.monotonic()
        if remaining <= 0:
            raise TimeoutError("the request was not complete in time")
        self._sock.settimeout(remaining)
        try:
            return self._sock.recv_into(buffer)
        finally:
            self._sock.settimeout(SEND_TIMEOUT_S)


class _Handler(BaseHTTPRequestHandler):
    server: StationServer
    protocol_version = "HTTP/1.1"

    def setup(self) -> None:
        super().setup()
        self._reader = _DeadlineReader(self.connection)
        self.rfile = io.BufferedReader(self._reader)
        self.connection.settimeout(SEND_TIMEOUT_S)

    def handle_one_request(self) -> None:
        """One request: its head and body must come within the server's deadline."""
        self._reader.deadline = time.monotonic() + self.server.request_deadline_s
        self.server.mark_waiting(self.connection, True)
        super().handle_one_request()

    def parse_request(self) -> bool:
        ok = super().parse_request()
        if ok:
            self.server.mark_waiting(self.connection, False)
        return ok

    def log_message(self, fmt: str, *args: Any) -> None:  # quiet: the station prints only its URL
        log.debug("%s - %s", self.address_string(), fmt % args)

    # -- plumbing ----------------------------------------------------------------------------------
    def _send(self, status: int, body: bytes, ctype: str = "application/json", extra: dict | None = None) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        extra = dict(extra or {})
        self.send_header("Cache-Control", extra.pop("Cache-Control", "no-store"))
        self.send_header("X-Content-Type-Options", "nosniff")
        for k, v in extra.items():
            self.send_header(k, v)
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, status: int, obj: Any) -> None:
        self._send(status, json.dumps(obj, allow_nan=False).encode())

    def _error(self, status: int, message: str) -> None:
        level = logging.INFO if status in (403, 409) else logging.WARNING
        log.log(level, "%s %s from %s -> %d %s", self.command, urlsplit(self.path).path[:80],
                self.client_address[0] if self.client_address else "?", status, message[:200])
        self._json(status, {"error": message})

    def _authorised(self, query: dict, cookie_ok: bool = False) -> bool:
        """The token from the header or the query; the cookie counts only for the page's own files
        (``cookie_ok``), so another page on this host cannot make the browser send API requests."""
        given = self.headers.get("X-Station-Token") or (query.get("token") or [""])[0]
        if not given and cookie_ok:
            given = self._cookie_token()
        return hmac.compare_digest(given.encode(), self.server.token.encode())

    def _cookie_token(self) -> str:
        cookie = SimpleCookie()
        try:
            cookie.load(self.headers.get("Cookie", ""))
        except CookieError:
            return ""
        morsel = cookie.get(_COOKIE)
        return morsel.value if morsel is not None else ""

    def _body(self) -> dict | None:
        """The JSON object of a POST, or None after answering 4xx."""
        try:
            n = int(self.headers.get("Content-Length", "0"))
        except ValueError:
            self._error(400, "bad Content-Length")
            return None
        if n > MAX_BODY:
            self.close_connection = True
            self._error(413, f"request body over {MAX_BODY} bytes")
            return None
        try:
            raw = self.rfile.read(n) if n > 0 else b""
        except TimeoutError:
            self.close_connection = True
            self._error(408, f"the request body did not come within {self.server.request_deadline_s:g} s")
            return None
        if len(raw) < n:
            self.close_connection = True
            self._error(400, f"the request body ended after {len(raw)} of {n} bytes")
            return None
        try:
            text = raw.decode("utf-8")
            if too_deeply_nested(text):      # refused before the parser descends into it
                self._error(400, f"malformed JSON: nested deeper than {NESTING_LIMIT} levels; send a flatter object")
                return None
            data = json.loads(text, parse_constant=_no_constant)
        except (UnicodeDecodeError, ValueError) as exc:
            self._error(400, f"malformed JSON: {exc}")
            return None
        if not isinstance(data, dict):
            self._error(400, "the request body must be a JSON object")
            return None
        return data

    # -- verbs -------------------------------------------------------------------------------------
    def do_GET(self) -> None:
        parts = urlsplit(self.path)
        if parts.path == "/favicon.ico":  # browsers ask on their own, without the token: nothing to show
            self.send_response(204)
            self.send_header("Content-Length", "0")
            self.send_header("Cache-Control", "max-age=86400")
            self.end_headers()
            return
        query = parse_qs(parts.query)
        if not self._authorised(query, cookie_ok=parts.path == "/" or parts.path.startswith("/static/")):
            self._error(403, "missing or wrong token: open the URL the station printed")
            return
        path = parts.path
        eng = self.server.engine
        if path in ("/", "/index.html"):
            self._static("index.html", {"Set-Cookie": f"{_COOKIE}={self.server.token}; HttpOnly; SameSite=Strict; Path=/"})
        elif path.startswith("/static/"):
            self._static(path[len("/static/"):])
        elif path == "/api/state":
            self._json(200, eng.state.snapshot() | {"allowed": list(eng.allowed())})
        elif path.startswith("/api/blob/"):
            name = path[len("/api/blob/"):]
            if name == "geometry":
                self._json(200, eng.geometry)
                return
            data = eng.state.blob(name) if name in ("hit", "frf", "setup") else None
            if data is None:
                self._error(404, f"no {name!r} data (yet)")
            else:
                self._send(200, data)
        elif path == "/api/events":
            self._events()
        else:
            self._error(404, f"no such page {path!r}")

    do_HEAD = do_GET

    def do_POST(self) -> None:
        parts = urlsplit(self.path)
        if not self._authorised(parse_qs(parts.query)):
            self._error(403, "missing or wrong token: open the URL the station printed")
            return
        body = self._body()
        if body is None:
            return
        eng = self.server.engine
        client = body.get("client")
        if client is not None and not isinstance(client, str):
            self._error(400, "client must be a string")
            return
        if parts.path == "/api/lease":
            take = body.get("take", False)
            if not isinstance(client, str) or not client or not isinstance(take, bool):
                self._error(400, "give {\"client\": ID, \"take\": false|true}")
                return
            with eng.state.cond:
                ok = eng.state.lease.acquire(client, take)
                eng.state.update()  # tabs learn who controls
            self._json(200, {"control": ok, "controller": eng.state.lease.holder})  # read-only is an answer, not an error
        elif parts.path == "/api/action":
            action = body.get("action")
            if not isinstance(action, str):
                self._error(400, "give {\"client\": ID, \"action\": NAME}")
                return
            with eng.state.cond:
                if not isinstance(client, str) or not eng.state.lease.holds(client):
                    self._error(409, "another tab controls the session (or this tab's control lapsed): take control "
                                     "first")
                    return
                eng.state.lease.acquire(client)  # an action renews the lease
            try:
                eng.submit(action, {k: v for k, v in body.items() if k not in ("client", "action")})
            except ActionRefused as exc:
                self._error(exc.status, str(exc))
                return
            except _BAD_VALUES as exc:
                self._error(422, f"invalid {action} request: {type(exc).__name__}: {exc}")
                return
            self._json(200, {"ok": True, "action": action})
        elif parts.path == "/api/setup/check":
            try:
                setup, windows = eng.check_setup(body)
            except ActionRefused as exc:
                self._error(exc.status, str(exc))
                return
            except _BAD_VALUES as exc:
                self._error(422, f"invalid set-up: {type(exc).__name__}: {exc}")
                return
            self._json(200, {"ok": True, "bandwidth_hz": setup.bandwidth_hz, "windows_text": windows.describe()})
        else:
            self._error(404, f"no such API {parts.path!r}")

    # -- pieces ------------------------------------------------------------------------------------
    def _static(self, name: str, extra: dict | None = None) -> None:
        if name == "plotly.min.js" and self.server.plotly_js is not None:
            try:
                path = self.server.plotly_js()
            except (ImportError, OSError) as exc:  # plotly missing (analysis.web_assets.MissingAssetError)
                self._error(404, str(exc))
                return
        else:
            try:
                path = (STATIC_DIR / name).resolve()
                found = STATIC_DIR in path.parents and path.is_file()
            except (ValueError, OSError):  # a NUL byte, a name too long for the file system
                found = False
            if not found:
                self._error(404, f"no static file {name[:100]!r}")
                return
        headers = dict(extra or {})
        if name.endswith(".min.js"):
            headers["Cache-Control"] = "max-age=3600"
        self._send(200, path.read_bytes(), _TYPES.get(path.suffix, "application/octet-stream"), headers)

    def _events(self) -> None:
        """Server-sent events: the state on connect and on every change until the client goes."""
        state = self.server.engine.state
        self.send_response(200)
        self.send_header("Content-Type", "text/event-stream")
        self.send_header("Cache-Control", "no-store")
        self.send_header("Connection", "close")
        self.end_headers()
        self.close_connection = True
        if self.command == "HEAD":
            return
        seen = -1
        try:
            while not self.server.closing.is_set():
                version = state.wait_change(seen, SSE_KEEPALIVE_S)
                if version == seen:
                    self.wfile.write(b": keep-alive\n\n")
                else:
                    seen = version
                    snap = state.snapshot() | {"allowed": list(self.server.engine.allowed())}
                    self.wfile.write(b"event: state\ndata: " + json.dumps(snap, allow_nan=False).encode() + b"\n\n")
                self.wfile.flush()
        except (BrokenPipeError, ConnectionResetError, TimeoutError):
            return
