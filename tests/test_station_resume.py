"""The station killed mid-test (SIGKILL at a point the test chooses: a hit on screen, undecided) and
resumed, by the station and by ``capture --resume``; and a capture's recording continued by the station."""
from __future__ import annotations

import subprocess
import sys

from station_support import WAIT_S, Api, StationProcess

POINTS = "right:6:-X,top:4:Z"


def _accept_hits(api: Api, n: int) -> None:
    """Arm and accept until ``n`` more hits are accepted at the current point (checks may reject some)."""
    target = api.state()["point_hits"] + n
    while True:
        st = api.state()
        if st["point_hits"] >= target:
            return
        if st["phase"] == "decide":
            assert api.act_here("accept")[0] == 200
        else:
            assert api.act("arm")[0] == 200
        seq = st["hit_seq"]
        api.wait(lambda s, q=seq, p=st["phase"]: (s["hit_seq"] > q and s["phase"] in ("decide", "ready", "complete"))
                 or (p == "decide" and s["phase"] in ("ready", "complete")), "the next hit")


def _recorded(path) -> tuple[list, list]:
    from analysis.recording import Recording

    with Recording(path) as rec:
        hits = list(rec.hits(skip_damaged=True))
        names = rec.measurement_names()
    return [sum(1 for h in hits if h.accepted and h.measurement == m) for m in (0, 1)], names


def test_killed_station_resumes_in_the_station_then_in_capture(tmp_path):
    rec = tmp_path / "rec.h5"
    s = StationProcess(["--device", "sim://?seed=5", "--out", str(rec), "--points", POINTS, "--hits", "3"], tmp_path)
    try:
        api = Api(s)
        assert api.lease() == (200, True)
        _accept_hits(api, 2)
        assert api.act("arm")[0] == 200
        api.wait(lambda st: st["phase"] == "decide", "a hit waiting for the operator")
    finally:
        s.kill()  # the hit on screen was never decided: it must not count
    assert _recorded(rec)[0] == [2, 0]

    s = StationProcess(["--resume", str(rec)], tmp_path)
    try:
        api = Api(s)
        assert api.lease() == (200, True)
        st = api.state()
        assert st["phase"] == "setup" and "arm" in st["allowed"]
        assert api.request("GET", "/api/blob/setup")[1]["editable"] is False
        assert api.act("arm")[0] == 200
        api.wait(lambda st: st["phase"] in ("decide", "ready") and st["point_hits"] >= 2, "the resumed point")
        _accept_hits(api, 3 - api.state()["point_hits"])
        api.wait(lambda st: st["phase"] == "complete", "point 1 complete")
        assert api.act_here("next-point")[0] == 200
        api.wait(lambda st: st["phase"] == "ready" and st["current"] == 1, "point 2")
        _accept_hits(api, 1)
        assert api.state()["current_point"] == "top:4:Z"
    finally:
        s.kill()
    assert _recorded(rec) == ([3, 1], ["m000"])

    done = subprocess.run([sys.executable, "-m", "acquisition", "capture", "--resume", str(rec), "--auto", "-q"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=WAIT_S, check=False)
    assert done.returncode == 0, done.stderr
    assert _recorded(rec) == ([3, 3], ["m000", "m001"])


def test_station_continues_a_capture(tmp_path):
    rec = tmp_path / "cap.h5"
    cap = subprocess.run([sys.executable, "-m", "acquisition", "capture", "--device", "sim://?seed=2", "--out", str(rec),
                          "--points", POINTS, "--hits", "2", "-q"], input="a\n", cwd=tmp_path, capture_output=True,
                         text=True, timeout=WAIT_S, check=False)  # one hit accepted, then the input ends: the test stops early
    assert cap.returncode == 3, cap.stderr  # ended early (exit code 3), every hit kept
    accepted, _ = _recorded(rec)
    assert accepted[1] == 0 and accepted[0] <= 1
    s = StationProcess(["--resume", str(rec), "--auto"], tmp_path)
    try:
        Api(s).wait(lambda st: st["phase"] == "finished", "the resumed plan to finish in auto mode")
        code, _out, err = s.stop()
        assert code == 0, err
    finally:
        if s.proc.poll() is None:
            s.kill()
    assert _recorded(rec) == ([2, 2], ["m000", "m001"])
