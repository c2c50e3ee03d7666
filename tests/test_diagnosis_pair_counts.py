"""The pair search drops no choice by its rank alone: every first cause that gains anything held out, every second
cause on the screen on top of a first and every rival single cause in place of a named one is refined, and only a
proven bound (its refined chi2 on all modes against what it must beat) stops it before its held-out chi2. The frame
has two local defects (the FE frame's own modes, no noise); each test puts the right cause where a fixed count of
the best would leave it out (fifth first cause, sixth second cause, fourth rival) and asks that the pair is still
named, each change at its place with its factor."""
from __future__ import annotations

import copy
import functools
import json

import numpy as np
import pytest
from pair_stage_support import physical_stage
from shared_frames import frame_variants
from test_diagnosis_physical import OUTS, REFS, _noise_free_modes, _sensor_masses

from simulator.config import FrameConfig
from simulator.fem import FrameModel
from simulator.physical import FrameVariants

#: a loose support and a soft joint, and four causes (neither of them) that the tests rank before both
CAUSES = ["member_stiffness", "member_mass", "stiffness_shift", "mass_loading", "support_stiffness", "joint_stiffness"]
SUPPORT_AND_JOINT = {"loose_supports": ["left:0"], "loose_support_factor": [0.15],
                     "soft_joints": ["right:10"], "soft_joint_factor": [0.05]}
TWO_SUPPORTS = {"loose_supports": ["left:0", "right:0"], "loose_support_factor": [0.12, 0.3]}
#: the second causes tried on top of the rivals: only the supports' cause as a first cause makes the pair of supports,
#: so the rivals' ranks are what the test shows (the screens on top of them are smaller than the whole list's)
RIVAL_SECONDS = ["support_stiffness"]


def _searched(damage: dict, causes: list) -> tuple:
    """The single causes ``causes`` fitted and judged as the physical stage does (:mod:`physical_verdict`) on the
    frame with ``damage``: (simulation, specs, modes, fmax, fits, found, judge)."""
    cfg = FrameConfig.from_dict({"damage": damage})
    measured = FrameModel.from_config(cfg, _sensor_masses(cfg)).analytic_frf(OUTS, REFS, np.arange(8.0, 500.0, 0.25))
    mm = _noise_free_modes(FrameVariants(cfg, OUTS, REFS), [])
    fv, specs, fmax, judge = physical_stage(measured, mm)
    fits = copy.deepcopy(_single_fits(json.dumps(damage, sort_keys=True), tuple(causes)))
    found = [judge.single(specs[f.cause], f) for f in fits]
    return fv, specs, mm, fmax, fits, found, judge


@functools.cache
def _single_fits(damage: str, causes: tuple) -> list:
    """The single causes ``causes`` fitted on the frame with ``damage`` (JSON) as the physical stage fits them
    (:func:`physical_causes`): made once per module, two tests start from the same frame (each gets a copy)."""
    from analysis.diagnosis.physical import physical_causes
    from analysis.diagnosis.physical_verdict import FMAX_FACTOR

    cfg = FrameConfig.from_dict({"damage": json.loads(damage)})
    mm = _noise_free_modes(FrameVariants(cfg, OUTS, REFS), [])
    return physical_causes(frame_variants(None, OUTS, REFS), mm, FMAX_FACTOR * float(mm.freq_hz[-1]), list(causes))


def _named(c: dict | None) -> dict:
    """The named pair's changes by place."""
    assert c is not None and c["significant"] and c["adequate"], c and c.get("effect")
    return {p.get("support", p.get("joint")): p for p in (s["parameters"] for s in c["_stages"])}


def _both_supports(c: dict | None) -> None:
    got = _named(c)
    assert set(got) == {"left:0", "right:0"}
    assert got["left:0"]["factor_translational"] == pytest.approx(0.12, rel=0.02)
    assert got["right:0"]["factor_translational"] == pytest.approx(0.3, rel=0.02)


def _support_and_joint(c: dict | None) -> None:
    got = _named(c)
    assert set(got) == {"left:0", "right:10"}
    # the simulator's soft joint is not the catalogue's joint springs scaled: each factor within 10 %
    assert got["left:0"]["factor_translational"] == pytest.approx(0.15, rel=0.1)
    joint = got["right:10"]
    assert min(joint["factor_translational"], joint["factor_rotational"]) == pytest.approx(0.05, rel=0.1)


def _last(found: list, effects: tuple) -> list:
    """``found`` with ``effects`` last and every other cause ranked before them (significant, some gain held out)."""
    return ([{**c, "significant": True, "gain_db": max(c["gain_db"], 0.1)} for c in found if c["effect"] not in effects]
            + [{**c, "significant": False, "gain_db": max(c["gain_db"], 0.1)} for c in found if c["effect"] in effects])


def test_first_causes_ranked_fifth_and_sixth_are_still_tried(monkeypatch: pytest.MonkeyPatch) -> None:
    """The supports' and the joints' causes ranked fifth and sixth among the first causes (after four significant
    others): the first round of the search tries a second cause on top of them too (not only in a later round with
    their choice held open), and the pair is named."""
    import analysis.diagnosis.physical_verdict as pv

    fv, specs, mm, fmax, fits, found, judge = _searched(SUPPORT_AND_JOINT, CAUSES)
    ranked = _last(found, ("support_stiffness", "joint_stiffness"))
    tried: list[tuple[str, bool]] = []
    on_top_of = pv._on_top_of

    def spy(*args: object, **kw: object) -> object:
        first, opened = args[4], args[7]
        tried.append((first["_fit"].cause, bool(opened)))  # type: ignore[index]
        return on_top_of(*args, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(pv, "_on_top_of", spy)
    _support_and_joint(pv._second_cause(fv, specs, mm, fmax, fits, ranked, judge, CAUSES))
    assert [c["effect"] for c in ranked[:4]] == [cause for cause, _ in tried[:4]]
    assert {("support_stiffness", False), ("joint_stiffness", False)} & set(tried), tried


def test_a_second_cause_ranked_sixth_on_the_screen_is_still_refined(monkeypatch: pytest.MonkeyPatch) -> None:
    """On top of the support left:0 (fitted alone there), the joints' cause ranked last of six on the screen of
    second causes (and its other kind of option not tried at all): it is refined with the first, and the pair is
    named."""
    import analysis.diagnosis.physical_verdict as pv

    fv, specs, mm, fmax, fits, found, judge = _searched(SUPPORT_AND_JOINT, CAUSES)
    first = pv._as_first(fv, specs, mm, fmax, "support_stiffness", ("factor_translational", "factor_rotational"),
                         options=["left:0"])
    screen = pv._on_top_fits

    def joint_last(*args: object, **kw: object) -> tuple:
        out, left, others = screen(*args, **kw)  # type: ignore[arg-type]
        assert len(out) == 6 and not left
        return ([f for f in out if f.cause != "joint_stiffness"] + [f for f in out if f.cause == "joint_stiffness"], left,
                [f for f in others if f.cause != "joint_stiffness"])

    monkeypatch.setattr(pv, "_on_top_fits", joint_last)
    _support_and_joint(pv._on_top_of(fv, specs, mm, fmax, first, judge, CAUSES, opened=False))


def test_a_rival_ranked_fourth_is_still_tried_in_place_of_a_named_cause() -> None:
    """In place of a named single cause (the right column's stiffness, as if named), the rivals of one kind twice:
    the supports' cause ranked fourth among the single causes with a choice is tried too (each rival with the supports'
    cause on top: only the supports' cause as a first makes the pair), and the two supports are named in its place."""
    from analysis.diagnosis.physical_verdict import _rival_pair

    causes = ["member_stiffness", "joint_stiffness", "member_mass", "added_mass", "support_stiffness"]
    fv, specs, mm, fmax, fits, found, judge = _searched(TWO_SUPPORTS, causes)
    ranked = _last(found, ("support_stiffness",))
    named = next(c for c in ranked if c["effect"] == "member_stiffness")
    _both_supports(_rival_pair(fv, specs, mm, fmax, fits, ranked, judge, RIVAL_SECONDS, named))
