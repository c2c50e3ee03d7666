"""What the simulation gets wrong: band/channel errors, mode pairing, lone peaks, coherence, noise."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from analysis.diagnosis.compare import compare, doubtful_coherence, error_db, line_weights, noise_level, pair_modes
from simulator.effects import add_frf_noise, base_model, simulate_with_effects

OUTS = ["left:9:Y", "top:4:X", "right:6:-X"]
REFS = ["right:6:-X"]
F = np.arange(2.0, 200.0, 0.125)


@pytest.fixture(scope="module")
def base():
    return base_model(None, OUTS, REFS)


def test_noise_level_matches_injected_relative_noise(base):
    clean = simulate_with_effects(base, OUTS, REFS, F)
    noisy = add_frf_noise(clean, np.random.default_rng(0), relative=0.01, floor_fraction=0.0)
    w = line_weights(noisy)
    true_db = error_db(noisy, clean.H, w)           # the error of the exact model is the noise
    assert true_db == pytest.approx(-40.0, abs=1.0)
    assert noise_level(noisy, w)["difference"] == pytest.approx(true_db, abs=1.5)


def test_pairing_sees_a_uniform_frequency_shift(base):
    meas = simulate_with_effects(base, OUTS, REFS, F, effects=[{"effect": "stiffness_shift", "factor": 0.98}])
    sim = simulate_with_effects(base, OUTS, REFS, F)
    modes = pair_modes(meas, sim)
    assert len(modes["pairs"]) >= 5
    for p in modes["pairs"]:
        assert p["df_percent"] == pytest.approx(100 * (1 / 0.98 - 1), abs=0.1)
        assert p["mac"] > 0.99
    assert modes["only_measured"] == [] and modes["only_simulated"] == []


def test_a_missing_mode_is_a_peak_only_in_the_measurement(base):
    R = np.array([[0.3], [-0.2], [0.25]]) * 0.3 / (2j * 2 * np.pi * 140.0)
    eff = {"effect": "missing_mode", "freq_hz": 140.0, "zeta": 0.005, "residue": np.stack([R.real, R.imag], -1).tolist()}
    meas = simulate_with_effects(base, OUTS, REFS, F, effects=[eff])
    sim = simulate_with_effects(base, OUTS, REFS, F)
    only = pair_modes(meas, sim)["only_measured"]
    assert any(abs(m["freq_hz"] - 140.0) < 0.2 for m in only)


def test_doubtful_coherence_ranges_and_band_errors(base):
    sim = simulate_with_effects(base, OUTS, REFS, F)
    coh = np.ones(sim.H.shape)
    dip = (F >= 50.0) & (F <= 52.0)
    coh[..., dip] = 0.5
    meas = replace(sim, coherence=coh)
    ranges = doubtful_coherence(meas)
    assert len(ranges) == 1
    assert ranges[0]["lo_hz"] == pytest.approx(50.0) and ranges[0]["hi_hz"] == pytest.approx(52.0)
    assert ranges[0]["min_coherence"] == pytest.approx(0.5)
    # a 10 % gain error on one channel shows on that channel only
    hot = replace(meas, H=meas.H * np.array([1.0, 1.1, 1.0])[:, None, None])
    c = compare(hot, sim)
    errs = {ch["output"]: ch["error_db"] for ch in c["channels"]}
    assert errs["top:4:X"] == pytest.approx(20 * np.log10(0.1 / 1.1), abs=0.5)
    assert errs["left:9:Y"] < -200
