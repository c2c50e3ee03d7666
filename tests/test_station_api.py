"""The station's HTTP API at the wire: token, control lease, bad requests (4xx, nothing changes, the
session survives), set-up validation, undo, and the recording it writes (the real process on sim://)."""
from __future__ import annotations

import pytest
from station_support import Api, StationProcess

POINTS = "right:6:-X,top:4:Z"


@pytest.fixture(scope="module")
def station(tmp_path_factory):
    d = tmp_path_factory.mktemp("station_api")
    s = StationProcess(["--device", "sim://?seed=3", "--out", str(d / "rec.h5"), "--points", POINTS, "--hits", "2"],
                       cwd=d)
    s.rec = d / "rec.h5"
    yield s
    if s.proc.poll() is None:
        s.stop()


def accept_until_complete(api: Api) -> None:
    """Arm (again after a rejected hit) and accept until the point is complete."""
    while True:
        st = api.state()
        if st["phase"] == "complete":
            return
        if st["phase"] == "decide":
            assert api.act_here("accept")[0] == 200
            api.wait(lambda x: x["phase"] in ("ready", "complete"), "the accept")
        else:
            assert api.act("arm")[0] == 200
            api.wait(lambda x, q=st["hit_seq"]: x["hit_seq"] > q and x["phase"] in ("decide", "ready"), "a hit")


def _key(st: dict) -> tuple:
    return (st["phase"], st.get("point_hits"), st["hit_seq"], st.get("total_accepted"), st.get("current"))


def test_bound_to_localhost_with_a_random_token(station):
    assert station.url.startswith("http://127.0.0.1:")
    assert len(station.token) >= 24


@pytest.mark.parametrize("method,path", [("GET", "/"), ("GET", "/api/state"), ("GET", "/static/station.js"),
                                         ("GET", "/api/blob/setup"), ("GET", "/api/events"),
                                         ("POST", "/api/action"), ("POST", "/api/lease")])
def test_every_request_without_the_token_is_refused(station, method, path):
    api = Api(station)
    body = {"client": "x", "action": "arm"} if method == "POST" else None
    assert api.request(method, path, body, token=None)[0] == 403
    assert api.request(method, path, body, token="wrong" + station.token)[0] == 403
    assert api.request(method, path + "?token=nope", body, token=None)[0] == 403


def test_the_page_cookie_opens_the_static_files_but_not_the_api(station):
    api = Api(station)
    status, _ = api.request("GET", f"/?token={station.token}", token=None)
    assert status == 200
    cookie = {"Cookie": f"impactlab_station={station.token}"}
    assert api.request("GET", "/static/station.js", token=None, headers=cookie)[0] == 200
    assert api.request("GET", "/api/state", token=None, headers=cookie)[0] == 403
    assert api.request("POST", "/api/action", {"client": "x", "action": "finish"}, token=None, headers=cookie)[0] == 403


def test_the_event_stream_sends_the_state_at_once_and_on_each_change(station):
    import http.client
    import json

    conn = http.client.HTTPConnection(station.host, station.port, timeout=60)
    conn.request("GET", f"/api/events?token={station.token}")
    r = conn.getresponse()
    assert r.status == 200 and r.getheader("Content-Type") == "text/event-stream"

    def next_event() -> dict:
        lines = []
        while True:
            line = r.fp.readline().decode()
            if line == "\n" and lines:
                break
            if line.startswith("data: "):
                lines.append(line[6:])
        return json.loads("".join(lines))

    first = next_event()
    assert first["phase"] == "setup" and "allowed" in first
    api = Api(station, "sse-tab")
    assert api.lease(take=True) == (200, True)
    assert api.act("pause")[0] == 200
    while not (ev := next_event())["paused"]:
        pass
    assert ev["version"] > first["version"]
    assert api.act("resume")[0] == 200
    conn.close()


def test_bad_requests_get_4xx_and_change_nothing(station):
    api = Api(station, "bad-requests")
    assert api.lease(take=True) == (200, True)
    before = _key(api.state())
    cases = [
        api.act("explode"),                                                     # unknown action
        api.act_here("accept"),                                                      # not possible in this phase
        api.request("POST", "/api/action", raw=b"{not json"),                    # malformed JSON
        api.request("POST", "/api/action", raw=b"[1, 2]"),                       # not an object
        api.request("POST", "/api/action", raw=b"\xff\xfe"),                     # not UTF-8
        api.request("POST", "/api/action", {"client": 7, "action": "arm"}),      # bad client type
        api.request("POST", "/api/action", {"client": "bad-requests"}),          # no action
        api.request("POST", "/api/action", raw=b"x" * 70000),                    # too large
        api.request("GET", "/static/../server.py"),                             # path traversal
        api.request("GET", "/static/../../cli_station.py"),
        api.request("GET", "/static/%2e%2e/engine.py"),
        api.request("GET", "/static//etc/passwd"),
        api.request("GET", "/api/blob/../../etc/passwd"),
        api.request("GET", "/nowhere"),
        api.request("POST", "/api/nowhere", {}),
        api.act("auto", on="yes"),                                               # bad parameter
    ]
    statuses = [c[0] for c in cases]
    assert all(400 <= s < 500 for s in statuses), statuses
    assert statuses[0] == 400 and statuses[1] == 409 and statuses[7] == 413
    assert all("error" in c[1] for c in cases if isinstance(c[1], dict))
    after = api.state()
    assert _key(after) == before and after["auto"] is False
    assert station.proc.poll() is None  # the session survives


def test_only_the_controlling_tab_acts(station):
    a, b = Api(station, "tab-a"), Api(station, "tab-b")
    assert a.lease(take=True) == (200, True)
    assert b.lease() == (200, False)              # a second tab is read-only ...
    assert b.act("pause")[0] == 409
    assert b.state()["controller"] == "tab-a"     # ... but sees the same session
    assert b.lease(take=True) == (200, True)              # until it takes control explicitly
    assert a.act("pause")[0] == 409
    assert b.act("resume")[0] == 200


def test_setup_is_validated_against_the_analyser_before_it_is_sent(station):
    api = Api(station, "setup-tab")
    assert api.lease(take=True) == (200, True)
    status, blob = api.request("GET", "/api/blob/setup")
    assert status == 200 and blob["editable"] is True and blob["capabilities"]["ranges_v"]
    setup = blob["setup"]
    bad = {**setup, "channels": [dict(setup["channels"][0], range_v=3.3)] + setup["channels"][1:]}
    status, err = api.request("POST", "/api/setup/check", {"setup": bad})
    assert status == 422 and "3.3 V is not offered" in err["error"]
    status, err = api.request("POST", "/api/setup/check", {"setup": setup, "windows": {"force": "-5ms"}})
    assert status == 422 and "bad duration" in err["error"]
    assert api.act("setup", setup=bad)[0] == 422
    ranges = blob["capabilities"]["ranges_v"]
    bigger = min(r for r in ranges if r > setup["channels"][1]["range_v"])
    good = {**setup, "channels": [setup["channels"][0], dict(setup["channels"][1], range_v=bigger)] + setup["channels"][2:]}
    assert api.request("POST", "/api/setup/check", {"setup": good})[0] == 200
    assert api.act("setup", setup=good, windows={"force": "15ms,3ms", "exp": "none"})[0] == 200
    status, blob = api.request("GET", "/api/blob/setup")
    assert blob["setup"]["channels"][1]["range_v"] == bigger


def test_hits_undo_and_the_recording(station):
    from analysis.recording import Recording

    api = Api(station, "operator")
    assert api.lease(take=True) == (200, True)
    assert api.act("arm")[0] == 200
    st = api.wait(lambda s: s["phase"] in ("decide", "ready") and s["hit_seq"] >= 1, "the first hit")
    while st["phase"] != "decide":  # a hit rejected by the checks: arm again
        assert api.act("arm")[0] == 200
        seq = st["hit_seq"]
        st = api.wait(lambda s, q=seq: s["hit_seq"] > q and s["phase"] in ("decide", "ready"), "a hit")
    for name in ("hit", "frf"):
        status, _blob = api.request("GET", f"/api/blob/{name}")
        assert status == 200
    assert api.act_here("accept")[0] == 200
    st = api.wait(lambda s: s["phase"] == "ready" and s["point_hits"] == 1, "the accepted hit")
    assert api.act_here("undo")[0] == 200
    st = api.wait(lambda s: s["point_hits"] == 0 and s["phase"] == "ready", "the undo")
    assert api.act_here("undo")[0] == 409  # nothing left to undo
    assert api.act("auto", on=True)[0] == 200
    st = api.wait(lambda s: s["phase"] == "finished", "the plan to finish in auto mode")
    code, _out, err = station.stop()
    assert code == 0, err
    with Recording(station.rec) as rec:
        hits = list(rec.hits())
        assert rec.plan["front_end"] == "station"
        assert rec.setup["channels"][1]["range_v"] > 5.0  # the set-up applied before the start
        frfs = rec.frfsets()
    withdrawn = [h for h in hits if "withdrawn by the operator (undo)" in h.reasons]
    assert len(withdrawn) == 1 and not withdrawn[0].accepted
    per_point = [sum(1 for h in hits if h.accepted and h.measurement == m) for m in (0, 1)]
    assert per_point == [2, 2]
    assert [s.meta["n_averages"] for s in frfs] == [2, 2]
    assert [s.references[0] for s in frfs] == POINTS.split(",")


def test_link_faults_show_as_messages_and_the_test_goes_on(tmp_path):
    s = StationProcess(["--device", "sim://?seed=4&faults=phase_error:0.2,garbage:0.05&fault_seed=2", "--out",
                        str(tmp_path / "rec.h5"), "--points", "right:6:-X", "--hits", "3", "--auto"], tmp_path)
    try:
        api = Api(s)
        st = api.wait(lambda x: x["phase"] in ("finished", "error"), "the auto-mode test to end")
        assert st["phase"] == "finished", st.get("error")
        texts = [m["text"] for m in st["messages"]]
        assert any("link fault" in t for t in texts), texts
        assert any(m["level"] == "WARNING" for m in st["messages"])
    finally:
        code, _out, err = s.stop()
    assert code == 0, err


def test_overload_advice_pause_remeasure_and_skip(tmp_path):
    from analysis.recording import Recording

    rec = tmp_path / "rec.h5"
    s = StationProcess(["--device", "sim://?seed=6&faults=overload:0.6&fault_seed=1", "--out", str(rec),
                        "--points", POINTS, "--hits", "2"], tmp_path)
    try:
        api = Api(s)
        assert api.lease() == (200, True)
        advice = None
        while advice is None or api.state()["point_hits"] < 1:
            st = api.state()
            assert st["phase"] in ("setup", "decide", "ready"), st["phase"]
            if st["phase"] == "decide":
                assert api.act_here("reject" if st["point_hits"] else "accept")[0] == 200
                api.wait(lambda x: x["phase"] == "ready", "the decision")
                continue
            seq = st["hit_seq"]
            assert api.act("arm")[0] == 200
            st = api.wait(lambda x, q=seq: x["hit_seq"] > q and x["phase"] in ("decide", "ready"), "a hit")
            if st["verdict"]["state"] == "rejected" and any(st["verdict"]["overload"]):
                assert "overload" in " ".join(st["verdict"]["reasons"])
                advice = st["verdict"]["advice"]
        assert advice and "set its range to" in advice[0] and "force" in advice[0]
        assert api.act("pause")[0] == 200
        assert api.act("arm")[0] == 409 and api.state()["paused"] is True
        assert api.act("resume")[0] == 200
        assert api.act_here("remeasure")[0] == 200
        api.wait(lambda x: x["point_hits"] == 0 and x["phase"] == "ready", "the point cleared")
        assert api.act_here("next-point")[0] == 200  # skip it
        api.wait(lambda x: x["current"] == 1 and x["phase"] == "ready", "the second point")
        assert api.act("auto", on=True)[0] == 200
        api.wait(lambda x: x["phase"] == "finished", "the end")
    finally:
        code, _out, err = s.stop()
    assert code == 0, err
    with Recording(rec) as r:
        hits = list(r.hits())
        assert r.measurement_names() == ["m001"]  # the skipped point has no FRF
    again = [h for h in hits if "point measured again by the operator" in h.reasons]
    assert len(again) == 1 and not again[0].accepted and again[0].measurement == 0
    assert not any(h.accepted for h in hits if h.measurement == 0)
    assert sum(h.accepted for h in hits if h.measurement == 1) == 2
    assert any(any("overload" in x for x in h.reasons) for h in hits)


def test_an_earlier_point_is_measured_again_during_and_after_the_test(tmp_path):
    from analysis.recording import Recording

    rec = tmp_path / "rec.h5"
    s = StationProcess(["--device", "sim://?seed=8", "--out", str(rec), "--points", POINTS, "--hits", "1"], tmp_path)
    one_hit = accept_until_complete

    try:
        api = Api(s)
        assert api.lease() == (200, True)
        one_hit(api)
        assert api.act_here("next-point")[0] == 200
        api.wait(lambda x: x["current"] == 1 and x["phase"] == "ready", "point 2")
        one_hit(api)
        assert api.act("remeasure", point=5)[0] == 400
        assert api.act("remeasure", point=0)[0] == 200          # back to point 1 before moving on
        api.wait(lambda x: x["current"] == 0 and x["phase"] == "ready" and x["point_hits"] == 0, "point 1 again")
        one_hit(api)
        assert api.act_here("next-point")[0] == 200
        api.wait(lambda x: x["phase"] == "finished", "the end (point 2 kept its hit)")
        assert api.act("remeasure", point=1)[0] == 200          # and point 2 after the end
        api.wait(lambda x: x["current"] == 1 and x["phase"] == "ready" and x["point_hits"] == 0, "point 2 again")
        one_hit(api)
        assert api.act_here("next-point")[0] == 200
        api.wait(lambda x: x["phase"] == "finished", "the end")
    finally:
        code, _out, err = s.stop()
    assert code == 0, err
    with Recording(rec) as r:
        hits = list(r.hits())
        groups = {name: r.frf_group(name) for name in r.measurement_names()}
        assert r.closed_cleanly
    again = [h for h in hits if "point measured again by the operator" in h.reasons]
    assert sorted(h.measurement for h in again) == [0, 1] and not any(h.accepted for h in again)
    accepted = [h for h in hits if h.accepted]
    assert sorted(h.measurement for h in accepted) == [0, 1]
    assert {int(g["measurement"]): list(g["hits"]) for g in groups.values()} == {h.measurement: [h.index] for h in accepted}


def test_a_test_hit_is_shown_with_range_advice_and_not_recorded(tmp_path):
    rec = tmp_path / "rec.h5"
    s = StationProcess(["--device", "sim://?seed=9&faults=overload:1&fault_seed=1", "--out", str(rec),
                        "--points", POINTS, "--hits", "2"], tmp_path)
    try:
        api = Api(s)
        assert api.lease() == (200, True)
        assert api.act("test-hit")[0] == 200
        st = api.wait(lambda x: x["hit_seq"] >= 1 and x["phase"] == "setup", "the test hit")
        v = st["verdict"]
        assert v["state"] == "test" and v["overload"][0] and "test hit: not recorded" in v["reasons"]
        assert any("overloaded at 1 V" in a for a in v["advice"])
        assert api.request("GET", "/api/blob/hit")[0] == 200
        assert api.state()["blobs"].get("frf") is None  # nothing averaged
        assert not rec.exists()  # nothing recorded before the test starts
    finally:
        code, out, err = s.stop()
    assert code == 130, err  # stopped before the test ended: early
    assert "nothing was recorded" in out


def test_finish_on_a_complete_plan_is_not_an_early_end(tmp_path):
    """Finish pressed once every point has its hits: the footer and the log say finished, never
    "ended early"; Finish before the plan is complete says it ended early."""
    from analysis.recording import Recording

    for points, complete in (("right:6:-X", True), ("right:6:-X,top:4:Z", False)):
        rec = tmp_path / f"rec{int(complete)}.h5"
        s = StationProcess(["--device", "sim://?seed=8", "--out", str(rec), "--points", points, "--hits", "1"],
                           tmp_path)
        try:
            api = Api(s)
            assert api.lease() == (200, True)
            accept_until_complete(api)
            assert api.act("finish")[0] == 200
            st = api.wait(lambda x: x["phase"] == "finished", "the end")
        finally:
            code, _out, err = s.stop()
        assert code == 0, err
        texts = [m["text"] for m in st["messages"]]
        if complete:
            assert "ended early" not in st["summary"] and not any("ended early" in t for t in texts), texts
            assert "test finished: the recording is complete" in texts
        else:
            assert "(ended early)" in st["summary"] and any("test ended early" in t for t in texts), texts
            assert "test finished: the recording is complete" not in texts
        with Recording(rec) as r:
            assert any("ended early" in e[2] for e in r.events()) is not complete
            assert r.measurement_names() == ["m000"]
