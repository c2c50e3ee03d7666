"""``python -m simulator serve``: the simulated analyser as its own process, over TCP or a pty.

    python -m simulator serve --tcp 127.0.0.1:0 [--seed N] [--config FILE] [--noise on|off] [--option K=V ...]
    python -m simulator serve --pty [same options]

The first line printed on stdout (flushed at once) is where to connect:
``socket://127.0.0.1:PORT`` (port 0 picks a free port) or the pseudo-terminal path
(``/dev/pts/N``, which ``serial.Serial(path)`` or the device URL ``/dev/pts/N`` opens).
Messages go to stderr through ``logging``.

Connections are served one after another (a TCP listen backlog queues the next clients).
**Each connection gets a fresh analyser**: a new ``Firmware`` from
``simulator.analyser.create_analyser(options)``, i.e. the power-on state with the same seed, so
the same commands give the same bytes to every client (the next one is built in the background
while the current client is served, so nobody waits for the frame's eigen-solution). Over a pty there is no connect event: a
client's first bytes after the previous client hung up (the master reads EIO while no one holds
the slave open) start a new analyser; a client that reopens the tty within one tick (50 ms) of the
last one closing may find the previous analyser's state (the driver's reset recovery copes).

Robustness: garbage is the firmware's business (it answers or ignores per the bulk-only rules);
a client that disconnects mid-command, stops reading for ``--send-timeout`` seconds, or trips an
internal error only ends its own connection; a TCP client silent for ``--yield-after`` seconds
while another client waits is closed. Every wait is bounded (0.05 s ticks), so SIGTERM and
SIGINT stop the server promptly and cleanly (exit status 0).
"""
from __future__ import annotations

import errno
import logging
import os
import select
import socket
import threading
import time
import tty
from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["StopFlag", "Session", "Prebuilt", "serve_tcp", "serve_pty", "analyser_options", "firmware_factory",
           "tcp_listener", "tcp_url", "open_pty"]

_log = logging.getLogger("simulator.serve")

#: largest chunk moved per call (bytes)
CHUNK = 1 << 20
#: wait granularity: how quickly a stop request or new data is noticed (s)
TICK_S = 0.05


class StopFlag:
    """Set by SIGTERM/SIGINT (or by a test); every loop checks it at least every ``TICK_S``."""

    def __init__(self) -> None:
        self.stopped = False

    def set(self, *_: Any) -> None:
        self.stopped = True

    def __bool__(self) -> bool:
        return self.stopped


class Session:
    """One client's analyser: a fresh firmware fed with the client's bytes."""

    def __init__(self, factory: Callable[[], Any], label: str) -> None:
        self.firmware = factory()
        self.label = label
        self.bytes_in = 0
        self.bytes_out = 0

    def feed(self, data: bytes) -> None:
        self.bytes_in += len(data)
        self.firmware.write(data)

    def pending(self) -> bytes:
        """Everything the firmware has to send right now (may be b"")."""
        parts = []
        while True:
            chunk = self.firmware.read(CHUNK)
            if not chunk:
                break
            parts.append(chunk)
        out = b"".join(parts)
        self.bytes_out += len(out)
        return out


class Prebuilt:
    """A firmware factory that always keeps the next fresh analyser built in the background.

    Building one (the frame's eigen-solution) takes about a second; a client should not wait for
    it. Calling the object returns the spare built earlier (waiting for it if needed) and starts
    building the next. A build error is raised to the caller that would have received it.
    """

    def __init__(self, factory: Callable[[], Any]) -> None:
        self._factory = factory
        self._result: tuple[bool, Any] = (False, None)
        self._thread: threading.Thread | None = None
        self._start()

    def _start(self) -> None:
        def build() -> None:
            try:
                self._result = (True, self._factory())
            except Exception as exc:  # handed to the caller of __call__
                self._result = (False, exc)

        self._thread = threading.Thread(target=build, name="analyser-prebuild", daemon=True)
        self._thread.start()

    def ready(self) -> Any:
        """Wait for the spare; raise its build error, if any (without consuming it)."""
        assert self._thread is not None
        self._thread.join()
        ok, value = self._result
        if not ok:
            raise value
        return value

    def __call__(self) -> Any:
        firmware = self.ready()
        self._start()
        return firmware


def analyser_options(seed: int | None, config: str | None, noise: str | None,
                     extra: Sequence[str]) -> dict:
    """The ``create_analyser`` options (as a ``sim://`` URL query would give them)."""
    options: dict = {}
    for item in extra:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ValueError(f"--option expects KEY=VALUE, got {item!r}")
        if key == "packetized":
            raise ValueError("--option packetized: the server is a byte stream (TCP, pty); drop it")
        options[key] = value
    if seed is not None:
        options["seed"] = int(seed)
    if config is not None:
        options["config"] = config
    if noise is not None:
        options["noise"] = noise == "on"
    return options


def firmware_factory(options: dict, precomputed: str | None = None) -> Callable[[], Any]:
    """A function building one fresh firmware; ``precomputed`` is an ``.npz`` with ``volts`` and ``fs_hz``."""
    from simulator.analyser import create_analyser
    from simulator.firmware import PrecomputedStand

    stand = None
    if precomputed is not None:
        import numpy as np

        from analysis.input_limits import check_input_file
        from analysis.work_limits import memory_budget_bytes

        from .errors import ConfigError

        check_input_file(precomputed, "--precomputed file", memory_budget_bytes(), ConfigError)  # a FIFO would block
        with np.load(precomputed) as data:
            if "volts" not in data or "fs_hz" not in data:
                raise ValueError(f"{precomputed}: a precomputed stand file needs arrays 'volts' and 'fs_hz'")
            stand = PrecomputedStand(data["volts"], float(data["fs_hz"]))

    def make() -> Any:
        analyser = create_analyser(dict(options), stand=stand)
        # the firmware imports its front end (scipy.signal) at the first strike; do it now (once the options are
        # known to be good: a wrong option is told without it) so that a client's first ARM does not wait for it
        import simulator.frontend  # noqa: F401
        return analyser

    return make


# --------------------------------------------------------------------------------- TCP
def _write_all(write: Callable[[memoryview], int], fd: Any, data: bytes, stop: StopFlag,
               send_timeout_s: float, who: str, dropped: str) -> bool:
    """Write ``data`` to a non-blocking ``fd`` through ``write`` (returns the bytes taken); False
    when the peer is gone (``OSError``) or took nothing for ``send_timeout_s`` (then ``dropped``
    says what is dropped; ``who`` names the peer in the log)."""
    view = memoryview(data)
    deadline = time.monotonic() + send_timeout_s
    while view:
        try:
            n = write(view)
            view = view[n:]
            deadline = time.monotonic() + send_timeout_s  # progress restarts the clock
            continue
        except (BlockingIOError, InterruptedError):
            pass
        except OSError as exc:  # reset, broken pipe; EIO: the client closed the tty
            _log.info("%s went away while receiving: %s", who, exc)
            return False
        if stop or time.monotonic() > deadline:
            _log.warning("%s stopped reading for %.1f s (or shutdown); dropping %s", who, send_timeout_s, dropped)
            return False
        select.select([], [fd], [], TICK_S)
    return True


def _send_all(conn: socket.socket, data: bytes, stop: StopFlag, send_timeout_s: float) -> bool:
    """Send ``data`` on a non-blocking socket; False if the client is gone or stalled."""
    return _write_all(conn.send, conn, data, stop, send_timeout_s, "client", "it")


def _serve_connection(conn: socket.socket, session: Session, stop: StopFlag, send_timeout_s: float,
                      idle_timeout_s: float, waiting: Callable[[], bool] | None = None,
                      yield_after_s: float = 0.0) -> None:
    """Serve one client until it hangs up, errs, stalls, or (``yield_after_s`` > 0) has been silent
    that long while ``waiting()`` says another client is queued: a stalled client cannot keep the
    next one out."""
    conn.setblocking(False)
    last = time.monotonic()
    while not stop:
        if (yield_after_s > 0 and waiting is not None and time.monotonic() - last > yield_after_s
                and waiting()):
            _log.warning("%s: silent for %.1f s while another client waits; closing it", session.label,
                         yield_after_s)
            return
        ready, _, _ = select.select([conn], [], [], TICK_S)
        if ready:
            try:
                data = conn.recv(CHUNK)
            except (BlockingIOError, InterruptedError):
                continue
            except OSError as exc:
                _log.info("%s: connection error: %s", session.label, exc)
                return
            if not data:
                _log.info("%s: client hung up", session.label)
                return
            last = time.monotonic()
            session.feed(data)
        elif idle_timeout_s and time.monotonic() - last > idle_timeout_s:
            _log.info("%s: idle for %.1f s; closing", session.label, idle_timeout_s)
            return
        out = session.pending()
        if out and not _send_all(conn, out, stop, send_timeout_s):
            return


def tcp_listener(host: str, port: int) -> socket.socket:
    infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    family, socktype, proto, _, addr = infos[0]
    srv = socket.socket(family, socktype, proto)
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    srv.bind(addr)
    srv.listen(8)
    srv.setblocking(False)
    return srv


def tcp_url(srv: socket.socket) -> str:
    """``socket://HOST:PORT`` of a bound listening socket."""
    host, port = srv.getsockname()[:2]
    return f"socket://[{host}]:{port}" if ":" in host else f"socket://{host}:{port}"


def serve_tcp(srv: socket.socket, factory: Callable[[], Any], stop: StopFlag, *, max_clients: int = 0,
              send_timeout_s: float = 10.0, idle_timeout_s: float = 0.0, yield_after_s: float = 5.0) -> int:
    """Accept and serve clients one after another until ``stop`` (or ``max_clients`` served).

    A client silent for ``yield_after_s`` seconds while another one is queued is closed (0: never)."""

    def waiting() -> bool:
        try:
            return bool(select.select([srv], [], [], 0)[0])
        except (OSError, ValueError):
            return False

    served = 0
    while not stop and not (max_clients and served >= max_clients):
        ready, _, _ = select.select([srv], [], [], TICK_S)
        if not ready:
            continue
        try:
            conn, peer = srv.accept()
        except (BlockingIOError, InterruptedError):
            continue
        served += 1
        label = f"client {served} {peer[0]}:{peer[1]}"
        _log.info("%s: connected; fresh analyser", label)
        with conn:
            try:
                session = Session(factory, label)
                _serve_connection(conn, session, stop, send_timeout_s, idle_timeout_s, waiting, yield_after_s)
            except Exception:  # a firmware fault ends this client only; the server stays up
                _log.exception("%s: internal error; closing this connection", label)
            else:
                _log.info("%s: done (%d bytes in, %d out)", label, session.bytes_in, session.bytes_out)
    return 0


# --------------------------------------------------------------------------------- pty
def open_pty() -> tuple[int, str]:
    """A raw pseudo-terminal: (master fd, slave path). The slave fd is closed: clients open the path."""
    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    os.close(slave)
    os.set_blocking(master, False)
    return master, path


def _pty_write(master: int, data: bytes, stop: StopFlag, send_timeout_s: float) -> bool:
    return _write_all(lambda view: os.write(master, view), master, data, stop, send_timeout_s,
                      "pty client", "its output")


def serve_pty(master: int, factory: Callable[[], Any], stop: StopFlag, *, max_clients: int = 0,
              send_timeout_s: float = 10.0) -> int:
    """Serve the pty master until ``stop``; a client's first bytes after a hang-up start a fresh analyser."""
    session: Session | None = None
    served = 0
    while not stop:
        ready, _, _ = select.select([master], [], [], TICK_S)
        if not ready:
            if session is not None:
                out = session.pending()
                if out and not _pty_write(master, out, stop, send_timeout_s):
                    session = None
            continue
        try:
            data = os.read(master, CHUNK)
        except (BlockingIOError, InterruptedError):
            continue
        except OSError as exc:
            if exc.errno != errno.EIO:
                raise
            data = b""
        if not data:  # nobody holds the slave open
            if session is not None:
                _log.info("%s: client hung up (%d bytes in, %d out)", session.label, session.bytes_in,
                          session.bytes_out)
                session = None
                if max_clients and served >= max_clients:
                    break
            time.sleep(TICK_S)
            continue
        if session is None:
            served += 1
            session = Session(factory, f"pty client {served}")
            _log.info("%s: first bytes; fresh analyser", session.label)
        try:
            session.feed(data)
            out = session.pending()
        except Exception:  # a firmware fault ends this client's analyser only
            _log.exception("%s: internal error; the next bytes start a fresh analyser", session.label)
            session = None
            continue
        if out and not _pty_write(master, out, stop, send_timeout_s):
            session = None
    return 0
