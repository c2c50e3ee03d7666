"""``python -m analysis diagnose``: files in, JSON and report out, clear errors."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from analysis.cli_diagnose import main
from analysis.diagnosis import EFFECTS
from analysis.uff import write_uff58
from simulator.effects import add_frf_noise, base_model, simulate_with_effects

OUTS = ["left:9:Y", "top:4:X", "right:6:-X"]
REFS = ["right:6:-X"]
F = np.arange(2.0, 150.0, 0.5)
TOML = str(Path(__file__).resolve().parents[1] / "simulator" / "frame.toml")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("diag")
    base = base_model(None, OUTS, REFS)
    eff = [{"effect": "time_delay", "delay_s": 3e-4}]
    meas = add_frf_noise(simulate_with_effects(base, OUTS, REFS, F, "accelerance", eff), np.random.default_rng(3))
    write_uff58(d / "m.uff", meas, overwrite=True)
    write_uff58(d / "s.uff", simulate_with_effects(base, OUTS, REFS, F, "accelerance"), overwrite=True)
    return d


#: the catalogue but its two costly modal searches (a mass, a resonator: several seconds each on the frame's 36 modes);
#: the whole catalogue through the command is the help example ``diagnose --measured rec.h5 --simulated
#: simulator/frame.toml`` (tests/test_examples_run.py), the catalogue's ranking the blind cases
CHEAP_EFFECTS = ",".join(n for n in EFFECTS if n not in ("mass_loading", "local_resonator"))


def test_toml_simulation_json_and_report(files, capsys):
    out = files / "out.json"
    rep = files / "rep"
    assert main(["--measured", str(files / "m.uff"), "--simulated", TOML, "--json", str(out),
                 "--report", str(rep), "--effects", CHEAP_EFFECTS]) == 0
    doc = json.loads(out.read_text())
    assert doc["verdict"] == "time_delay"
    assert set(doc) >= {"verdict", "causes", "error_before_db", "error_after_db"}
    gains = [c["gain_db"] for c in doc["causes"]]
    assert gains == sorted(gains, reverse=True)
    top = doc["causes"][0]
    assert top["effect"] == "time_delay" and top["parameters"]["delay_s"] == pytest.approx(3e-4, rel=0.02)
    assert doc["error_after_db"] < doc["error_before_db"] - 10
    text = (rep / "report.md").read_text()
    assert "Verdict: `time_delay`" in text
    assert (rep / "bands.png").stat().st_size > 1000 and (rep / "frf_0_0.png").exists()
    terminal = capsys.readouterr().out
    assert "verdict: time_delay" in terminal
    # why this verdict: the trace, in the JSON, report.md and on the terminal, the verdict's rule among its steps
    chosen = [s for s in doc["trace"] if s["rule"] == "largest_gain"]
    assert chosen and chosen[0]["cause"] == "time_delay" and chosen[0]["outcome"] == "verdict time_delay"
    assert "## Why this verdict" in text and "largest_gain time_delay: verdict time_delay" in text
    why = terminal.index("why this verdict:")
    assert terminal.index("verdict: time_delay") < why < terminal.index("largest_gain time_delay") < terminal.index(
        "error before")


def test_uff_simulation_gives_same_frf_effect(files):
    out = files / "out2.json"
    assert main(["--measured", str(files / "m.uff"), "--simulated", str(files / "s.uff"), "--json", str(out),
                 "--effects", "time_delay,sensor_highpass,sensitivity_error,residual_modes"]) == 0
    doc = json.loads(out.read_text())
    assert doc["verdict"] == "time_delay"
    assert doc["causes"][0]["parameters"]["delay_s"] == pytest.approx(3e-4, rel=0.02)


def test_bad_inputs_exit_2_with_message(files, capsys):
    assert main(["--measured", str(files / "nope.uff"), "--simulated", TOML, "--json", str(files / "x.json")]) == 2
    assert "not found" in capsys.readouterr().err
    assert main(["--measured", str(files / "m.uff"), "--simulated", TOML, "--json", str(files / "x.json"),
                 "--effects", "gremlins"]) == 2
    assert "unknown effect" in capsys.readouterr().err
    assert main(["--measured", str(files / "m.uff")]) == 2
    assert "required" in capsys.readouterr().err


def test_recording_with_hits_adds_time_data(tmp_path):
    from test_diagnosis_physical import _short_setup

    from acquisition.cli_capture import main as capture_main

    rec = tmp_path / "rec.h5"
    # a 1.28 s record (see test_unchanged_frame_captured_with_an_exponential_window_is_none for the 5.12 s default)
    assert capture_main(["--device", "sim://", "--seed", "3", "--out", str(rec), "--points", "right:6:-X",
                         "--hits", "4", "--auto", "-q", "--setup", _short_setup(tmp_path)]) == 0
    out = tmp_path / "d.json"
    assert main(["--measured", str(rec), "--simulated", TOML, "--json", str(out), "--band", "3:400",
                 "--effects", "stiffness_shift,sensitivity_error"]) == 0
    doc = json.loads(out.read_text())
    names = {c["effect"] for c in doc["time_data"]}
    assert names == {"double_hit", "overload", "input_noise", "amplitude_nonlinearity"}
    amp = next(c for c in doc["time_data"] if c["effect"] == "amplitude_nonlinearity")
    assert not amp["present"] and "two levels" in amp["evidence"]     # one force level: untestable, said so
    noise = next(c for c in doc["time_data"] if c["effect"] == "input_noise")
    assert noise["parameters"]["noise_rms_n"] > 0
    # the simulated frame and the simulated capture agree in frequency: no stiffness shift above 0.5 %
    st = next(c for c in doc["causes"] if c["effect"] == "stiffness_shift")
    assert abs(st["parameters"]["factor"] - 1) < 0.005
