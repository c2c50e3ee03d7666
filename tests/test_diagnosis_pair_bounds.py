"""The pair search makes no pair that cannot win, and the bound that says so never drops the pair the full search
names. A pair's score is its nested held-out chi2 (>= 0) plus both choices' freedom, so against a named pair of score
``top`` a first cause whose choice alone costs ``top`` has nothing to search, and a second cause whose choice does
with the first's is not fitted on top of it (it still counts in the pair's freedom); on a fleet's unit the first
cause its scatter takes is searched first, and its named pair bounds the firsts before it. The frame: a loose support
and a stiffer material (the FE frame's own modes, no noise)."""
from __future__ import annotations

import functools

import numpy as np
import pytest
from pair_stage_support import physical_stage
from shared_frames import frame_variants
from test_diagnosis_physical import OUTS, REFS, _noise_free_modes, _sensor_masses

from simulator.config import FrameConfig
from simulator.fem import FrameModel
from simulator.physical import FrameVariants

#: the causes fitted (the named pair is the support's and the material's); three of them: every one is counted
CAUSES = ["support_stiffness", "joint_stiffness", "stiffness_shift"]
LOOSE = {"loose_supports": ["left:0"], "loose_support_factor": [0.15]}
STIFFER = 1.04


@functools.cache
def _frame() -> tuple:
    """The frame with a loose support and its material STIFFER: (its FRFs at the outputs, its modes)."""
    cfg = FrameConfig.from_dict({"damage": LOOSE})
    cfg = cfg.with_overrides({"material": {"youngs_modulus_pa": STIFFER * cfg.material.youngs_modulus_pa}})
    measured = FrameModel.from_config(cfg, _sensor_masses(cfg)).analytic_frf(OUTS, REFS, np.arange(8.0, 500.0, 0.25))
    return measured, _noise_free_modes(FrameVariants(cfg, OUTS, REFS), [])


@functools.cache
def _fits() -> list:
    from analysis.diagnosis.physical import physical_causes
    from analysis.diagnosis.physical_verdict import FMAX_FACTOR

    _, mm = _frame()
    return physical_causes(frame_variants(None, OUTS, REFS), mm, FMAX_FACTOR * float(mm.freq_hz[-1]), CAUSES, processes=1)


def _searched() -> tuple:
    """The single causes fitted and judged as the physical stage does: (simulation, specs, modes, fmax, judge, the
    support fitted alone at left:0 as a first cause)."""
    from analysis.diagnosis.physical_verdict import _as_first

    measured, mm = _frame()
    fv, specs, fmax, judge = physical_stage(measured, mm)
    first = _as_first(fv, specs, mm, fmax, "support_stiffness", ("factor_translational", "factor_rotational"),
                      options=["left:0"])
    return fv, specs, mm, fmax, judge, first


def _fitted_on_top(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The causes fitted from now on (:func:`fit_cause` as the pair search calls it), in turn."""
    import analysis.diagnosis.physical_verdict as pv

    fitted: list[str] = []
    real = pv.fit_cause

    def spy(sim: object, cause: object, *a: object, **k: object) -> object:
        fitted.append(cause.name)  # type: ignore[attr-defined]
        return real(sim, cause, *a, **k)  # type: ignore[arg-type]

    monkeypatch.setattr(pv, "fit_cause", spy)
    return fitted


def _pair(c: dict | None) -> tuple:
    """A judged pair as the search returns it: its causes, parameters, nested held-out chi2, score and freedom."""
    assert c is not None
    return (c["_pair"].causes, c["_pair"].params, c["_pair"].cv_per_mode.tolist(), c["_chi2_cv"], c["_over_first"],
            c["significant"], c["adequate"])


def test_a_first_cause_whose_pairs_cannot_beat_a_named_score_makes_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    """Against a named pair of a score below the support's own choice's freedom (2 ln 3), no pair on top of the support
    can win whatever its held-out chi2: nothing is fitted on top of it and no pair is refined."""
    import analysis.diagnosis.physical_pairs as pp
    import analysis.diagnosis.physical_verdict as pv

    fv, specs, mm, fmax, judge, first = _searched()
    fitted = _fitted_on_top(monkeypatch)
    refined: list[object] = []

    def fit_pair(*a: object, **k: object) -> object:
        refined.append(a)
        return pp.fit_pair(*a, **k)  # type: ignore[arg-type]

    monkeypatch.setattr(pv, "fit_pair", fit_pair)
    assert pv.choice_penalty(specs["support_stiffness"]) > 2.0
    assert pv._on_top_of(fv, specs, mm, fmax, first, judge, CAUSES, opened=False, top=2.0) is None
    assert fitted == [] and refined == []


def test_the_bound_keeps_the_pair_the_full_search_names(monkeypatch: pytest.MonkeyPatch) -> None:
    """On top of the loose support fitted alone: the full search (no named pair known) names the support with the
    stiffer material. Given a named score just above that pair's, the joints' cause (its choice's freedom with the
    support's above the score) is not fitted on top of the support, yet counts in the pair's freedom, and the same
    pair is named with the same parameters, held-out chi2, score and freedom; given that pair's own score, none is
    (only a lower score beats a named pair)."""
    import analysis.diagnosis.physical_verdict as pv

    fv, specs, mm, fmax, judge, first = _searched()
    full = pv._on_top_of(fv, specs, mm, fmax, first, judge, CAUSES, opened=False)
    assert full is not None and pv._named_pair(full)
    assert full["_pair"].causes == ("support_stiffness", "stiffness_shift")
    assert full["_pair"].params[1]["stiffness_factor"] == pytest.approx(STIFFER, rel=1e-3)
    score = float(full["_chi2_cv"])
    assert pv.choice_penalty(specs["support_stiffness"]) * 2 > score + 1e-6
    judge.kept.clear()                  # the second causes fitted on top of the support anew
    fitted = _fitted_on_top(monkeypatch)
    bounded = pv._on_top_of(fv, specs, mm, fmax, first, judge, CAUSES, opened=False, top=score + 1e-6)
    assert _pair(bounded) == _pair(full)
    assert "joint_stiffness" not in fitted and "support_stiffness" not in fitted
    assert pv._on_top_of(fv, specs, mm, fmax, first, judge, CAUSES, opened=False, top=score) is None


def test_a_fleets_scatter_cause_is_searched_first_and_bounds_the_firsts_before_it(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A simulation that names a ``scatter_cause`` (a fleet's unit): among first causes ranked [support, material],
    the material's is searched first; the support's is still searched, with the named pair found on top of the
    material as the score to beat; the same two changes are named as in the causes' own order, at a score no worse."""
    import analysis.diagnosis.physical_verdict as pv

    fv, specs, mm, fmax, judge, first = _searched()
    fits = _fits()
    found = [judge.single(specs[f.cause], f) for f in fits]
    firsts = [c for c in found if c["effect"] == "support_stiffness"] + \
             [c for c in found if c["effect"] == "stiffness_shift"]
    for c in firsts:
        c["significant"] = True
        c["gain_db"] = max(c["gain_db"], 0.1)
    plain = pv._second_cause(fv, specs, mm, fmax, fits, firsts, judge, CAUSES)

    class Fleet:
        """The frame as a fleet's unit sees it: the same answers, and the material's cause its scatter's."""
        scatter_cause = "stiffness_shift"

        def __getattr__(self, name: str) -> object:
            return getattr(fv, name)

    searched: list[tuple[str, float]] = []
    on_top_of = pv._on_top_of

    def spy(*a: object, **k: object) -> object:
        searched.append((a[4]["_fit"].cause, float(k.get("bound", np.inf))))  # type: ignore[index, arg-type]
        return on_top_of(*a, **k)  # type: ignore[arg-type]

    monkeypatch.setattr(pv, "_on_top_of", spy)
    fleet = pv._second_cause(Fleet(), specs, mm, fmax, fits, firsts, judge, CAUSES)  # type: ignore[arg-type]
    assert [c for c, _ in searched[:2]] == ["stiffness_shift", "support_stiffness"]
    assert searched[0][1] == np.inf and np.isfinite(searched[1][1])
    # the same two changes named (in either order), at a score no worse than the old order's
    assert plain is not None and fleet is not None
    for got in (plain, fleet):
        assert pv._named_pair(got)
        changes = dict(got["_pair"].changes)
        assert set(changes) == {"support_stiffness", "stiffness_shift"}
        assert changes["support_stiffness"]["support"] == "left:0"
        assert changes["stiffness_shift"]["stiffness_factor"] == pytest.approx(STIFFER, rel=1e-3)
    assert fleet["_chi2_cv"] <= plain["_chi2_cv"]


def test_a_first_causes_folds_are_made_only_when_a_pair_needs_them() -> None:
    """The support fitted alone at left:0 as a first cause is refined on all modes, not cross-validated. Against a
    named score that leaves the pairs on top of it a target below the chi2 they refine to (no pair cross-validated),
    its held-out chi2 is not made either; the full search (no score) makes it, as its pair is cross-validated, and
    names the same pair as with the first cause cross-validated from the start."""
    import analysis.diagnosis.physical_verdict as pv

    fv, specs, mm, fmax, judge, first = _searched()
    assert "_alone_cv" not in first and first["_alone_chi2"] <= first["_fit"].chi2 + 1e-9
    lazy = dict(first)
    full = pv._on_top_of(fv, specs, mm, fmax, lazy, judge, CAUSES, opened=False)
    assert full is not None and "_alone_cv" in lazy
    eager = dict(first)
    pv._alone_cv(fv, specs, mm, fmax, eager)
    assert _pair(pv._on_top_of(fv, specs, mm, fmax, eager, judge, CAUSES, opened=False)) == _pair(full)
    top = pv.choice_penalty(specs["support_stiffness"]) + 0.5 * full["_pair"].chi2
    assert pv._on_top_of(fv, specs, mm, fmax, first, judge, CAUSES, opened=False, top=top) is None
    assert "_alone_cv" not in first


def test_a_target_is_the_same_whether_its_held_out_chi2_is_made_or_not() -> None:
    """:func:`_win_target` given the first cause's held-out chi2 or a function that makes it: the same target, the
    function asked only where the target depends on it."""
    from analysis.diagnosis.physical_verdict import _Judge, _win_target

    K = 10
    judge = _Judge(measured=None, frf=None, weights=np.ones(1), base=np.full(K, 50.0), far=np.zeros(K, bool),
                   before_db=0.0, noise_db=0.0)
    asked: list[float] = []

    def made(cv: float) -> object:
        def make() -> float:
            asked.append(cv)
            return cv
        return make

    named = {"significant": True, "adequate": True, "_chi2_cv": 12.0}
    unnamed = {"significant": False, "adequate": False, "_chi2_cv": 300.0}
    for alone in (30.0, 80.0, 900.0):
        for cv in (alone, 1.2 * alone, 3.0 * alone):
            for best, top, named_only in ((None, np.inf, True), (named, np.inf, False), (None, 15.0, False),
                                          (unnamed, np.inf, False), (None, np.inf, False)):
                first = {"_alone_chi2": alone}
                args = (3.0, 4.0, 6.0, named_only)
                assert _win_target(best, top, judge, first, made(cv), *args) == \
                    _win_target(best, top, judge, first, cv, *args)         # type: ignore[arg-type]
    # far from the first cause's reach (a named score of 12 less a freedom of 6): never asked
    asked.clear()
    assert _win_target(named, np.inf, judge, {"_alone_chi2": 900.0}, made(900.0), 3.0, 4.0, 6.0) == 6.0  # type: ignore[arg-type]
    assert asked == []


def test_a_choice_costs_its_freedom_at_the_option_it_holds() -> None:
    """What a choice chose (the second cause's test against its first alone): one place among n, 2 ln n; the option
    of every support (every joint) at once, nothing; a choice without such an option (a mass's node), 2 ln n at every
    option; a cause without a choice, nothing. A pair's score counts 2 ln n at every option (like for like)."""
    import analysis.diagnosis.physical_verdict as pv

    _, specs, *_ = _searched()
    support, mass = specs["support_stiffness"], specs["added_mass"]
    assert support.every == "all" and len(support.options) == 3
    assert pv.choice_freedom(support, {"support": "right:0"}) == pytest.approx(2.0 * np.log(3.0))
    assert pv.choice_freedom(support, {"support": "all"}) == 0.0
    assert pv.least_choice_freedom(support) == 0.0
    n = len(mass.options)
    assert n > 20 and mass.every is None
    assert pv.choice_freedom(mass, {"point": mass.options[3]}) == pytest.approx(2.0 * np.log(n))
    assert pv.least_choice_freedom(mass) == pytest.approx(2.0 * np.log(n))
    assert pv.choice_freedom(specs["stiffness_shift"], {}) == pv.least_choice_freedom(specs["stiffness_shift"]) == 0.0
    assert pv.choice_penalty(support) == pytest.approx(2.0 * np.log(3.0))
    assert pv.choice_penalty(mass) == pytest.approx(2.0 * np.log(n))


def test_on_top_of_a_first_cause_every_place_and_one_place_are_both_kept() -> None:
    """On top of the loose support fitted alone, the joints' cause is fitted at every joint at once and at each joint
    apart: the better by chi2 plus its freedom is ranked, the other returned beside the ranking, so neither kind is
    lost to the other's lower chi2; a cause without an option for every place is fitted once."""
    import analysis.diagnosis.physical_verdict as pv

    fv, specs, mm, fmax, judge, first = _searched()
    ranked, left, others = pv._on_top_fits(fv, mm, fmax, first["_fit"], CAUSES, {})
    assert not left
    joints = [f for f in ranked if f.cause == "joint_stiffness"] + [f for f in others if f.cause == "joint_stiffness"]
    assert len(joints) == 2
    kinds = sorted(f.params["joint"] == "all" for f in joints)
    assert kinds == [False, True]
    spec = specs["joint_stiffness"]

    def key(f: object) -> float:
        return f.chi2 + pv._freedom(spec, f.free)  # type: ignore[attr-defined]

    assert key(joints[0]) <= key(joints[1])
    assert [f.cause for f in ranked].count("stiffness_shift") == 1
    assert all(f.cause != "stiffness_shift" for f in others)
