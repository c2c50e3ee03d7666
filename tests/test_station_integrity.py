"""The station never acts on what the operator did not see, and stays answerable.

- Actions name the hit or point they act on: a double click of "next point", "undo" or "accept"
  (the second request made from the same, now stale, page) is refused with 409 instead of skipping
  the next point with no hit, withdrawing a second hit or accepting the next hit unseen.
- Hits are numbered from 1 alike in the verdict and the log.
- Connections are bounded: half-sent requests are dropped (a deadline for head and body, the
  longest-waiting one closed when the bound is reached) and the excess beyond busy connections gets
  503; a valid request is still answered and the thread count stays bounded.
- Ctrl-C before the first hit is an early stop (130); the browser's favicon request is no error.

The station runs as a real process on sim:// (the API at the wire); the connection bound also runs
in-process on 127.0.0.1 with a small bound and deadline (real sockets, a stand-in engine)."""
from __future__ import annotations

import http.client
import json
import os
import signal
import socket
import threading
import time
from pathlib import Path

import pytest
from station_support import WAIT_S, Api, StationProcess

POINTS = "right:6:-X,top:4:Z"


def _one_hit_accepted(api: Api) -> dict:
    """Arm (again after a hit the checks rejected) until a hit waits for the decision; accept it."""
    while True:
        st = api.state()
        if st["phase"] == "decide":
            status, body = api.act_here("accept")
            assert status == 200, body
            return api.wait(lambda x: x["phase"] in ("ready", "complete"), "the accept")
        assert api.act_here("arm")[0] == 200
        api.wait(lambda x, q=st["hit_seq"]: x["hit_seq"] > q and x["phase"] in ("decide", "ready"), "a hit")


def test_a_double_next_point_is_refused_and_skips_nothing(tmp_path):
    from analysis.recording import Recording

    rec = tmp_path / "rec.h5"
    s = StationProcess(["--device", "sim://?seed=8", "--out", str(rec), "--points", POINTS, "--hits", "1"], tmp_path)
    try:
        api = Api(s)
        assert api.lease() == (200, True)
        _one_hit_accepted(api)
        st = api.wait(lambda x: x["phase"] == "complete", "point 1 complete")
        assert st["current"] == 0
        # a double click: both requests come from the page that shows point 1 complete
        first = api.act("next-point", point=0)
        second = api.act("next-point", point=0)
        assert first[0] == 200, first
        assert second[0] == 409 and "look at the page again" in second[1]["error"], second
        st = api.wait(lambda x: x["current"] == 1 and x["phase"] in ("ready", "finished"), "point 2")
        assert st["phase"] == "ready" and st["point_hits"] == 0  # point 2 waits for its hit, not skipped
        # a request from a page still showing point 1 is refused, naming both points
        status, body = api.act("next-point", point=0)
        assert status == 409 and "names point 1 but point 2 is on now" in body["error"]
        assert api.act("next-point")[0] == 400  # an action that does not say which point it means
        _one_hit_accepted(api)
        assert api.act_here("next-point")[0] == 200
        api.wait(lambda x: x["phase"] == "finished", "the end")
    finally:
        code, _out, err = s.stop()
    assert code == 0, err
    with Recording(rec) as r:
        assert r.measurement_names() == ["m000", "m001"]  # both points measured
        assert [h.measurement for h in r.hits() if h.accepted] == [0, 1]


def test_double_undo_and_double_accept_act_once_and_hits_are_numbered_from_1(tmp_path):
    from analysis.recording import Recording

    rec = tmp_path / "rec.h5"
    s = StationProcess(["--device", "sim://?seed=8", "--out", str(rec), "--points", "right:6:-X", "--hits", "3"],
                       tmp_path)
    try:
        api = Api(s)
        assert api.lease() == (200, True)
        # a hit waits for the decision: its number is the one it gets in the recording, from 1
        while (st := api.state())["phase"] != "decide":
            assert api.act_here("arm")[0] == 200
            api.wait(lambda x, q=st["hit_seq"]: x["hit_seq"] > q and x["phase"] in ("decide", "ready"), "a hit")
        n = api.state()["verdict"]["number"]
        assert api.act("accept")[0] == 400                      # which hit?
        assert api.act("accept", hit=n + 1)[0] == 409           # not the one on screen
        assert api.act("reject", hit=n)[0] == 200
        st = api.wait(lambda x: x["phase"] == "ready", "the rejection")
        assert st["verdict"]["number"] == n and st["verdict"]["state"] == "rejected"
        texts = [m["text"] for m in st["messages"]]
        assert f"hit {n} at right:6:-X rejected: rejected by the operator" in texts, texts
        _one_hit_accepted(api)
        # a double click of accept on the next hit: the second one is refused, the hit after it waits
        while (st := api.state())["phase"] != "decide":
            assert api.act_here("arm")[0] == 200
            api.wait(lambda x, q=st["hit_seq"]: x["hit_seq"] > q and x["phase"] in ("decide", "ready"), "a hit")
        n = st["verdict"]["number"]
        assert api.act("accept", hit=n)[0] == 200
        assert api.act("accept", hit=n)[0] == 409
        st = api.wait(lambda x: x["phase"] in ("ready", "complete"), "the accept")
        assert st["point_hits"] == 2
        # a double click of undo withdraws one hit, not two: refused while the first is carried out, and
        # refused after it (the second click still names the 2 hits the page showed), however fast the first was
        assert api.act("undo", point=0)[0] == 400                # how many hits did the page show?
        assert api.act("undo", point=0, hits=2)[0] == 200
        assert api.act("undo", point=0, hits=2)[0] == 409
        st = api.wait(lambda x: x["phase"] == "ready" and x["point_hits"] < 2, "the undo")
        assert st["point_hits"] == 1
        code, body = api.act("undo", point=0, hits=2)                # a late second click: the first is done
        assert code == 409 and "has 1 now" in str(body), body
        assert api.state()["point_hits"] == 1
        assert api.act_here("next-point")[0] == 200
        api.wait(lambda x: x["phase"] == "finished", "the end")
    finally:
        code, _out, err = s.stop()
    assert code == 0, err
    with Recording(rec) as r:
        hits = list(r.hits())
        events = [e[2] for e in r.events()]
    assert sum(h.accepted for h in hits) == 1
    assert [h.index for h in hits if "withdrawn by the operator (undo)" in h.reasons] == [hits[-1].index]
    assert f"hit {hits[-1].index + 1} at right:6:-X withdrawn: withdrawn by the operator (undo)" in events


# -- connections ------------------------------------------------------------------------------------
def _threads(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/task"))


def _half_open(host: str, port: int, n: int) -> list[socket.socket]:
    """``n`` connections that each sent part of a request head and then nothing more."""
    socks = []
    for _ in range(n):
        c = socket.create_connection((host, port), timeout=WAIT_S)
        c.sendall(b"GET /api/state HTTP/1.1\r\nHost: station\r\n")
        socks.append(c)
    return socks


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads in /proc")
def test_two_hundred_half_sent_requests_hold_no_threads_and_a_valid_request_answers(tmp_path):
    from acquisition.station.server import MAX_CONNECTIONS

    s = StationProcess(["--device", "sim://?seed=1", "--out", str(tmp_path / "rec.h5"), "--points", "right:6:-X"],
                       tmp_path)
    socks: list[socket.socket] = []
    try:
        api = Api(s)
        base = _threads(s.proc.pid)
        socks = _half_open(s.host, s.port, 200)
        status, st = api.request("GET", "/api/state")
        assert status == 200 and st["phase"] == "setup"
        bound = base + MAX_CONNECTIONS + 2
        end = time.monotonic() + WAIT_S  # the closed connections' threads end as they read the end of the stream
        while _threads(s.proc.pid) > bound and time.monotonic() < end:
            time.sleep(0.05)
        assert _threads(s.proc.pid) <= bound, (_threads(s.proc.pid), bound)
        assert s.proc.poll() is None
    finally:
        for c in socks:
            c.close()
        code, _out, err = s.stop()
    assert code == 130, err  # stopped before the test ended


class _Engine:
    """What the server needs of an engine for its state and event routes."""

    def __init__(self) -> None:
        from acquisition.station.state import StationState

        self.state = StationState()
        self.state.update(phase="setup")
        self.geometry = {"nodes": {}, "lines": []}

    def allowed(self) -> tuple:
        return ()


@pytest.fixture()
def small_server():
    from acquisition.station.server import StationServer

    server = StationServer(("127.0.0.1", 0), _Engine(), "tok", max_connections=4, request_deadline_s=0.5)
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    yield server
    server.shutdown()
    server.server_close()


def _get(server, path: str, token: str | None = "tok") -> tuple[int, bytes]:
    conn = http.client.HTTPConnection("127.0.0.1", server.server_address[1], timeout=WAIT_S)
    conn.request("GET", path, headers={"X-Station-Token": token} if token else {})
    r = conn.getresponse()
    body = r.read()
    conn.close()
    return r.status, body


def test_a_slow_client_is_dropped_at_the_deadline(small_server):
    port = small_server.server_address[1]
    c = socket.create_connection(("127.0.0.1", port), timeout=WAIT_S)
    c.sendall(b"GET /api/state HTTP/1.1\r\nHost: s")            # and then nothing: the head never ends
    assert c.recv(1024) == b""                                   # the server closed it (after 0.5 s)
    c.close()
    post = socket.create_connection(("127.0.0.1", port), timeout=WAIT_S)
    post.sendall(b"POST /api/lease HTTP/1.1\r\nHost: s\r\nX-Station-Token: tok\r\nContent-Length: 40\r\n\r\n{\"cli")
    answer = post.makefile("rb").read()                          # a body that never ends: 408, then closed
    assert answer.startswith(b"HTTP/1.1 408") and b"did not come within 0.5 s" in answer
    post.close()
    assert _get(small_server, "/api/state")[0] == 200


def test_connections_beyond_the_bound_get_503_when_all_are_busy(small_server):
    port = small_server.server_address[1]
    streams = []
    for _ in range(4):  # event streams: busy connections, never closed to make room
        c = http.client.HTTPConnection("127.0.0.1", port, timeout=WAIT_S)
        c.request("GET", "/api/events?token=tok")
        r = c.getresponse()
        assert r.status == 200 and r.fp.readline().startswith(b"event: state")
        streams.append(c)
    try:
        status, body = _get(small_server, "/api/state")
        assert status == 503 and "serves 4 connections at once" in json.loads(body)["error"]
    finally:
        for c in streams:
            c.close()
    end = time.monotonic() + WAIT_S  # the streams' threads notice the closed connections at their next write
    while _get(small_server, "/api/state")[0] != 200:
        assert time.monotonic() < end, "the bound never freed"
        small_server.engine.state.update(poke=time.monotonic())  # an event makes each stream write
        time.sleep(0.05)


def test_the_favicon_request_is_answered_without_the_token(small_server):
    assert _get(small_server, "/favicon.ico", token=None) == (204, b"")
    assert _get(small_server, "/api/state", token=None)[0] == 403


@pytest.mark.parametrize("sigint_ignored", [False, True], ids=["plain", "started-with-sigint-ignored"])
def test_ctrl_c_before_the_first_hit_exits_130(tmp_path, sigint_ignored):
    s = StationProcess(["--device", "sim://?seed=1", "--out", str(tmp_path / "rec.h5"), "--points", "right:6:-X"],
                       tmp_path, sigint_ignored=sigint_ignored)
    assert Api(s).state()["phase"] == "setup"
    s.proc.send_signal(signal.SIGINT)
    out, err = s.proc.communicate(timeout=WAIT_S)
    assert s.proc.returncode == 130, err
    assert "nothing was recorded" in out and not (tmp_path / "rec.h5").exists()
    assert "Traceback" not in err
