"""The commands end to end on the simulated frame over ``sim://``: capture -> recording -> replay ->
export, playback of a recording through the simulated analyser, the demo, and bad input (exit 2)."""
from __future__ import annotations

import hashlib

import numpy as np
import pytest
import pyuff

from acquisition.cli_capture import main as capture_main
from acquisition.cli_demo import main as demo_main
from acquisition.cli_export import main as export_main
from acquisition.cli_replay import main as replay_main
from acquisition.setup import default_setup
from analysis.recording import Recording, load_frfset
from analysis.uff import read_uff58


def sha(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def captured(sim_capture):
    """One roving-hammer capture on the simulated frame: 2 points x 3 hits (made once per session, shared)."""
    from conftest import TWO_POINTS_EXP

    return sim_capture(*TWO_POINTS_EXP)


def test_capture_writes_a_complete_recording(captured):
    with Recording(captured) as rec:
        assert rec.instrument["model"] == "SIGLAB-SIM 2042"
        assert rec.plan["mode"] == "roving_hammer" and rec.plan["points"] == ["right:6:-X", "top:4:Z"]
        assert [c["point"] for c in rec.channels] == ["right:6:-X", "left:9:Y", "top:4:X", "right:4:-Z"]
        assert rec.windows.exp_window_tau_s is not None and rec.windows.exp_window_end_fraction is None  # resolved from 5 %
        acc = list(rec.hits(accepted_only=True))
        assert len(acc) == 6 and {h.reference for h in acc} == {"right:6:-X", "top:4:Z"}
        assert all(h.counts.dtype == np.int16 and h.crc_ok for h in acc)
        assert rec.closed_cleanly
    s = load_frfset(captured)
    assert s.H.shape[:2] == (3, 2) and s.quantity == "accelerance" and s.unit == "(m/s^2)/N"
    setup = default_setup()  # 5 % at the block end: tau = (block - pre-trigger) / fs / ln 20
    assert s.exp_window_tau_s == pytest.approx(
        (setup.block_size - setup.trigger.pretrigger_samples) / setup.sample_rate_hz / np.log(20.0))


def test_replay_with_original_settings_is_bit_exact_and_leaves_original(captured, tmp_path):
    before = sha(captured)
    out = tmp_path / "replayed.h5"
    assert replay_main([str(captured), "--out", str(out)]) == 0
    assert sha(captured) == before
    a, b = load_frfset(captured), load_frfset(out)
    assert np.array_equal(a.H, b.H) and np.array_equal(a.coherence, b.coherence)
    # H2 = Gxx/Gxf is 0/0 (NaN) on an output that does not move (left:9:Y for in-plane blows)
    assert np.array_equal(load_frfset(captured, "H2").H, load_frfset(out, "H2").H, equal_nan=True)
    with Recording(captured) as r1, Recording(out) as r2:
        assert r1.n_hits == r2.n_hits
        assert all(np.array_equal(h1.counts, h2.counts) for h1, h2 in zip(r1.hits(), r2.hits()))


def test_replay_with_other_settings(captured, tmp_path):
    out = tmp_path / "other.h5"
    assert replay_main([str(captured), "--out", str(out), "--window", "force=5ms,1ms;exp=none",
                        "--exclude-hits", "0", "--estimator", "H2"]) == 0
    s = load_frfset(out)
    assert s.exp_window_tau_s is None and s.meta["n_averages"] == [2, 3]
    assert not np.array_equal(s.H, load_frfset(captured).H)
    with Recording(out) as rec:
        assert rec.windows.force_width_s == pytest.approx(0.005)
        assert any("replayed from" in e[2] for e in rec.events())


def test_export_uff_reads_back_the_same_numbers(captured, tmp_path):
    uff = tmp_path / "frf.uff"
    assert export_main([str(captured), "--uff", str(uff), "--time"]) == 0
    s = load_frfset(captured)
    back = read_uff58(uff)
    assert back.outputs == s.outputs and back.references == s.references
    assert np.array_equal(back.H, s.H) and np.array_equal(back.coherence, s.coherence)
    sets = pyuff.UFF(str(uff)).read_sets()
    types = [d["func_type"] for d in sets]
    assert types.count(4) == 6 and types.count(6) == 6 and types.count(1) == 6 * 4
    assert all("exp tau" in d["id3"] for d in sets if d["func_type"] == 4)
    with Recording(captured) as rec:
        first = next(rec.hits(accepted_only=True))
        assert np.array_equal(sets[12]["data"], first.data[0])


def test_recording_plays_back_through_the_simulated_analyser(captured, tmp_path):
    out = tmp_path / "played.h5"
    assert capture_main(["--device", f"sim://?replay={captured}", "--out", str(out), "--auto", "-q",
                         "--exp-window", "5%"]) == 0
    a, b = load_frfset(captured), load_frfset(out)
    assert b.references == a.references and b.meta["n_averages"] == [3, 3]
    good = (a.freq_hz > 20) & (a.freq_hz < 2000) & (a.coherence > 0.99)  # lines measured well
    assert good.sum() > 1000
    rel = np.abs(b.H - a.H)[good] / np.abs(a.H)[good]
    # the front end filters and requantises the replayed volts a second time: close (measured: median
    # 1.2 %), not identical; the bit-exact recomputation is `replay`
    assert np.median(rel) < 0.02


@pytest.mark.parametrize("argv,message", [
    (["capture", "--device", "nonsense", "--out", "X"], "invalid device URL"),
    (["capture", "--device", "sim://", "--out", "X", "--points", "left:nine:Y"], "bad point label"),
    (["capture", "--device", "sim://", "--out", "X", "--exp-window", "150%"], "between 0 and 100"),
    (["capture", "--device", "socket://localhost:1", "--seed", "2", "--out", "X"], "--seed applies"),
    (["capture", "--device", "sim://", "--out", "X", "--hits", "0"], "at least one hit"),
    (["replay", "MISSING.h5", "--out", "Y"], "not found"),
    (["replay", "NOTH5", "--out", "Y"], "not an HDF5 file"),
    (["export", "NOTH5", "--uff", "Y"], "not an HDF5 file"),
])
def test_bad_input_exit_2(tmp_path, capsys, argv, message):
    (tmp_path / "NOTH5").write_text("plain text")
    argv = [str(tmp_path / a) if a in ("X", "Y", "MISSING.h5", "NOTH5") else a for a in argv]
    cmd = {"capture": capture_main, "replay": replay_main, "export": export_main}[argv[0]]
    assert cmd(argv[1:]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_out_file_is_never_overwritten_silently(captured, tmp_path, capsys):
    assert capture_main(["--device", "sim://", "--out", str(captured), "--auto"]) == 2
    assert "exists" in capsys.readouterr().err
    assert replay_main([str(captured), "--out", str(captured)]) == 2


def test_demo(tmp_path, capsys):
    assert demo_main(["--out", str(tmp_path), "--hits", "2"]) == 0
    text = capsys.readouterr().out
    assert "double hit" in text and "overload" in text and "peak Hz" in text
    with Recording(tmp_path / "demo.h5") as rec:
        rejected = [h for h in rec.hits() if not h.accepted]
        assert len(rejected) >= 2  # the scripted double hit and overload (a random double hit may add one)
        assert any("double hit" in r for h in rejected for r in h.reasons)
        assert any("overload" in r for h in rejected for r in h.reasons)
        assert len(rec.measurement_names()) == 3
    assert read_uff58(tmp_path / "demo.uff").H.shape[:2] == (3, 3)


def test_capture_killed_mid_session_keeps_every_reported_hit(tmp_path):
    """SIGKILL a running ``python -m acquisition capture`` after it reported three written hits."""
    import signal
    import subprocess
    import sys

    rec = tmp_path / "killed.h5"
    proc = subprocess.Popen([sys.executable, "-m", "acquisition", "capture", "--device", "sim://", "--seed", "4",
                             "--out", str(rec), "--hits", "200", "--auto"], stdout=subprocess.PIPE, text=True)
    reported = 0
    try:
        for line in proc.stdout:
            if line.strip().startswith("progress:"):  # printed after the hit was written and flushed
                reported += 1
                if reported == 3:
                    break
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stdout.close()
    assert reported == 3 and proc.returncode == -signal.SIGKILL
    with Recording(rec) as r:
        assert not r.closed_cleanly
        hits = list(r.hits(skip_damaged=True))
        assert len(hits) >= 3 and all(h.crc_ok for h in hits)
        assert r.measurement_names() == []  # the average was not finished: FRFs come from a replay
    out = tmp_path / "recovered.h5"
    assert replay_main([str(rec), "--out", str(out)]) == 0
    assert load_frfset(out).meta["n_averages"][0] >= 3


def test_capture_asks_the_operator(tmp_path, monkeypatch, capsys):
    """Without --auto each hit that passed the checks is offered: a = accept, r = reject, q = quit."""
    import io

    monkeypatch.setattr("sys.stdin", io.StringIO("a\nr\nq\n"))
    rec = tmp_path / "asked.h5"
    # q on an incomplete test: exit code 3, every hit kept
    assert capture_main(["--device", "sim://?seed=8", "--out", str(rec), "--hits", "5"]) == 3
    cap = capsys.readouterr()
    assert "accept (a), reject (r), quit (q)?" in cap.out
    # the operator is told where to go and when to strike
    assert "point 1/1: move the hammer to right:6:-X and strike there" in cap.out
    assert "strike right:6:-X now (hit 1 at this point)" in cap.out and "(hit 3 at this point)" in cap.out
    assert "rejected hit #2 at point 1" in cap.out and "rejected hit #0" not in cap.out
    assert "capture --resume" in cap.err
    with Recording(rec) as r:
        assert [(h.accepted, h.reasons) for h in r.hits()] == [
            (True, []), (False, ["rejected by the operator"]), (False, ["test ended by the operator"])]
        assert any("ended early" in e[2] for e in r.events())
    assert load_frfset(rec).meta["n_averages"] == [1]


def test_capture_reports_each_points_excitation_band_and_warns_when_narrow(captured):
    """The medium tip's force spectrum is 20 dB down near 1.1 kHz, well inside the
    analyser's 2.5 kHz band: the summary says so per point and warns."""
    from acquisition.averaging import average_recorded_hits
    from acquisition.session import SessionResult
    from acquisition.terminal import summary_text
    from analysis.recording import Recording

    with Recording(captured) as rec:
        avgs = average_recorded_hits(list(rec.hits(accepted_only=True)), rec.windows, rec.channels)
    text = summary_text(SessionResult(averages=avgs, accepted=sum(a.n_averages for a in avgs)))
    bands = [line for line in text.splitlines() if "excitation band (force spectrum)" in line]
    assert len(bands) == 2
    e20 = [float(line.split("-20 dB at ")[1].split()[0]) for line in bands]
    assert all(900.0 < e < 1400.0 for e in e20), e20
    assert text.count("warning: the hammer excites this point only up to") == 2


def test_resume_continues_the_hit_count_the_rejections_and_the_simulated_stream(tmp_path, monkeypatch, capsys):
    """After 'q', --resume numbers its hits on from the recording's, lists the
    earlier rejections, and the simulated device does not play the same strikes again."""
    import io

    rec = tmp_path / "r.h5"
    monkeypatch.setattr("sys.stdin", io.StringIO("a\nr\nq\n"))
    assert capture_main(["--device", "sim://?seed=8", "--out", str(rec), "--points", "right:6:-X", "--hits", "3"]) == 3
    capsys.readouterr()
    with Recording(rec) as r:
        first = [h.counts.copy() for h in r.hits()]
    assert capture_main(["--resume", str(rec), "--auto"]) == 0
    out = capsys.readouterr().out
    assert "strike right:6:-X now (hit 4 at this point)" in out  # three hits were recorded before
    assert "rejected hit #2 at point 1" in out and "rejected hit #3 at point 1" in out
    with Recording(rec) as r:
        hits = list(r.hits())
    assert sum(h.accepted for h in hits) == 3
    for h in hits[3:]:
        assert not any(np.array_equal(h.counts, c) for c in first), "the resumed device repeated a recorded strike"


def test_sep005_export_import_round_trip(captured, tmp_path, capsys):
    """SEP005 (SDyPy's time-series exchange dicts) beside UFF: a recording's hits exported,
    valid for SDyPy's own checker when it is installed, and imported back into the same FRFs."""
    import json

    from acquisition.cli_export import main as export_main
    from acquisition.cli_import import main as import_main
    from analysis.sep005 import SEP005Error, check_sep005

    out = tmp_path / "hits.json"
    assert export_main([str(captured), "--sep005", str(out)]) == 0
    doc = json.loads(out.read_text())
    with Recording(captured) as rec:
        n_hits, n_ch = rec.n_hits, len(rec.channels)
    assert len(doc) == n_hits * n_ch and {"data", "name", "unit_str", "fs", "group"} <= set(doc[0])
    try:
        from sdypy_sep005.sep005 import assert_sep005
    except ImportError:
        pass
    else:
        assert_sep005(doc)
    # only the accepted hits of one point go back into a recording with the same averages (the hits
    # of the other point are refused: one import is one measurement, never hits relabelled)
    (tmp_path / "all.json").write_text(json.dumps([c for c in doc if c["accepted"]]))
    assert import_main([str(tmp_path / "all.json"), "--out", str(tmp_path / "mixed.h5")]) == 2
    assert "channel 'force' has point 'top:4:Z'" in capsys.readouterr().err
    at_first = {c["group"] for c in doc if c["name"] == "force" and c["point"] == "right:6:-X"}
    accepted = [c for c in doc if c["accepted"] and c["group"] in at_first]
    (tmp_path / "acc.json").write_text(json.dumps(accepted))
    back = tmp_path / "back.h5"
    assert import_main([str(tmp_path / "acc.json"), "--out", str(back), "--reference", "right:6:-X",
                        "--exp-window", "5%"]) == 0
    with Recording(back) as r:
        assert r.n_hits == sum(1 for c in accepted if c["name"] == accepted[0]["name"])
    # malformed documents are named, never a traceback
    with pytest.raises(SEP005Error, match="lacks unit_str"):
        check_sep005([{"data": [1.0, 2.0], "name": "x", "fs": 10.0}])
    with pytest.raises(SEP005Error, match="forbids the key 'timestamp'"):
        check_sep005([{"data": [1.0, 2.0], "name": "x", "unit_str": "N", "fs": 10.0, "timestamp": 0}])
    with pytest.raises(SEP005Error, match="give fs"):
        check_sep005([{"data": [1.0, 2.0], "name": "x", "unit_str": "N"}])
    (tmp_path / "bad.json").write_text("{not json")
    assert import_main([str(tmp_path / "bad.json"), "--out", str(tmp_path / "b.h5")]) == 2
    assert "not a JSON SEP005 file" in capsys.readouterr().err


def test_a_point_off_the_simulated_frame_is_refused_before_anything_is_written(tmp_path, capsys):
    """``--points top:40:Z`` on the simulated frame: exit 2, the message names the point, its node and
    the frame's nodes, and no recording is created (a retry needs no --overwrite)."""
    rec = tmp_path / "off.h5"
    assert capture_main(["--device", "sim://?seed=1", "--out", str(rec), "--points", "top:40:Z", "--auto"]) == 2
    err = capsys.readouterr().err
    assert "point top:40:Z: node top:40 is not on the simulated frame" in err
    assert "top:0..8" in err and "left:0..10" in err and "Traceback" not in err
    assert not rec.exists()
    from acquisition.cli_station import main as station_main

    assert station_main(["--device", "sim://?seed=1", "--out", str(rec), "--points", "top:40:Z"]) == 2
    assert "node top:40 is not on the simulated frame" in capsys.readouterr().err
    assert not rec.exists()


def test_a_capture_that_fails_before_its_first_hit_leaves_no_empty_recording(tmp_path, capsys, monkeypatch):
    from acquisition.session import CaptureSession, SessionError

    def refused(self):
        raise SessionError("the analyser refuses the set-up")

    monkeypatch.setattr(CaptureSession, "run", refused)
    rec = tmp_path / "failed.h5"
    assert capture_main(["--device", "sim://?seed=1", "--out", str(rec), "--auto", "-q"]) == 1
    assert "the analyser refuses the set-up" in capsys.readouterr().err
    assert not rec.exists()
