"""The station under hostile and careless clients: every bad request gets a 4xx and one log line
(never a dropped connection or a traceback), resets are logged in one line, NaN/Infinity never
reach the engine, 30 parallel clients are all served, and IPv6 loopback works."""
from __future__ import annotations

import json
import socket
import struct
import threading

import pytest
from station_support import Api, StationProcess

from analysis.input_limits import NESTING_LIMIT

POINTS = "left:9:Y,top:4:X"


@pytest.fixture(scope="module")
def station(tmp_path_factory):
    d = tmp_path_factory.mktemp("station_rel")
    s = StationProcess(["--device", "sim://?seed=5", "--out", str(d / "rec.h5"), "--points", POINTS, "--hits", "2"],
                       cwd=d)
    yield s
    if s.proc.poll() is None:
        s.stop()


def _raw(station, data: bytes) -> bytes:
    with socket.create_connection((station.host, station.port), timeout=30) as c:
        c.sendall(data)
        c.shutdown(socket.SHUT_WR)
        out = b""
        while chunk := c.recv(65536):
            out += chunk
    return out


def test_bad_requests_with_the_token_get_4xx_not_a_dropped_connection(station):
    api = Api(station, "rel-bad")
    assert api.lease(take=True) == (200, True)
    status, blob = api.request("GET", "/api/blob/setup")
    setup = blob["setup"]
    nul = _raw(station, b"GET /static/a\x00b.js HTTP/1.1\r\nHost: x\r\nX-Station-Token: " + station.token.encode()
               + b"\r\nConnection: close\r\n\r\n")
    assert nul.startswith(b"HTTP/1.1 404")
    cases = [
        api.request("GET", "/static/" + "a" * 5000),
        api.request("POST", "/api/setup/check", raw=b"[" * 30000 + b"]" * 30000),
        api.request("POST", "/api/setup/check", {"setup": setup, "windows": {"force": 5}}),
        api.request("POST", "/api/setup/check", {"setup": setup, "windows": {"force": ["x"], "exp": {}}}),
        api.request("POST", "/api/setup/check", raw=json.dumps({"setup": dict(setup, block_size=1)}).replace(
            '"block_size": 1', '"block_size": Infinity').encode()),
        api.request("POST", "/api/setup/check", {"setup": dict(setup, block_size="big")}),
        api.request("POST", "/api/setup/check", {"setup": dict(setup, channels="none")}),
    ]
    statuses = [c[0] for c in cases]
    assert all(400 <= s < 500 for s in statuses), statuses
    assert all(isinstance(c[1], dict) and c[1].get("error") for c in cases)
    assert "Infinity is not a JSON number" in cases[4][1]["error"]
    # nested deeper than the readers take, yet shallow enough for the parser: refused before it is parsed
    deep = api.request("POST", "/api/setup/check", raw=b'{"setup": ' + b"[" * 100 + b"]" * 100 + b"}")
    assert deep[0] == 400 and f"nested deeper than {NESTING_LIMIT} levels" in deep[1]["error"]


def test_a_nan_channel_name_is_rejected_before_anything_is_applied(station):
    api = Api(station, "rel-nan")
    assert api.lease(take=True) == (200, True)
    before = api.request("GET", "/api/blob/setup")[1]["setup"]
    body = json.dumps({"client": "rel-nan", "action": "setup", "setup": before}).replace(
        f'"name": {json.dumps(before["channels"][1]["name"])}', '"name": NaN', 1)
    assert '"name": NaN' in body
    status, err = api.request("POST", "/api/action", raw=body.encode())
    assert status == 400 and "NaN is not a JSON number" in err["error"]
    assert api.request("GET", "/api/blob/setup")[1]["setup"] == before
    assert api.act("arm")[0] == 200
    assert api.state()["phase"] != "error"


def test_thirty_parallel_clients_are_all_served(station):
    from acquisition.station.server import StationServer

    assert StationServer.request_queue_size >= 30  # the listen backlog holds every client's connection
    api = Api(station, "rel-many")
    failures: list = []

    def client() -> None:
        for _ in range(20):
            try:
                status, _ = api.request("GET", "/api/state")
                if status != 200:
                    failures.append(status)
            except OSError as exc:
                failures.append(type(exc).__name__)

    threads = [threading.Thread(target=client) for _ in range(30)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert failures == []


def test_resets_without_the_token_are_logged_without_tracebacks(tmp_path):
    s = StationProcess(["--device", "sim://?seed=6", "--out", str(tmp_path / "rec.h5"), "--points", POINTS,
                        "--hits", "2"], cwd=tmp_path)
    try:
        for k in range(30):
            c = socket.create_connection((s.host, s.port), timeout=10)
            c.sendall(b"POST /api/action HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\n{\"a\"" if k % 2 else b"GE")
            c.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            c.close()  # RST
        api = Api(s, "after-resets")
        assert api.request("GET", "/api/state")[0] == 200
        assert api.request("GET", "/api/state", token=None)[0] == 403
        assert api.request("POST", "/api/setup/check", raw=b"{bad")[0] == 400
    finally:
        code, out, err = s.stop()
    assert "Traceback" not in err, err[-2000:]
    assert sum("-> 400 malformed JSON" in line for line in err.splitlines()) == 1


@pytest.mark.skipif(not socket.has_ipv6, reason="no IPv6 in this Python")
def test_ipv6_loopback(tmp_path):
    try:
        with socket.socket(socket.AF_INET6) as probe:
            probe.bind(("::1", 0))
    except OSError:
        pytest.skip("no IPv6 loopback on this machine")
    s = StationProcess(["--device", "sim://?seed=7", "--out", str(tmp_path / "rec.h5"), "--points", POINTS,
                        "--hits", "2", "--host", "::1"], cwd=tmp_path)
    try:
        assert s.url.startswith("http://[::1]:")
        assert Api(s, "v6").request("GET", "/api/state")[0] == 200
    finally:
        code, _, err = s.stop()
    assert "Traceback" not in err
