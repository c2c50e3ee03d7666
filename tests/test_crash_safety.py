"""Crash safety: the capture process killed (SIGKILL) at points the test controls (after hit k, inside
the next hit's transfers or at its prompt, or during start-up) keeps every reported hit, and
``capture --resume`` finishes the plan from the killed recording (benchmarks/reliability/crash_kill.py runs the
same with 50+ kills). No outcome depends on the machine's speed: the capture cannot finish before
the kill because it waits for operator answers that the trial withholds."""
from __future__ import annotations

from benchmark_modules import load_benchmark


def _crash_module():
    return load_benchmark("reliability/crash_kill.py")


def test_five_random_kills_lose_no_reported_hit_and_resume_completes(tmp_path):
    crash = _crash_module()
    trials = crash.run_kills(5, tmp_path, seed=7, resume_every=5, hits=30, workers=3)
    problems = [(t.index, t.problems) for t in trials if not t.ok]
    assert not problems
    assert all("ended by itself" not in t.phase for t in trials)  # every trial is a kill
    after_hits = [t for t in trials if t.phase.startswith("after hit")]
    assert after_hits and all(t.reported_accepted >= int(t.phase.split()[2]) for t in after_hits)
    assert sum(t.reported_accepted for t in trials) > 0
    assert all(t.recorded_accepted >= t.reported_accepted for t in trials)
    assert trials[0].resumed is True or not trials[0].file_opened


def test_resume_refuses_a_changed_plan(tmp_path, capsys):
    from acquisition.cli_capture import main

    assert main(["--resume", str(tmp_path / "none.h5"), "--points", "top:4:X"]) == 2
    assert "drop --out, --points" in capsys.readouterr().err
    assert main(["--resume", str(tmp_path / "none.h5")]) == 2
    assert "not found" in capsys.readouterr().err


def test_resume_removes_a_hit_cut_short_and_appends_after_the_last_complete_one(tmp_path):
    import h5py
    import numpy as np

    from analysis.hit import Hit
    from analysis.recording import Recording
    from analysis.recording_writer import RecordingWriter
    from analysis.spectra import WindowSettings

    p = tmp_path / "rec.h5"
    hit = dict(eu_per_count=[0.01, 0.02], volts_per_count=[3e-5, 1.5e-4], trigger_index=8, sample_rate_hz=6400.0,
               timestamp=1.0, measurement=0, point="right:6:-X", reference="right:6:-X", outputs=["left:9:Y"],
               force_channel=0, response_channels=[1], overload=[False, False], accepted=True)
    counts = [np.full((2, 16), k, dtype=np.int16) for k in range(3)]
    with RecordingWriter(p, instrument={}, setup={}, channels=[], windows=WindowSettings()) as w:
        for k in range(3):
            w.write_hit(Hit(counts=counts[k], sequence=k + 1, **hit))
    with h5py.File(p, "r+") as f:  # as if the writer died while writing hit 2
        del f["hits/000002"].attrs["complete"]
    with RecordingWriter.resume(p) as w:
        assert w.n_hits == 2
        assert w.write_hit(Hit(counts=counts[0] + 7, sequence=9, **hit)) == 2
    with Recording(p) as rec:
        hits = list(rec.hits())
        assert [h.sequence for h in hits] == [1, 2, 9] and np.all(hits[2].counts == 7)
