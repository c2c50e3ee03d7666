"""Helpers for the station tests: the station as a real process, a small JSON client, headless Chromium."""
from __future__ import annotations

import http.client
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from browser_support import headless_chrome

ROOT = Path(__file__).resolve().parents[1]
#: generous bound for every condition wait (the suite shares two cores with other work)
WAIT_S = 90.0


class StationProcess:
    """``python -m acquisition station ARGS`` in a child process; ``url``, ``base``, ``token``."""

    def __init__(self, args: list, cwd: Path, sigint_ignored: bool = False) -> None:
        """``sigint_ignored``: start it as a script's background job is started (SIGINT ignored, which
        a child inherits and Python then leaves without its own Ctrl-C handler)."""
        env = dict(os.environ, PYTHONUNBUFFERED="1", MPLBACKEND="Agg")
        ignore = (lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)) if sigint_ignored else None
        self.proc = subprocess.Popen([sys.executable, "-m", "acquisition", "station", *args], cwd=cwd,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                                     preexec_fn=ignore)
        line = self.proc.stdout.readline().strip()  # the URL is the first line (blocks until printed)
        if not line.startswith("http://"):
            self.proc.kill()
            out, err = self.proc.communicate(timeout=WAIT_S)
            raise AssertionError(f"station did not print its URL: {line!r} {out!r} {err!r}")
        self.url = line
        parts = urlsplit(line)
        self.host, self.port = parts.hostname, parts.port
        self.base = f"http://{parts.hostname}:{parts.port}"
        self.token = parts.query.split("token=", 1)[1]

    def kill(self) -> None:
        """SIGKILL: no clean-up at all (as a power cut of the laptop's process)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
        self.proc.communicate(timeout=WAIT_S)

    def stop(self) -> tuple[int, str, str]:
        """SIGTERM (as Ctrl-C): the station closes the recording and exits."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        out, err = self.proc.communicate(timeout=WAIT_S)
        return self.proc.returncode, out, err


class Api:
    """JSON requests to a station (token in the header unless ``token=None``)."""

    def __init__(self, station: StationProcess, client: str = "test-client") -> None:
        self.s = station
        self.client = client

    def request(self, method: str, path: str, body: Any = None, token: str | None = "", raw: bytes | None = None,
                headers: dict | None = None) -> tuple[int, Any]:
        conn = http.client.HTTPConnection(self.s.host, self.s.port, timeout=WAIT_S)
        h = dict(headers or {})
        if token is not None:
            h["X-Station-Token"] = token or self.s.token
        data = raw if raw is not None else (None if body is None else json.dumps(body).encode())
        if data is not None:
            h["Content-Type"] = "application/json"
        conn.request(method, path, body=data, headers=h)
        r = conn.getresponse()
        payload = r.read()
        conn.close()
        try:
            return r.status, json.loads(payload)
        except ValueError:
            return r.status, payload

    def state(self) -> dict:
        status, st = self.request("GET", "/api/state")
        assert status == 200, st
        return st

    def lease(self, take: bool = False) -> tuple[int, bool | None]:
        """(status, control): 200 and whether this client now controls the session."""
        status, body = self.request("POST", "/api/lease", {"client": self.client, "take": take})
        return status, body.get("control") if isinstance(body, dict) else None

    def act(self, action: str, **extra: Any) -> tuple[int, Any]:
        return self.request("POST", "/api/action", {"client": self.client, "action": action, **extra})

    def act_here(self, action: str, **extra: Any) -> tuple[int, Any]:
        """``action`` naming what the state shows now, as the page does: the hit waiting for a decision
        (``hit``, its number) or the point on now (``point``, its plan index; for ``undo`` also ``hits``, its
        accepted hits)."""
        st = self.state()
        if action in ("accept", "reject"):
            extra.setdefault("hit", (st.get("verdict") or {}).get("number"))
        elif action in ("next-point", "undo", "remeasure", "arm"):
            extra.setdefault("point", st["current"])
        if action == "undo":
            extra.setdefault("hits", st.get("point_hits"))
        return self.act(action, **extra)

    def wait(self, pred, what: str, timeout_s: float = WAIT_S) -> dict:
        """Poll the state until ``pred(state)``: a condition, never a fixed delay."""
        end = time.monotonic() + timeout_s
        while True:
            st = self.state()
            if pred(st):
                return st
            if time.monotonic() > end:
                raise AssertionError(f"timed out waiting for {what}; state phase={st.get('phase')} "
                                     f"messages={st.get('messages', [])[-5:]}")
            time.sleep(0.05)


def chrome(tmp_path: Path) -> Any:
    """A headless Chromium for the station's page (:func:`browser_support.headless_chrome`: skips with an
    install hint when missing, fails under CI=true)."""
    return headless_chrome(tmp_path / "chromium-profile", window="1500,1100")
