"""``python -m simulator serve --tcp 127.0.0.1:0`` survives hostile clients and keeps serving.

One server process meets, in turn: a client that sends garbage and hangs up; one that sends half
a command and stalls while the next one waits (closed after ``--yield-after``); one that asks
for megabytes and never reads (dropped after ``--send-timeout``); one that resets the connection
mid-command; and one that stalls with faults injected. After each, a well-behaved client
(``Analyser("socket://...")``) identifies the analyser; at the end a full capture works and
SIGTERM stops the server with status 0. Loopback only; every wait is bounded.
"""
from __future__ import annotations

import signal
import socket
import struct
import subprocess
import sys
import time

import numpy as np
import pytest

from acquisition import protocol as P
from acquisition.driver import Analyser
from acquisition.errors import ImpactlabError
from acquisition.setup import default_setup, setup_to_wire


@pytest.fixture(scope="module")
def server():
    proc = subprocess.Popen([sys.executable, "-m", "simulator", "serve", "--tcp", "127.0.0.1:0", "--seed", "3",
                             "--send-timeout", "1", "--yield-after", "0.5",
                             "--option", "faults=garbage:0.001,phase_error:0.001"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        url = proc.stdout.readline().strip()
        assert url.startswith("socket://127.0.0.1:"), proc.stderr.read() if proc.poll() is not None else url
        yield proc, url
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(10)
        proc.stdout.close()
        proc.stderr.close()


def _addr(url: str) -> tuple[str, int]:
    host, port = url[len("socket://"):].rsplit(":", 1)
    return host, int(port)


def _good_client(url: str) -> None:
    """A normal client is served (a few attempts: faults are injected at a low rate)."""
    deadline = time.monotonic() + 20
    last: Exception | None = None
    while time.monotonic() < deadline:
        try:
            with Analyser(url, timeout_s=3.0) as a:
                assert a.identify().vendor == "IMPACTLB"
                return
        except (ImpactlabError, OSError) as exc:  # retried, reported if it persists
            last = exc
            time.sleep(0.2)
    raise AssertionError(f"the server no longer serves a good client: {last}")


def test_garbage_then_hang_up(server):
    proc, url = server
    rng = np.random.default_rng(1)
    with socket.create_connection(_addr(url), timeout=5) as s:
        for _ in range(16):
            s.sendall(rng.integers(0, 256, 4096, dtype=np.uint8).tobytes())
    _good_client(url)
    assert proc.poll() is None


def test_stalled_client_yields_to_the_next(server):
    proc, url = server
    with socket.create_connection(_addr(url), timeout=5) as stalled:
        stalled.sendall(P.encode_cbw(1, 36, True, P.build_cdb(P.Op.INQUIRY, length=36))[:10])  # half a CBW
        time.sleep(0.2)
        t0 = time.monotonic()
        _good_client(url)  # queued behind the stalled one, served after --yield-after
        assert time.monotonic() - t0 < 15
    assert proc.poll() is None


def test_client_that_never_reads_is_dropped(server):
    proc, url = server
    cbw = P.encode_cbw(2, 36, True, P.build_cdb(P.Op.INQUIRY, length=36))
    with socket.create_connection(_addr(url), timeout=5) as greedy:
        greedy.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        greedy.settimeout(0.2)
        sent = 0
        try:
            for _ in range(200_000):  # ~10 MB of replies asked for, none read
                greedy.send(cbw)
                sent += 1
        except (TimeoutError, OSError):
            pass  # the server stopped reading us (its send to us blocked) or dropped us
        assert sent > 0
        _good_client(url)
    assert proc.poll() is None


def test_client_vanishing_mid_command(server):
    proc, url = server
    setup = P.encode_setup(setup_to_wire(default_setup()))
    s = socket.create_connection(_addr(url), timeout=5)
    s.sendall(P.encode_cbw(3, len(setup), False, P.build_cdb(P.Op.SET_UP, length=len(setup))))
    s.sendall(setup[: len(setup) // 2])
    s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))  # close = RST
    s.close()
    _good_client(url)
    assert proc.poll() is None


def test_full_capture_after_the_abuse_and_clean_stop(server):
    proc, url = server
    with Analyser(url, timeout_s=5.0) as a:
        for attempt in range(5):  # low-rate injected faults may hit a command: retry like the session does
            try:
                a.configure(default_setup())
                block = a.capture(10.0)
                break
            except ImpactlabError:
                if attempt == 4:
                    raise
        assert block.counts.shape == (4, default_setup().block_size) and np.abs(block.data[0]).max() > 20.0
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(10) == 0
    assert "Traceback" not in proc.stderr.read()
