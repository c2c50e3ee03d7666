"""The one-place hold-out study's section changes (benchmarks/studies/diagnosis_one_place.py): drawn in their
stated range, written as the frame's configuration states a member's section, scored by their own rule; and the summary of hold-out runs (benchmarks/studies/diagnosis_holdout_summary.py)."""
from __future__ import annotations

import json

import numpy as np
import pytest
from benchmark_modules import load_benchmark

from simulator.config import FrameConfig


@pytest.fixture(scope="module")
def study():
    return load_benchmark("studies/diagnosis_one_place.py")


def test_section_changes_are_drawn_in_their_range_and_reproducibly(study) -> None:
    cases = study.draw_sections(5, 12)
    assert cases == study.draw_sections(5, 12)
    lo, hi = study.SECTION_SCALE
    for c in cases:
        assert c["family"] == "section_change" and c["place"] in ("left", "right", "top")
        f = np.array([c["width_factor"], c["depth_factor"]])
        assert np.all((f >= lo - 1e-4) & (f <= hi + 1e-4))
        assert np.max(np.abs(f - 1.0)) >= study.SECTION_MIN_CHANGE - 1e-4
    assert len({c["place"] for c in cases}) > 1


def test_a_section_change_gives_the_member_its_own_scaled_section(study, tmp_path) -> None:
    (case,) = [c for c in study.draw_sections(7, 6) if c["place"] == "left"][:1]
    path = tmp_path / "frame.toml"
    path.write_text(study.frame_toml(case))
    base, cfg = FrameConfig.load(), FrameConfig.load(path)
    sec, new = base.sections["column"], cfg.sections[cfg.components["left"].section]
    assert cfg.components["left"].section != "column" and new.shape == "rect"
    assert new.width_m == pytest.approx(sec.width_m * case["width_factor"])
    assert new.depth_m == pytest.approx(sec.depth_m * case["depth_factor"])
    assert cfg.components["right"] == base.components["right"] and cfg.sections["column"] == sec
    assert cfg.components["left"].roll_deg == base.components["left"].roll_deg


def test_a_section_change_is_right_only_when_every_named_cause_is_its_member_s(study) -> None:
    case = {"family": "section_change", "place": "right"}
    cfg = study.frame()

    def named(*causes: tuple[str, dict]) -> dict:
        return {"verdict": "combined" if len(causes) > 1 else causes[0][0] if causes else "unexplained",
                "named": [{"effect": e, "parameters": p} for e, p in causes]}

    stiff, mass = ("member_stiffness", {"component": "right", "factor": 1.3}), ("member_mass", {"component": "right",
                                                                                                 "factor": 1.1})
    assert study.score(case, named(stiff), cfg) == {"right": True, "named_among": True}
    assert study.score(case, named(stiff, mass), cfg)["right"]
    beside = study.score(case, named(stiff, ("added_mass", {"point": "right:10", "mass_kg": 0.4})), cfg)
    assert beside == {"right": False, "named_among": True}
    assert not study.score(case, named(("member_stiffness", {"component": "left", "factor": 1.3})), cfg)["named_among"]
    assert study.score(case, named(), cfg) == {"right": False, "named_among": False}


def test_the_holdout_summary_counts_each_family_and_lists_every_miss_with_its_truth(tmp_path) -> None:
    """The summary of hold-out runs: one row per file and family (named / cases, misses or false alarms), a
    fleet's defective units and its good units given a local cause, each miss with its truth and what was said."""
    summary = load_benchmark("studies/diagnosis_holdout_summary.py")
    cases = [{"name": "loose_support-00", "family": "loose_support", "place": "left:0", "factor": 0.2, "right": True,
              "verdict": "support_stiffness", "named": [], "cpu_s": 1.0, "cpu_children_s": 1.0},
             {"name": "soft_joint-01", "family": "soft_joint", "place": "top:8", "factor": 0.05, "right": False,
              "verdict": "joint_stiffness", "cpu_s": 3.0, "cpu_children_s": 0.5,
              "named": [{"effect": "joint_stiffness", "parameters": {"joint": "all", "factor_translational": 0.07}}]},
             {"name": "null-00", "family": "null", "setup": "plan", "right": False, "verdict": "missing_mode",
              "named": [], "cpu_s": 0.5, "cpu_children_s": 0.0}]
    fleet = [{"fleet": "fleet-0", "info": {"diagnosed": 2, "diagnosis_cpu_seconds": 10.0}, "units": [
        {"fleet": "fleet-0", "name": "unit-001", "flagged": True, "verdict": "support_stiffness", "right": True,
         "defect": {"family": "loose_support", "place": "right:0", "factor": 0.1},
         "named": [{"effect": "support_stiffness", "parameters": {"support": "right:0"}}]},
        {"fleet": "fleet-0", "name": "unit-002", "flagged": True, "verdict": "element_stiffness", "right": False,
         "defect": None, "named": [{"effect": "element_stiffness", "parameters": {"element": "top:3", "factor": 0.9}}]},
        {"fleet": "fleet-0", "name": "unit-003", "flagged": False, "verdict": None, "right": True, "defect": None,
         "named": []}]}]
    a, b = tmp_path / "one.results.json", tmp_path / "fleets.results.json"
    a.write_text(json.dumps(cases))
    b.write_text(json.dumps(fleet))
    text = summary.summary([a, b])
    assert "| one.results.json | loose_support | 1 | 1/1 | 0 misses | 2.0 / 2.0 |" in text
    assert "| one.results.json | soft_joint | 1 | 0/1 | 1 misses | 3.5 / 3.5 |" in text
    assert "| one.results.json | null | 1 | 0/1 | 1 false alarms |" in text
    assert ("| fleets.results.json | fleet (1 fleets) | 1 defective, 2 good | 1/1 | 0 missed; 1 good units given a "
            "local cause | 5.0 per flagged unit (mean) |") in text
    assert "- one.results.json soft_joint-01: soft_joint top:8 x0.05 -> `joint_stiffness`: joint_stiffness joint=all, " \
           "factor_translational=0.07" in text
    assert "- one.results.json null-00: unchanged (plan) -> `missing_mode`" in text
    assert "- fleets.results.json fleet-0 unit-002: good unit, flagged -> `element_stiffness`: element_stiffness " \
           "element=top:3, factor=0.9" in text
    assert "unit-001" not in text and "loose_support-00" not in text
