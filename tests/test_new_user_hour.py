"""A new user's hour, following README and docs command by command: each thing that went wrong has a
test here (the examples themselves run in tests/test_examples_run.py)."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from acquisition.cli_capture import main as capture_main
from analysis.recording import Recording


@pytest.fixture(scope="module")
def rec(tmp_path_factory) -> Path:
    """The README tour's recording: one point, 5 hits, simulated frame (seed 1)."""
    path = tmp_path_factory.mktemp("hour") / "rec.h5"
    assert capture_main(["--device", "sim://?seed=1", "--out", str(path), "--hits", "5", "--auto", "-q"]) == 0
    return path


def test_a_soft_then_hard_capture_gives_linearity_its_two_levels(tmp_path, capsys) -> None:
    """capture --soft-hard prompts a soft then a hard series at each point, the simulated operator follows
    it, and 'linearity REC.h5' compares the two levels of that one recording."""
    from analysis.cli_linearity import main as linearity_main

    path = tmp_path / "levels.h5"
    assert capture_main(["--device", "sim://?seed=1", "--out", str(path), "--hits", "3", "--soft-hard", "--auto"]) == 0
    out = capsys.readouterr().out
    assert "strike right:6:-X now SOFT (hit 1 at this point; soft hit 1/3)" in out
    assert "strike right:6:-X now HARD (hit 4 at this point; hard hit 1/3)" in out
    with Recording(path) as r:
        peaks = [float(np.max(np.abs(h.data[0]))) for h in r.hits(accepted_only=True)]
        assert r.plan["levels"] == ["soft", "hard"] and r.plan["hits_per_point"] == 6
    assert len(peaks) == 6 and max(peaks[:3]) * 1.5 < min(peaks[3:]), peaks
    assert linearity_main([str(path)]) == 0
    assert "levels " in capsys.readouterr().out


def test_resuming_an_auto_capture_goes_on_automatically(tmp_path, monkeypatch, capsys) -> None:
    """A crash during an --auto capture; 'capture --resume' alone finishes it without asking (stdin closed)."""
    from acquisition import session as session_module

    path = tmp_path / "crash.h5"
    real_write = session_module.CaptureSession._write_hit
    written: list[int] = []

    def crash_after_two(self, hit):
        idx = real_write(self, hit)
        written.append(idx)
        if len(written) == 2:
            raise KeyboardInterrupt  # the program stops here, as a crash would after a hit on disk
        return idx

    monkeypatch.setattr(session_module.CaptureSession, "_write_hit", crash_after_two)
    assert capture_main(["--device", "sim://?seed=2", "--out", str(path), "--hits", "4", "--auto", "-q"]) == 130
    monkeypatch.setattr(session_module.CaptureSession, "_write_hit", real_write)
    monkeypatch.setattr("sys.stdin", io.StringIO(""))  # nobody at the keyboard
    capsys.readouterr()
    assert capture_main(["--resume", str(path)]) == 0
    out = capsys.readouterr().out
    assert "hits accepted automatically" in out and "recording completed" in out
    with Recording(path) as r:
        assert sum(h.accepted for h in r.hits()) == 4


def test_a_missed_trigger_names_the_level_and_how_to_change_it(tmp_path, capsys) -> None:
    """A trigger level above every hit: the message names the level (N) and the way to change it."""
    from acquisition.setup import default_setup, setup_to_toml

    setup = setup_to_toml(default_setup()).replace("level = 20.0", "level = 400.0")
    (tmp_path / "setup.toml").write_text(setup)
    code = capture_main(["--device", "sim://?seed=1", "--out", str(tmp_path / "r.h5"), "--hits", "1", "--auto",
                         "--setup", str(tmp_path / "setup.toml"), "--timeout", "0.2", "-q"])
    err = capsys.readouterr().err
    assert code == 1
    assert "trigger level 400 N" in err and "--setup" in err and "--timeout" in err, err


def test_replay_estimator_is_explained_and_the_fit_table_says_which_estimate(rec, tmp_path, capsys) -> None:
    from acquisition.cli_replay import main as replay_main
    from analysis.cli_fit import main as fit_main

    with pytest.raises(SystemExit):
        replay_main(["--help"])
    helps = " ".join(capsys.readouterr().out.split())
    assert "--estimator {H1,H2,h1,h2} the FRF estimate the new recording prefers" in helps, helps
    assert fit_main([str(rec), "--band", "100:300", "-q"]) == 0
    assert "LSFD (lm) fit of H1, residues of" in capsys.readouterr().out


def test_stabilization_heads_its_columns_and_names_visible_modes_without_a_pole(rec, tmp_path, capsys) -> None:
    """The README's 'stabilization rec.h5 --max-order 30': the weak low modes beside the strong ones
    get no stable pole in 12.5-1102 Hz; the command says so and how to get them."""
    from analysis.cli_stabilization import main as stab_main

    assert stab_main([str(rec), "--png", str(tmp_path / "s.png"), "--max-order", "30"]) == 0
    got = capsys.readouterr()
    header = got.out.splitlines()[1].split()
    assert header[0] == "pole" and header[1:3] == ["f", "[Hz]"]
    warn = [ln for ln in got.err.splitlines() if "have no stable pole up to order 30" in ln]
    assert warn and all(f in warn[0] for f in ("35.", "50.", "81.")), got.err


def test_diagnose_prints_its_verdict_without_json_and_says_what_is_not_significant(rec, capsys) -> None:
    from analysis.cli_diagnose import NOT_SIGNIFICANT
    from analysis.cli_diagnose import main as diagnose_main

    frame = Path(__file__).resolve().parents[1] / "simulator" / "frame.toml"
    assert diagnose_main(["--measured", str(rec), "--simulated", str(frame), "--effects",
                          "mains_hum,residual_modes"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("verdict: ")
    causes = [ln for ln in out.splitlines() if "held-out error" in ln]
    assert causes
    for ln in causes:
        assert ln.lstrip().startswith("*") != ln.endswith(NOT_SIGNIFICANT), ln
