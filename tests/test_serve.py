"""The simulated analyser server: connection handling (in-process, with a tiny echo firmware) and
the real ``python -m simulator serve`` process (loopback TCP and pty)."""
from __future__ import annotations

import itertools
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import serial

from acquisition import protocol as P
from acquisition.bot import BulkOnly
from acquisition.errors import DeviceGone, ImpactlabError
from acquisition.urls import open_transport
from simulator import serve

ROOT = Path(__file__).resolve().parents[1]


class TaggedEcho:
    """Echo firmware stamped with its instance number; ``b"boom"`` raises (an internal fault)."""

    counter = itertools.count(1)

    def __init__(self) -> None:
        self.ident = next(self.counter)
        self.out = bytearray()

    def write(self, data: bytes) -> None:
        if data == b"boom":
            raise RuntimeError("simulated firmware fault")
        self.out += b"%d:" % self.ident + data

    def read(self, max_len: int) -> bytes:
        chunk = bytes(self.out[:max_len])
        del self.out[:max_len]
        return chunk


@pytest.fixture
def tcp_server():
    srv = serve.tcp_listener("127.0.0.1", 0)
    stop = serve.StopFlag()
    made: list[TaggedEcho] = []

    def factory() -> TaggedEcho:
        fw = TaggedEcho()
        made.append(fw)
        return fw

    th = threading.Thread(target=serve.serve_tcp, args=(srv, factory, stop), kwargs={"send_timeout_s": 2.0},
                          daemon=True)
    th.start()
    host, port = srv.getsockname()
    yield (host, port), made
    stop.set()
    th.join(30)
    assert not th.is_alive()  # the server thread ends when asked (no hang)
    srv.close()


def _exchange(addr, payload: bytes, expect: int) -> bytes:
    with socket.create_connection(addr, timeout=2) as c:
        c.sendall(payload)
        got = b""
        while len(got) < expect:
            chunk = c.recv(expect - len(got))
            if not chunk:
                break
            got += chunk
        return got


def test_each_connection_gets_a_fresh_analyser(tcp_server) -> None:
    addr, made = tcp_server
    first = _exchange(addr, b"hello", 7)
    second = _exchange(addr, b"hello", 7)
    a, b = made[0].ident, made[1].ident
    assert first == b"%d:hello" % a and second == b"%d:hello" % b and a != b


def test_tcp_url_is_printed_form(tcp_server) -> None:
    (host, port), _ = tcp_server
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        assert serve.tcp_url(s) == f"socket://127.0.0.1:{s.getsockname()[1]}"


def test_server_survives_internal_fault_and_hangups(tcp_server) -> None:
    addr, made = tcp_server
    # a client that trips a firmware fault is dropped ...
    with socket.create_connection(addr, timeout=2) as c:
        c.sendall(b"boom")
        assert c.recv(10) == b""  # the server closed this connection
    # ... one that hangs up at once, and one that leaves without reading its reply
    socket.create_connection(addr, timeout=2).close()
    with socket.create_connection(addr, timeout=2) as c:
        c.sendall(b"x" * 100_000)
    # and the next client is served normally
    with socket.create_connection(addr, timeout=2) as c:
        c.sendall(b"ok")
        reply = b""
        while not reply.endswith(b":ok"):
            reply += c.recv(16)
    assert reply == b"%d:ok" % made[-1].ident and len(made) == 4


def test_analyser_options() -> None:
    assert serve.analyser_options(3, "f.toml", "off", ["polls=2"]) == {
        "polls": "2", "seed": 3, "config": "f.toml", "noise": False}
    with pytest.raises(ValueError, match="KEY=VALUE"):
        serve.analyser_options(None, None, None, ["oops"])


def test_prebuilt_hands_out_fresh_instances_and_errors() -> None:
    spare = serve.Prebuilt(TaggedEcho)
    a, b = spare(), spare()
    assert isinstance(a, TaggedEcho) and b.ident == a.ident + 1

    def broken() -> TaggedEcho:
        raise ValueError("unknown simulator option(s) ['x']")

    bad = serve.Prebuilt(broken)
    with pytest.raises(ValueError, match="unknown simulator option"):
        bad.ready()


def test_max_clients_ends_the_server() -> None:
    srv = serve.tcp_listener("127.0.0.1", 0)
    with srv:
        th = threading.Thread(target=serve.serve_tcp, args=(srv, TaggedEcho, serve.StopFlag()),
                              kwargs={"max_clients": 1}, daemon=True)
        th.start()
        with socket.create_connection(srv.getsockname(), timeout=2) as c:
            c.sendall(b"one")
            reply = b""
            while not reply.endswith(b":one"):
                reply += c.recv(16)
        th.join(3)
        assert not th.is_alive()


def test_pty_in_process_reconnect() -> None:
    master, path = serve.open_pty()
    stop = serve.StopFlag()
    th = threading.Thread(target=serve.serve_pty, args=(master, TaggedEcho, stop), daemon=True)
    th.start()
    try:
        def ident() -> int:
            with serial.Serial(path, timeout=2) as port:
                port.write(b"\x00\x03\x11\x13\r\n")  # control characters pass untouched (raw tty)
                head = port.read(2)
                while not head.endswith(b":"):
                    head += port.read(1)
                assert port.read(6) == b"\x00\x03\x11\x13\r\n"
                return int(head[:-1])

        first = ident()
        # a fresh analyser once the server has seen the hang-up (polled: no assumption on how fast)
        assert _eventually(lambda: ident() != first)
    finally:
        stop.set()
        th.join(3)
        os.close(master)
    assert not th.is_alive()


# -- the real server process ---------------------------------------------------------------------
def _start(*args: str) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "simulator", "serve", *args], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline().strip()
    if not line:
        proc.kill()
        _, err = proc.communicate(timeout=10)
        pytest.fail(f"server printed no URL; stderr:\n{err}")
    return proc, line


def _eventually(check, *, errors: tuple = (), limit_s: float = 30.0) -> bool:
    """Poll ``check()`` until it is true (a condition, not a guess at how long the server takes)."""
    deadline = time.monotonic() + limit_s
    while True:
        try:
            if check():
                return True
        except errors:
            pass
        if time.monotonic() > deadline:
            return False
        time.sleep(serve.TICK_S)


def _stop(proc: subprocess.Popen, sig: int = signal.SIGTERM) -> None:
    """Stop the server process with ``sig``; it must exit by itself with code 0 (no hang)."""
    proc.send_signal(sig)
    try:
        rc = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.stdout.close()
        proc.stderr.close()
    assert rc == 0


def _inquiry(url: str) -> P.Inquiry:
    with open_transport(url) as t:
        bot = BulkOnly(t, timeout_s=5.0)
        return P.decode_inquiry(bot.command("INQUIRY", length=36).data)


@pytest.fixture(scope="module")
def tcp_process():
    proc, url = _start("--tcp", "127.0.0.1:0", "--seed", "1")
    yield url
    _stop(proc)


def test_process_prints_url_and_answers(tcp_process: str) -> None:
    assert tcp_process.startswith("socket://127.0.0.1:")
    inq = _inquiry(tcp_process)
    assert inq.vendor == "IMPACTLB" and inq.device_type == P.DEVICE_TYPE_PROCESSOR


def test_process_survives_garbage_then_serves_next_client(tcp_process: str) -> None:
    host, port = tcp_process[len("socket://"):].rsplit(":", 1)
    with socket.create_connection((host, int(port)), timeout=2) as c:
        c.sendall(bytes(range(256)) * 64)  # not a CBW: the firmware discards until a reset
        c.settimeout(0.2)
        with pytest.raises(socket.timeout):
            c.recv(1)  # nothing comes back for garbage
    assert _inquiry(tcp_process).vendor == "IMPACTLB"


def test_process_survives_disconnect_mid_command(tcp_process: str) -> None:
    host, port = tcp_process[len("socket://"):].rsplit(":", 1)
    # a SET UP that announces 200 bytes of parameter data, of which 10 are sent before hanging up
    cbw = P.encode_cbw(7, 200, False, P.build_cdb(P.Op.SET_UP, length=200))
    with socket.create_connection((host, int(port)), timeout=2) as c:
        c.sendall(cbw + b"\x01" * 10)
    # a READ of a big reply abandoned half way: INQUIRY asked, reply never read
    with socket.create_connection((host, int(port)), timeout=2) as c:
        c.sendall(P.encode_cbw(8, 36, True, P.build_cdb(P.Op.INQUIRY, length=36)))
    assert _inquiry(tcp_process).product.startswith("SIGLAB-SIM")


def test_process_pty() -> None:
    proc, path = _start("--pty", "--seed", "1")
    try:
        assert path.startswith("/dev/")
        with serial.Serial(path, timeout=0.2) as port:  # garbage, then hang up
            port.write(bytes(range(256)) * 8)
            assert port.read(1) == b""
        # the next client gets a fresh analyser once the server has seen the hang-up
        assert _eventually(lambda: _inquiry(path).vendor == "IMPACTLB", errors=(ImpactlabError, OSError))
        assert _inquiry(path).vendor == "IMPACTLB"
        lingering = open_transport(path)
    finally:
        _stop(proc, signal.SIGINT)
    # the pty vanished with the server: the client's next read says so
    with pytest.raises(DeviceGone):
        lingering.read(13, 0.5)
    lingering.close()


def test_process_rejects_bad_options() -> None:
    res = subprocess.run([sys.executable, "-m", "simulator", "serve", "--tcp", "127.0.0.1:0", "--option", "bogus=1"],
                         cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert res.returncode == 2 and "unknown simulator option" in res.stderr and res.stdout == ""
    res = subprocess.run([sys.executable, "-m", "simulator", "serve", "--tcp", "nohostport"],
                         cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert res.returncode == 2 and "HOST:PORT" in res.stderr


@pytest.mark.long
def test_process_soak_random_clients() -> None:
    """200 clients: random garbage, half commands, abandoned replies; every 10th must be served."""
    import random

    rng = random.Random(1234)
    proc, url = _start("--tcp", "127.0.0.1:0", "--seed", "4")
    host, port = url[len("socket://"):].rsplit(":", 1)
    try:
        for i in range(200):
            if i % 10 == 9:
                assert _inquiry(url).vendor == "IMPACTLB"
                continue
            with socket.create_connection((host, int(port)), timeout=2) as c:
                kind = rng.randrange(3)
                if kind == 0:
                    c.sendall(rng.randbytes(rng.randrange(1, 5000)))
                elif kind == 1:
                    cbw = P.encode_cbw(i, 36, True, P.build_cdb(P.Op.INQUIRY, length=36))
                    c.sendall(cbw[:rng.randrange(1, 31)])
                else:
                    c.sendall(P.encode_cbw(i, 36, True, P.build_cdb(P.Op.INQUIRY, length=36)))
        assert proc.poll() is None
    finally:
        _stop(proc)
