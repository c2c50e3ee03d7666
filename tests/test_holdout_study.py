"""The one-place hold-out study's section changes (benchmarks/studies/diagnosis_one_place.py): drawn in their
stated range, written as the frame's configuration states a member's section, scored by their own rule."""
from __future__ import annotations

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
