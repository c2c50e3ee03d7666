"""Blind diagnosis of the time-data effects on hits from the simulated stand (simulator.time_effects).

Each time-data effect is injected once, in a seeded random order with random physical parameters
(``draw_time_effect``), into 8 hits at two force levels (fs 2048 Hz, 4096 samples, 3 accelerometers);
the diagnosis runs on the hit arrays without knowing the effect and must name it, recover its
parameter within ``TIME_TOLERANCES`` (k and noise rms 15 %, hit counts exact) and show a significant
positive held-out gain. Clean hits must give ``none``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis.diagnosis.effects import predict
from analysis.diagnosis.timedata_gain import diagnose_time_effects, windowed_accelerance
from simulator.effect_oracle import TIME_ORACLE, TIME_TOLERANCES, draw_time_effect, time_primary_error
from simulator.stand import TestStand
from simulator.time_effects import NonlinearStand, simulate_hits

BAND = (5.0, 400.0)
TOML = Path(__file__).resolve().parents[1] / "simulator" / "frame.toml"
ORDER = [str(n) for n in np.random.default_rng(2026).permutation(list(TIME_ORACLE))]


@pytest.fixture(scope="module")
def stand() -> TestStand:
    return TestStand(seed=0)


def _diagnose(rec):
    return diagnose_time_effects(rec.force, rec.responses, rec.fs_hz, rec.base, BAND, full_scale=rec.full_scale,
                                 outputs=rec.outputs, reference=rec.reference)


@pytest.mark.parametrize("i", range(len(TIME_ORACLE)))
def test_hidden_time_effect_named_measured_and_gains(stand, i):
    rng = np.random.default_rng([2026, i])
    name = ORDER[i]
    eff = draw_time_effect(name, rng)
    rec = simulate_hits(eff, seed=100 + i, stand=None if name == "amplitude_nonlinearity" else stand)
    d = _diagnose(rec)
    assert d["verdict"] == name, [(c["effect"], c["present"], c["gain_db"]) for c in d["causes"]]
    cause = d["causes"][0]
    assert cause["effect"] == name and cause["present"] and cause["significant"]
    assert cause["gain_db"] > 3.0
    assert cause["error_after_db"] < cause["error_before_db"]
    assert time_primary_error(rec.effect, cause["parameters"], rec.n_hits) <= TIME_TOLERANCES[name]
    others = [c for c in d["causes"][1:] if c["counts"]]
    assert not others, others


def test_clean_hits_give_no_time_data_cause(stand):
    rec = simulate_hits(None, seed=7, stand=stand)
    d = _diagnose(rec)
    assert d["verdict"] == "none"
    assert not any(c["present"] for c in d["causes"])
    assert max(c["gain_db"] for c in d["causes"]) < 0.5
    assert d["error_before_db"] < -40.0      # the windowed simulation matches clean hits to ~1 %


def test_windowed_accelerance_matches_catalogue_without_window_and_scales_frequencies(stand):
    base = stand.model.modal_model(["left:9:Y", "top:4:X"], ["right:6:-X"], "receptance")
    f = np.linspace(5.0, 400.0, 500)
    for a in (1.0, 0.98):
        ref = predict(base, f, "accelerance", [{"effect": "stiffness_shift", "factor": a}]).H
        np.testing.assert_allclose(windowed_accelerance(base, f, None, a), ref, rtol=1e-9,
                                   atol=1e-12 * np.abs(ref).max())


def test_nonlinear_stand_scales_frequencies_by_peak_force():
    k = 2e-4
    st = NonlinearStand(seed=3, k_per_n=k)
    st.next_strike(double_hit=False, neighbour=False)
    ev = st.strike(2048.0, 1024, 64, noise=False)
    assert ev.info["frequency_factor"] == pytest.approx(1 - k * np.max(np.abs(ev.force_n)), rel=1e-12)
    lin = TestStand(seed=3)
    lin.next_strike(double_hit=False, neighbour=False)
    ev0 = lin.strike(2048.0, 1024, 64, noise=False)
    np.testing.assert_array_equal(ev.force_n, ev0.force_n)        # same hit, different frame
    assert not np.allclose(ev.response[1:], ev0.response[1:])
    assert st.model.modes().freq_hz[0] == lin.model.modes().freq_hz[0]   # linear between strikes


def test_the_diagnosis_adds_held_out_gains_to_time_data(tmp_path):
    from acquisition.cli_capture import main as capture_main
    from analysis.diagnosis import diagnose
    from analysis.inputs import load_input
    from simulator.physical import FrameVariants

    rec = tmp_path / "rec.h5"
    assert capture_main(["--device", "sim://", "--seed", "3", "--out", str(rec), "--points", "right:6:-X",
                         "--hits", "4", "--auto", "-q"]) == 0
    m = load_input(rec)
    doc = diagnose(rec, FrameVariants(TOML, m.outputs, m.references), band=(3.0, 400.0),
                   effects=["stiffness_shift"]).to_json()
    assert doc["time_data_verdict"] == "none"
    for c in doc["time_data"]:
        assert {"gain_db", "error_before_db", "error_after_db", "significant", "counts"} <= set(c)
        assert not c["counts"] and c["gain_db"] < 0.5
