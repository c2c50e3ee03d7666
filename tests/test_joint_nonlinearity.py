"""The joint_nonlinearity cause: which spring's strain-energy shares the modes' level dependence follows
(analysis.diagnosis.joint_nonlinearity), on hand-made patterns and on the time-domain frame."""
from __future__ import annotations

import numpy as np
import pytest

from analysis.diagnosis import joint_nonlinearity as jn
from analysis.diagnosis.joint_nonlinearity import JointCandidate, joint_nonlinearity
from analysis.linearity import LinearityResult, ModeShift

F = np.array([10.0, 40.0, 90.0, 150.0, 230.0])
SHARES = {"joint a ry": np.array([0.10, 0.001, 0.12, 0.002, 0.05]),
          "joint b ry": np.array([0.08, 0.09, 0.001, 0.07, 0.001]),
          "support c ry": np.array([0.002, 0.03, 0.04, 0.001, 0.10])}


class _Shares:
    def joint_candidates(self):
        return F, [JointCandidate(name, name.split()[0], (name.split()[1],), "ry", 1e4, s)
                   for name, s in SHARES.items()]


def _result(df_percent, dzeta_percent, verdict="nonlinear"):
    modes = tuple(ModeShift(freq_hz=f, zeta=0.01, df_percent=d, df_std_percent=0.005, dzeta_percent=z,
                            dzeta_std_percent=1.0, df_percent_per_decade=d, dzeta_percent_per_decade=z,
                            significant=abs(d) > 0.02) for f, d, z in zip(F, df_percent, dzeta_percent))
    n = len(modes)
    return LinearityResult(levels=(20.0, 400.0), modes=modes, verdict=verdict, band=(5.0, 300.0),
                           freq_hz=np.tile(F, (2, 1)), zeta=np.full((2, n), 0.01), freq_hz_std=np.zeros((2, n)),
                           zeta_std=np.zeros((2, n)))


def test_the_spring_whose_shares_the_softening_follows_is_named():
    a, b = -0.1, 0.05  # stiffness -10 %, loss factor +0.05
    s = SHARES["joint b ry"]
    df = 100 * s * a / 2
    dz = 100 * (s * b / 2) / 0.01
    c = joint_nonlinearity(_result(df, dz), _Shares())
    assert c["present"] and c["joint"]["name"] == "joint b ry"
    assert c["law"]["kind"] == "micro-slip friction"
    assert c["law"]["stiffness_change_percent"] == pytest.approx(-10.0, rel=1e-6)
    assert c["law"]["loss_factor_change"] == pytest.approx(0.05, rel=1e-6)
    assert c["method"] == "strain-energy shares"


def test_every_mode_alike_is_not_a_joint_and_linear_is_absent():
    c = joint_nonlinearity(_result(np.full(5, -0.5), np.full(5, 0.0)), _Shares())
    assert not c["present"] and c["global_chi2"] < c["chi2"][0]["chi2"]
    c = joint_nonlinearity(_result(np.zeros(5), np.zeros(5), verdict="linear"), _Shares())
    assert c == {"effect": "joint_nonlinearity", "present": False, "evidence": c["evidence"]}
    assert "do not change" in c["evidence"]


@pytest.mark.long
def test_time_domain_frame_joint_named_by_simulated_hits(monkeypatch):
    from quality_support import level_hits

    from analysis.linearity import compare_levels, level_frfsets
    from simulator.config import FrameConfig
    from simulator.nonlinear_simulation import JointHitSimulation

    base = {"joints": {"stiffness": [1e9, 1e9, 1e9, 1e8, 2e4, 1e8]},
            "supports": {"stiffness": [1e9, 1e9, 1e9, 1.6e7, 5e4, 1.6e7]}}
    points = ("right:6:-X", "left:6:X", "top:4:Z")
    cfg = FrameConfig.from_dict({**base, "nonlinear": {"law": "iwan", "joint": "right:10", "axis": "ry",
                                                       "slip_moment_nm": 2.0}})
    hits = level_hits(cfg, 0, n_hits=4, points=points)
    lv, sets = level_frfsets(hits)
    res = compare_levels(sets, lv, band=(5.0, 400.0))
    monkeypatch.setattr(jn, "N_SIMULATED", 2)
    sim = JointHitSimulation(FrameConfig.from_dict(base), points, hits[0].outputs, lv, 1024.0, 4096, 64)
    c = joint_nonlinearity(res, sim)
    assert c["present"] and c["method"] == "simulated hits"
    assert "right:10" in c["joint"]["nodes"] and c["joint"]["axis"] == "ry"
    assert 1.0 < c["law"]["slip_moment_nm"] < 4.0


def test_the_diagnosis_carries_the_level_stage_and_a_present_joint_becomes_its_verdict(monkeypatch):
    from analysis.diagnosis import entry
    from analysis.diagnosis.verdict import Diagnosis

    linear = Diagnosis(verdict="element_stiffness", causes=[], error_before_db=-20.0, error_after_db=-30.0,
                       noise_db={"difference": -40.0}, comparison={}, unexplained=[], measured=None,
                       simulated=None, extended=None, named=[{"effect": "element_stiffness", "parameters": {}}])
    cause = {"effect": "joint_nonlinearity", "present": True, "evidence": "the modes follow the joint right:10 ry",
             "joint": {"name": "joint right:10-top:8 ry", "nodes": ["right:10", "top:8"], "axis": "ry"},
             "law": {"stiffness_change_percent": -3.0, "kind": "micro-slip friction", "levels": [20.0, 400.0]}}
    seen = {}

    def compare(recording, band, simulation):
        seen.update(recording=recording, band=band, simulation=simulation)
        return {"linearity": {"verdict": "nonlinear"}, "cause": cause}

    monkeypatch.setattr(jn, "level_dependence", compare)
    factory = object()
    got = entry._level_stage(linear, "rec.h5", (5.0, 400.0), factory)
    assert seen == {"recording": "rec.h5", "band": (5.0, 400.0), "simulation": factory}
    assert got.verdict == "joint_nonlinearity" and got.linear_verdict == "element_stiffness"
    assert got.named == [{"effect": "joint_nonlinearity", "evidence": cause["evidence"],
                          "parameters": {"joint": "joint right:10-top:8 ry", "stiffness_change_percent": -3.0,
                                         "kind": "micro-slip friction"}}]
    doc = got.to_json()
    assert doc["verdict"] == "joint_nonlinearity" and doc["linear_verdict"] == "element_stiffness"
    assert doc["level_dependence"]["cause"]["joint"]["axis"] == "ry" and linear.verdict == "element_stiffness"
    # an absent cause keeps the FRF comparison's verdict; no levels to compare leave the diagnosis as it is
    monkeypatch.setattr(jn, "level_dependence", lambda *a: {"linearity": {"verdict": "linear"}})
    kept = entry._level_stage(linear, "rec.h5", (5.0, 400.0), None)
    assert kept.verdict == "element_stiffness" and kept.linear_verdict is None and "linear_verdict" not in kept.to_json()
    assert kept.to_json()["level_dependence"] == {"linearity": {"verdict": "linear"}}
    monkeypatch.setattr(jn, "level_dependence", lambda *a: None)
    assert entry._level_stage(linear, "rec.h5", (5.0, 400.0), None) is linear
