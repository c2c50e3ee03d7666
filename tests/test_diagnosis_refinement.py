"""A refinement of a cause (a mass's rotary inertia about one axis) is kept when it predicts the held-out modes
better, even when one mode has no witness but itself.

A heavy block of its own size makes a mode that a point mass with a cube's rotary inertia has not; only the
inertia about one axis brings it. Left out, that mode is predicted by neither the mass alone nor the mass with
its inertia (nothing else pins the inertia), so it holds a capped chi2 in both, and summed over all modes it
drowned what the inertia gains on every other mode. The data: the noise-free modes of the frame with a 4.7 kg
steel block (12.2 x 10.5 x 4.7 cm) across the left column at node 6, on the joint springs, as the configuration
states an attached body (not the diagnosis' point mass).
"""
from __future__ import annotations

import numpy as np
import pytest
from shared_frames import frame_variants
from test_diagnosis_physical import OUTS, REFS, _sensor_masses

from analysis.diagnosis.physical import (
    MAX_MODES,
    MODE_CHI2_MAX,
    MeasuredModes,
    _best_variant,
    _refinement_bar,
    refinement_gain_bound,
    refinement_gain_db,
)
from analysis.diagnosis.rule import DEFAULT_RULE, gain_db
from simulator.config import FrameConfig
from simulator.fem import FrameModel

FMAX = 700.0
MASS_KG = 4.6855


def _block_modes() -> MeasuredModes:
    """The lowest MAX_MODES noise-free modes of the frame with the block (a component of two elements across the
    column, its own section, its middle node on the joint springs at left:6)."""
    base = FrameConfig.load()
    b, h, span = 0.1218, 0.105, 0.0467            # m; 7850 kg/m^3: 4.6855 kg
    z = 0.4008                                    # left:6, m
    cfg = base.with_overrides({
        "sections": {"block": {"shape": "explicit", "area_m2": b * h, "iy_m4": b * h ** 3 / 12, "iz_m4": h * b ** 3 / 12,
                               "j_m4": 2.2649e-05}},
        "components": {"block": {"section": "block", "start_m": [0.0, -span / 2, z], "end_m": [0.0, span / 2, z],
                                 "n_elements": 2, "roll_deg": 0.0}},
        "joints": {"pairs": [list(p) for p in base.joints.pairs] + [["left:6", "block:1"]]}})
    model = FrameModel.from_config(cfg, _sensor_masses(cfg)).modal_model(OUTS, REFS, "receptance")
    keep = np.flatnonzero((model.freq_hz > 1.0) & (model.freq_hz < 460.0))[:MAX_MODES]
    return MeasuredModes(model.freq_hz[keep], np.zeros(keep.size), model.residues[..., keep].reshape(-1, keep.size))


def test_a_heavy_block_s_rotary_inertia_is_kept_though_one_mode_alone_witnesses_it() -> None:
    """Fitted by added_mass, the block's inertia about Y is set free (its best variant predicts the held-out modes
    far better than the mass alone); before, the mass alone was kept (its held-out chi2 234 against 182, 1.1 dB, the
    mode at 347 Hz capped in both) and the diagnosis said unexplained."""
    fv = frame_variants(None, OUTS, REFS)
    spec = {c.name: c for c in fv.causes()}["added_mass"]
    best = _best_variant(fv, spec, _block_modes(), FMAX)
    assert best is not None and best.params["point"] == "left:6"
    assert "inertia_y" in best.free
    assert best.params["mass_kg"] == pytest.approx(MASS_KG, rel=0.02)
    iy = best.params["inertia_y"] * best.params.get("inertia_factor", 1.0)
    assert iy == pytest.approx(1.83, rel=0.05)        # the block's inertia about Y: 1.83 times a cube's of its mass
    assert best.chi2_cv < 20.0


def test_one_mode_neither_variant_predicts_is_left_out_of_the_refinement_s_gain() -> None:
    current = np.array([0.1, 131.0, 0.2, 3.2, 99.0])
    refined = np.array([0.1, 34.0, 0.2, 2.7, 145.0])
    assert gain_db(current, refined) < 3.0              # summed over all modes: the lost mode drowns the gain
    assert refinement_gain_db(current, refined) == pytest.approx(gain_db(current[:4], refined[:4]))
    assert refinement_gain_db(current, refined) > 5.0
    # a mode the refinement predicts is counted; two modes lost in both are both counted
    assert refinement_gain_db(current, np.array([0.1, 34.0, 0.2, 2.7, 1.0])) == pytest.approx(
        gain_db(current, np.array([0.1, 34.0, 0.2, 2.7, 1.0])))
    two = np.array([0.1, 131.0, 99.0, 3.2, 99.0])
    assert refinement_gain_db(two, two * 0.9) == pytest.approx(gain_db(two, two * 0.9))


def test_the_refinement_s_bar_holds_every_refined_variant_that_can_win() -> None:
    """The bar (the most held-out chi2 a winning refinement may have) is at least the chi2 of any refined variant
    that gains the rule's dB: the refined variant's own lost mode at the most one mode can hold."""
    current = np.array([0.1, 31.0, 0.2, 3.2, 99.0])
    scale = 10 ** (-DEFAULT_RULE.physical_min_gain_db / 10)
    winner = np.r_[current[:4] * scale * 0.999, MODE_CHI2_MAX]
    assert refinement_gain_db(current, winner) >= DEFAULT_RULE.physical_min_gain_db
    assert np.sum(winner) <= _refinement_bar(current, DEFAULT_RULE)
    plain = np.array([1.0, 2.0, 3.0])
    assert _refinement_bar(plain, DEFAULT_RULE) == pytest.approx(6.0 * scale)


def test_the_refinement_s_gain_bound_holds_every_held_out_chi2_its_folds_may_still_reach() -> None:
    """Part way through a refinement's folds (the folds done, each remaining mode at least its chi2 at the fit on all
    modes), the bound on its gain is at least the gain of every way the remaining folds may come out (a mode lost or
    not, in either variant), and equal to the gain once every fold is done."""
    rng = np.random.default_rng(7)
    for _ in range(400):
        K = int(rng.integers(3, 9))
        current = rng.uniform(0.0, 40.0, K)
        current[rng.random(K) < 0.3] = rng.uniform(50.0, 200.0)           # modes the current variant loses
        refined = rng.uniform(0.0, 40.0, K)
        refined[rng.random(K) < 0.3] = rng.uniform(50.0, 200.0)
        least = refined * rng.uniform(0.0, 1.0, K)                         # each mode's chi2 on all modes: below
        assert refinement_gain_bound(current, refined, least[K:]) == refinement_gain_db(current, refined)
        for d in range(K):
            bound = refinement_gain_bound(current, refined[:d], least[d:])
            assert refinement_gain_db(current, refined) <= bound
            assert refinement_gain_db(current, np.r_[refined[:d], least[d:]]) <= bound
    # a mode lost by the current variant: the comparison without it is the most the refinement can gain
    current = np.array([0.1, 131.0, 0.2, 3.2, 99.0])
    assert refinement_gain_bound(current, np.array([0.1]), np.array([34.0, 0.2, 2.7, 1.0])) == pytest.approx(
        gain_db(current[[0, 2, 3, 4]], [0.1, 0.2, 2.7, 1.0]))
