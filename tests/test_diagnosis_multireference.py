"""A multi-reference FRF file as the simulation: 3 hammer points x 3 accelerometers, the hammer struck at
the accelerometers' points (driving points), captured twice by the simulated analyser (different seeds).

Regression: the file's 0 Hz line, undefined in receptance, made every line weight of its FRFs NaN and the
pseudo-mode above the band crashed (``SVD did not converge in Linear Least Squares``); and a recording's
exponential window was counted twice (the measurement's window applied to a model whose correction already
held the simulation's), so two captures of one frame were named ``damping_change`` 0.88."""
from __future__ import annotations

import contextlib
import io
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from analysis.diagnosis.compare import line_weights
from analysis.frf import FRFSet
from analysis.modal import ModalModel, pole_from_fz, synthesize

POINTS = ("left:9:Y", "top:4:X", "right:4:-Z")        # the default set-up's accelerometers, struck there
EFFECTS = "stiffness_shift,damping_change,mass_loading,sensitivity_error"


def _model(points=POINTS) -> ModalModel:
    """A symmetric 3 x 3 receptance model (real modes, m/N) of four modes at the given points."""
    rng = np.random.default_rng(7)
    f = np.array([60.0, 150.0, 260.0, 370.0])
    lam = pole_from_fz(f, np.full(f.size, 0.01))
    phi = rng.normal(size=(len(points), f.size))
    R = np.einsum("or,ir->oir", phi, phi) / (2j * lam.imag)[None, None, :]
    return ModalModel(poles=lam, residues=R, quantity="receptance", outputs=points, references=points)


def _accelerance(model: ModalModel, freq_hz: np.ndarray, **kw) -> FRFSet:
    rec = synthesize(model, freq_hz)
    return replace(rec.as_quantity("accelerance"), **kw)


def test_weights_of_an_frf_with_a_0hz_line_in_receptance_are_finite():
    f = np.arange(0.0, 400.0, 0.5)
    sim = _accelerance(_model(), f).as_quantity("receptance")   # NaN at 0 Hz
    assert not np.all(np.isfinite(sim.H[..., 0]))
    w = line_weights(sim)
    assert np.all(np.isfinite(w)) and np.all(w[..., 0] == 0) and np.all(w[..., 1:] > 0)


def test_simulation_frfs_with_driving_points_and_an_exponential_window_are_reproduced():
    """The simulation's model (fitted, pseudo-mode above the band, refitted) seen through the simulated
    FRFs' own window and record gives those FRFs back, and its poles are the structure's (the window's
    decay removed)."""
    from analysis.diagnosis.effects import predict
    from analysis.diagnosis.entry import simulation_model
    from analysis.diagnosis.verdict import known_processing

    f = np.arange(0.0, 450.0, 0.25)
    truth = _model()
    tau = 0.5
    from analysis.diagnosis.processing import synthesize_windowed
    from analysis.frf import window_pole_shift

    H = synthesize_windowed(truth, f[1:], "accelerance", window_pole_shift(tau)).H
    H = np.concatenate([np.full(H.shape[:2] + (1,), 1e-3 + 0j), H], axis=2)        # a finite 0 Hz line
    sim = FRFSet(freq_hz=f, H=H, quantity="accelerance", outputs=POINTS, references=POINTS, exp_window_tau_s=tau)
    base = simulation_model(sim, sim)
    got = predict(base, f[1:], "accelerance", known_processing(sim)).H
    assert np.max(np.abs(got - sim.H[..., 1:])) < 1e-9 * np.max(np.abs(sim.H))
    in_band = np.sort(base.freq_hz[base.freq_hz < 400])
    assert in_band == pytest.approx(np.sort(truth.freq_hz), rel=1e-3)
    zeta = -base.poles.real / np.abs(base.poles)
    assert np.sort(zeta[base.freq_hz < 400]) == pytest.approx(0.01, rel=0.05)   # not 0.01 + the window's


@pytest.fixture(scope="module")
def captures(tmp_path_factory) -> dict:
    """Two captures of the frame and one with a 0.5 kg steel block at top:4 (0.32 s records, 513 lines)."""
    from benchmark_modules import load_benchmark

    from acquisition.cli_capture import main as capture
    from acquisition.setup import default_setup, setup_to_toml
    from simulator.config import FrameConfig, overrides_to_toml

    d = tmp_path_factory.mktemp("multiref")
    setup = d / "short.toml"
    setup.write_text(setup_to_toml(replace(default_setup(), sample_rate_hz=3200.0, block_size=1024)))
    block = d / "block.toml"
    bench = load_benchmark("accuracy/bench_diagnosis_physical.py")
    block.write_text(overrides_to_toml(bench.steel_block(FrameConfig.load(), "top:4", 0.5)))
    out = {}
    for name, device in (("a", "sim://?seed=1"), ("b", "sim://?seed=2"), ("block", f"sim://?seed=3&config={block}")):
        out[name] = d / f"{name}.h5"
        with contextlib.redirect_stdout(io.StringIO()):
            assert capture(["--device", device, "--setup", str(setup), "--out", str(out[name]), "--points",
                            ",".join(POINTS), "--hits", "3", "--auto", "-q"]) == 0
    return out


def _cli(tmp_path: Path, measured: Path, simulated: Path, effects: str = EFFECTS) -> dict:
    from analysis.cli_diagnose import main

    out = tmp_path / "d.json"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["--measured", str(measured), "--simulated", str(simulated), "--json", str(out),
                     "--effects", effects, "-q"]) == 0
    return json.loads(out.read_text())


def test_two_captures_of_the_frame_three_references_name_nothing(captures, tmp_path):
    doc = _cli(tmp_path, captures["b"], captures["a"])
    assert doc["verdict"] == "none", doc.get("reason")
    damping = next(c for c in doc["causes"] if c["effect"] == "damping_change")
    assert damping["parameters"]["factor"] == pytest.approx(1.0, abs=0.03)      # the window counted once
    assert "simulation" in doc["noise_db"]                                       # the simulated FRFs' own noise


def test_two_captures_as_uff_exports_name_nothing(captures, tmp_path):
    from acquisition.cli_export import main as export

    uff = {}
    for name in ("a", "b"):
        uff[name] = tmp_path / f"{name}.uff"
        with contextlib.redirect_stdout(io.StringIO()):
            assert export([str(captures[name]), "--uff", str(uff[name]), "-q"]) == 0
    doc = _cli(tmp_path, uff["b"], uff["a"], EFFECTS + ",mains_hum")
    # the mains lines' cross-validation scored the harmonics' amplitudes on the lines they were fitted to
    # (and the training harmonics in-sample): the two captures' noise was named mains_hum
    assert doc["verdict"] == "none" and doc["named"] == [], (doc["named"], doc.get("reason"))
    hum = next(c for c in doc["causes"] if c["effect"] == "mains_hum")
    assert not hum["significant"]


def test_python_api_with_frf_sets(captures):
    from analysis.diagnosis import diagnose
    from analysis.inputs import load_input

    a, b = load_input(captures["a"]), load_input(captures["b"])
    assert a.freq_hz[0] == 0 and a.references == POINTS
    # the four effects name nothing on these captures: test_two_captures_of_the_frame_three_references_name_nothing
    d = diagnose(b, a, band="data", effects=["damping_change"])
    assert d.verdict == "none" and d.named == []
    d = diagnose(b, a, effects=["damping_change"])                 # on all the sets' lines (the 0 Hz line left out)
    assert np.isfinite(d.error_before_db)


def test_a_block_on_the_frame_is_named_as_lowering_its_frequencies(captures, tmp_path):
    doc = _cli(tmp_path, captures["block"], captures["a"])
    assert doc["verdict"] in ("stiffness_shift", "mass_loading"), doc.get("reason")
    p = doc["named"][0]["parameters"]
    assert (p["factor"] < 1) if doc["verdict"] == "stiffness_shift" else (p["mass_kg"] > 0)
    # the seed-3 capture has one hit of left:9:Y struck elsewhere by the simulated hammer (its neighbour
    # probability): it is left out before the comparison. Averaged in, it had added an FRF difference the
    # catalogue's causes partly absorbed (2.9 dB); on the clean FRFs a lumped cause explains the block by
    # about 1 dB (1.5 dB with the hammer's misplaced and double hits switched off), so the named cause must
    # lower the error by the decision rule's own gain, not by a margin set on the contaminated FRFs.
    assert doc["trace"][0]["rule"] == "stray_hits"
    assert [d["reference"] for d in doc["trace"][0]["values"]["left_out"]] == ["left:9:Y"]
    assert doc["error_after_db"] < doc["error_before_db"] - doc["rule"]["min_gain_db"]
