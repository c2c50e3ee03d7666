"""A mass at every sensor told from a stiffness change, mode by mode (:mod:`analysis.diagnosis.mode_vote`).

The FRF files come from the benchmark's generator (``benchmarks/accuracy/frf_beam_cases.py``: a
continuous pinned beam solved by dynamic stiffness, sharing no code with the diagnosis). The plan of the
case below strikes the beam at 0.35 m of 1.01 m, near the node at a third of the span shared by its
third and sixth modes: their residues at the driving point are small, so their shapes at the sensors
(scaled by the driving point) are poorly known and a mass moves those two modes too little. Summed over
every line, a common frequency factor then fits better than the mass; mode by mode, the mass places the
other five modes where they are.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from benchmark_modules import load_benchmark

from analysis.diagnosis import diagnose
from analysis.diagnosis.mode_vote import mode_regions, mode_vote, separable

beam = load_benchmark("accuracy/frf_beam_cases.py")
EFFECTS = ["mass_loading", "stiffness_shift"]


def _case():
    case = beam.draw_cases(5813)[16]
    assert case.family == "mass_all" and len(case.sensors) == 4 and case.hammer == 0.35
    return case


def test_mode_regions_split_at_the_geometric_means() -> None:
    f = np.array([1.0, 9.9, 10.1, 15.0, 100.0, 1000.0])
    got = mode_regions(f, np.array([40.0, 10.0, 4.0]))          # unsorted modes: regions of 4, 10, 40 Hz
    np.testing.assert_array_equal(got, [0, 1, 1, 1, 2, 2])
    with pytest.raises(ValueError, match="at least one mode"):
        mode_regions(f, np.array([]))


def test_mode_vote_counts_the_regions_where_the_predictions_differ() -> None:
    """Three modes: a wins at the first, b at the second; the third's predictions differ by less than the
    noise can hide and its errors do not count."""
    f = np.array([9.0, 11.0, 19.0, 21.0, 39.0, 41.0])
    w = np.ones((1, 1, f.size))
    noise_db = -40.0                                           # noise power 1e-4 per line
    pa = np.zeros((1, 1, f.size), complex)
    pb = pa.copy()
    pb[..., :4] = 0.1                                          # difference 0.02 per region: 100 x the noise
    pb[..., 4:] = 1e-3                                         # 2e-6: below 2 x 1e-4 x 9
    ea = np.array([[[1.0, 1.0, 5.0, 5.0, 1.0, 1.0]]])
    eb = np.array([[[2.0, 2.0, 1.0, 1.0, 0.5, 0.5]]])
    vote = mode_vote(f, np.array([10.0, 20.0, 40.0]), ea, eb, pa, pb, w, noise_db)
    assert (vote["a"], vote["b"], vote["separable"]) == (1, 1, 2)
    assert [r["separable"] for r in vote["regions"]] == [True, True, False]
    assert separable(np.array([1.9e-3, 1.7e-3]), 1e-4).tolist() == [True, False]


def test_a_mass_at_every_sensor_with_the_driving_point_near_a_node(tmp_path: Path) -> None:
    """21.7 g at each of 4 sensors of a 2.17 kg beam: named a mass at every sensor, within 25 %."""
    case = _case()
    sim, meas = beam.write_case(case, tmp_path)
    d = diagnose(meas, sim, effects=EFFECTS)
    assert d.verdict == "mass_loading", [c["evidence"] for c in d.causes]
    got = d.named[0]["parameters"]
    assert got["sensor"] == "all"
    assert got["mass_kg"] == pytest.approx(case.truth["mass_kg"], rel=0.25)
    stiff = next(c for c in d.causes if c["effect"] == "stiffness_shift")
    mass = next(c for c in d.causes if c["effect"] == "mass_loading")
    # the modes vote for the mass; the stiffness keeps its significance only where the mass gains more
    assert "favour the mass" in stiff["evidence"]
    assert not stiff["significant"] or mass["gain_db"] > stiff["gain_db"]


def test_a_stiffness_change_on_the_same_plan_stays_a_stiffness_change(tmp_path: Path) -> None:
    """The same beam, plan and noise with the modulus x 0.955 (every frequency x 0.977, the shift of the
    mass above on average): the poorly scaled shapes do not make the mass win it."""
    case = _case()
    case = replace(case, family="stiffness", change={"modulus_factor": 0.955},
                   truth={"effect": "stiffness_shift", "stiffness_factor": 0.955})
    sim, meas = beam.write_case(case, tmp_path)
    d = diagnose(meas, sim, effects=EFFECTS)
    assert d.verdict == "stiffness_shift", [c["evidence"] for c in d.causes]
    assert d.named[0]["parameters"]["stiffness_factor"] == pytest.approx(0.955, rel=0.02)
