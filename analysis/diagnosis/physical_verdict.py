"""The verdict of the physical causes (:mod:`analysis.diagnosis.physical`) for :func:`diagnose`.

Steps, each one able to decide:

1. Measured modes: the automatic LSFD fit of the measurement (or the modes given).
2. Same structure? Fewer than half of the measured modes pair with the simulation's by frequency
   and MAC: ``unexplained``, with that reason, unless a cause fitted on its own pairing (step 4, alone
   or with a second) is named: a large change may mix the shapes of neighbouring modes (nothing is
   fitted when fewer than 3 modes pair). Measured modes that pair with
   no simulated mode (``unpaired_measured_hz``) or stand for a close pair the fit did not resolve
   (``merged_measured_hz``, :func:`merged_pairs`) are reported and left out of the fit.
3. Discrepancy? Mean chi2 per mode of the nominal simulation (frequency errors in units of their
   uncertainty with the model-form floor, and shape mismatch) at most ``discrepancy_chi2`` and the
   typical FRF error within the margin of the noise: nothing to explain here unless the modes hold a
   summed chi2 of at least ``quiet_chi2`` (a change that moves a few modes, a joint's springs, is
   diluted in the mean and may hide in the FRFs' typical line); then the causes are fitted and one
   that removes ``quiet_chi2`` of held-out chi2 and is named by step 4 (alone) decides; else the
   FRF-level catalogue is tried (not decided here).
4. Causes: every physical cause fitted, nested variants and choices selected by leave-one-mode-out
   chi2. Named: the cause with the largest held-out gain among those that are significant
   (gain >= ``physical_min_gain_db``, no parameter at the edge of its range) and adequate (the held-out modes
   agree, mean chi2 per mode <= ``discrepancy_chi2``, and the extended simulation's FRFs, through the
   measurement's processing, leave the typical error within ``none_margin_db`` of the noise or
   remove ``adequate_fraction`` of the excess error in power). A second cause is searched on top of the
   first (:mod:`analysis.diagnosis.physical_pairs`); with no single cause named, every local cause (a
   support, a joint, an element) at each of its places is a first cause too (:func:`_local_pairs`), and
   the best pair by the same rule is named. None named: when the modes differ,
   ``unexplained`` with the best partial causes (no FRF-level effect moves natural frequencies);
   when only the FRFs differ, not decided here: the FRF-level catalogue is tried, and the physical
   causes are listed in ``Diagnosis.physical["causes"]``.

Every threshold is a field of the one :class:`analysis.diagnosis.rule.DecisionRule`; the rules applied are
appended to :attr:`PhysicalOutcome.trace` in order.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..frf import FRFSet
from ..progress import progress
from .compare import typical_error_db
from .effect_types import named as named_form
from .effect_types import stage_entry
from .effects import predict
from .next_measurement import pair_rivals, propose, rivals
from .param_range import pair_ranges, supported_ranges
from .physical import (
    MODE_CHI2_MAX,
    CauseSpec,
    MeasuredModes,
    PhysicalFit,
    PhysicalSimulation,
    counted_modes,
    fit_cause,
    gain_db,
    lost_modes,
    pair,
    paired_well,
    physical_causes,
    residuals,
    same_structure,
    shown_params,
    variants,
)
from .physical_pairs import (
    PARAMETER_CHI2,
    OnTop,
    PairFit,
    SplitBound,
    as_places,
    besides,
    choice_freedom,
    choice_penalty,
    fit_pair,
    held_open,
    held_spec,
    least_choice_freedom,
    rechoose,
    refit_on_top,
    split_choice,
    split_places,
    splits,
    splits_in_two,
    widened,
    with_options,
)
from .rule import DEFAULT_RULE, DecisionRule, db, paired_z, step
from .verdict_part import VerdictPart

__all__ = ["PhysicalOutcome", "physical_verdict", "measure_modes", "compared_band_hz"]

#: Candidate modes are computed up to this multiple of the highest measured mode used (modes that may pair).
FMAX_FACTOR = 1.5


@dataclass
class PhysicalOutcome(VerdictPart):
    """decided: the physical stage gives the verdict (else the FRF catalogue is tried); the verdict's
    fields (:class:`~analysis.diagnosis.verdict_part.VerdictPart`) as the ``Diagnosis`` takes them;
    doc (JSON), on_top: a named cause an FRF-level effect is tried on top of, trace: the rules applied."""

    decided: bool
    doc: dict = field(default_factory=dict)
    on_top: dict | None = None
    trace: list = field(default_factory=list)


#: The trace's words for the gates of steps 2 and 3.
_SAME = {True: "same structure", False: "not the same structure: unexplained unless a cause is named"}
_DIFFER = {(True, True): "modes differ", (True, False): "modes differ", (False, True): "FRFs differ",
           (False, False): "neither differs"}


def measure_modes(measured: FRFSet, band: tuple[float, float] | None = None) -> MeasuredModes:
    """The measured modes from the automatic fit (:func:`analysis.pipeline.fit_auto`) in ``band`` (Hz;
    None: the band from the data), so that its warnings speak of the band the user gave."""
    from ..pipeline import fit_auto

    res = fit_auto(measured, band=band)
    lf = res.lsfd
    return MeasuredModes.from_model(lf.model, lf.freq_hz_std)


#: Simulated modes closer than this (relative) are a close pair that a fit may see as one mode.
CLOSE_PAIR = 0.02


def merged_pairs(mm: MeasuredModes, f: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Mask of measured modes that stand for a close pair of simulated modes (within ``CLOSE_PAIR``)
    of which the fit resolved only one: the other has no measured partner. Such a mode's frequency
    and shape are a mixture of the two and are not compared."""
    idx, _ = pair(mm, f, P)
    used = set(int(j) for j in idx if j >= 0)
    out = np.zeros(mm.freq_hz.size, bool)
    for k, j in enumerate(idx):
        if j < 0:
            continue
        near = np.flatnonzero(np.abs(f / f[j] - 1) < CLOSE_PAIR)
        out[k] = any(int(i) not in used for i in near if i != j)
    return out


def _power(db: float) -> float:
    return float(10 ** (db / 10))


def physical_verdict(measured: FRFSet, sim: PhysicalSimulation, prior: Sequence, weights: np.ndarray,
                     noise_db: float, measured_modes: MeasuredModes | None = None,
                     causes: Sequence[str] | None = None, rule: DecisionRule = DEFAULT_RULE) -> PhysicalOutcome:
    """Steps 1-4 of the module docstring with the thresholds of ``rule``; ``causes`` limits the physical
    causes tried (None: all). The rules applied are in the outcome's ``trace``, in order."""
    trace: list = []
    out = _physical_verdict(measured, sim, prior, weights, noise_db, measured_modes, causes, rule, trace)
    out.trace = trace
    return out


def _physical_verdict(measured: FRFSet, sim: PhysicalSimulation, prior: Sequence, weights: np.ndarray,
                      noise_db: float, measured_modes: MeasuredModes | None, causes: Sequence[str] | None,
                      rule: DecisionRule, trace: list) -> PhysicalOutcome:
    """:func:`physical_verdict`, the rules applied appended to ``trace``."""
    from ..errors import ImpactlabError

    try:
        mm = measured_modes if measured_modes is not None else measure_modes(measured)
    except (ImpactlabError, ValueError, np.linalg.LinAlgError) as exc:
        return PhysicalOutcome(decided=False, doc={"skipped": f"no measured modes: {exc}"})
    if mm.freq_hz.size < 3:
        return PhysicalOutcome(decided=False, doc={"skipped": f"{mm.freq_hz.size} well-determined measured modes; "
                                                              "at least 3 are needed to fit a physical cause"})
    fmax = FMAX_FACTOR * float(mm.freq_hz[-1])
    f0, P0 = sim.modes(None, {}, fmax)
    idx, macs = pair(mm, f0, P0)
    doc: dict = {"measured_modes_hz": mm.freq_hz.tolist(), "measured_std_hz": mm.freq_std_hz.tolist(),
                 "simulated_modes_hz": [float(f0[i]) if i >= 0 else None for i in idx], "mac": macs.tolist()}

    def frf(changes: list) -> FRFSet:
        model = (sim.model(None, {}) if not changes else sim.model(*changes[0]) if len(changes) == 1
                 else sim.model_of(changes))
        return predict(model, measured.freq_hz, measured.quantity, prior,
                       outputs=measured.outputs, references=measured.references)

    nominal = frf([])
    before_db = typical_error_db(measured, nominal.H, weights)
    good = paired_well(mm, f0, P0)
    same, why = same_structure(mm, f0, P0, good)
    trace.append(step("same_structure", None, {"paired_modes": int(good.sum()), "measured_modes": int(good.size)},
                      _SAME[same]))
    other: PhysicalOutcome | None = None
    if not same:
        other = PhysicalOutcome(decided=True, verdict="unexplained", extended=nominal, error_before_db=before_db,
                                error_after_db=before_db, reason=why, doc={**doc, "same_structure": False})
        # a large change (a heavy block mixing the shapes of neighbouring modes) may leave fewer than half of
        # the modes paired with the unchanged frame: the causes are fitted, each on its own pairing, and the
        # structure is called another only when none of them (alone or with one other) is named
        if int(good.sum()) < 3:
            return other
    # every candidate is paired with the measured modes on its own: a measured mode that no mode of the
    # unchanged frame pairs with stays in (a large change may have moved a mode past its neighbours or
    # into the band) and counts against every candidate that does not produce it
    doc["unpaired_measured_hz"] = mm.freq_hz[~good].tolist()
    merged = merged_pairs(mm, f0, P0)
    doc["merged_measured_hz"] = mm.freq_hz[merged & good].tolist()
    keep = ~(merged & good)
    mm, far = mm.subset(keep), ~good[keep]
    if int((~far).sum()) < 3:
        few = "fewer than 3 measured modes pair with the simulation's"
        return other or PhysicalOutcome(decided=False, doc={**doc, "skipped": few})
    base = np.sum(residuals(mm, f0, P0) ** 2, axis=1)
    doc["chi2_per_mode"] = float(base[~far].mean())
    # a mode of its own is not evidence of a change while the paired modes agree (a spurious peak, a
    # local mode of something not modelled): the paired modes decide whether the modes differ
    modes_differ = bool(base[~far].mean() > rule.discrepancy_chi2)
    frfs_differ = not rule.explained(before_db, noise_db)
    doc["discrepancy"] = {"modes": modes_differ, "frfs": frfs_differ}
    trace.append(step("discrepancy", None, {"chi2_per_mode": float(base[~far].mean()),
                                            "discrepancy_chi2": rule.discrepancy_chi2, "error_db": before_db,
                                            "noise_db": noise_db, "none_margin_db": rule.none_margin_db},
                      _DIFFER[modes_differ, frfs_differ]))
    # neither gate: a change that moves a few modes by a few standard deviations each (a joint, a local
    # stiffness) is diluted in the mean over the modes and may hide in the FRFs' typical line; the causes
    # are still fitted when the modes hold enough mismatch for one to remove rule.quiet_chi2 of it
    quiet = not (modes_differ or frfs_differ)
    if quiet and (other is not None or float(base.sum()) < rule.quiet_chi2):
        trace.append(step("quiet", None, {"chi2": float(base.sum()), "quiet_chi2": rule.quiet_chi2},
                          "nothing to explain in the modes: causes not fitted"))
        return other or PhysicalOutcome(decided=False, doc=doc)
    specs = {c.name: c for c in sim.causes()}
    fits = physical_causes(sim, mm, fmax, causes, rule=rule)
    if not fits:
        return other or PhysicalOutcome(decided=False, doc=doc)
    judge = _Judge(measured, frf, weights, base, far, before_db, noise_db, rule)
    found = [judge.single(specs[fit.cause], fit) for fit in fits]
    found.sort(key=lambda c: c["gain_db"], reverse=True)
    _trace_singles(trace, found, rule)
    named = [c for c in found if c["significant"] and c["adequate"]]
    if quiet:
        doc["quiet"] = [{k: c[k] for k in ("effect", "gain_db", "removed_chi2", "significant", "adequate")}
                        for c in found[:3]]
        named = _quiet_named(named, rule, trace)
        if not named:
            return PhysicalOutcome(decided=False, doc=doc)
    out = PhysicalOutcome(decided=True, error_before_db=before_db, doc=doc)
    pairs_ok = hasattr(sim, "modes_of") and (causes is None or len(causes) > 1) and not quiet
    firsts: list | None = None          # None: the pair search picks its first causes
    two: dict | None = None
    if named:
        best = named[0]
        out.verdict, out.extended, out.error_after_db = best["effect"], best["_extended"], best["error_after_db"]
        # the values of its parameters the modes do not tell apart (a block's mass and its rotary inertia)
        best["parameters"].update(supported_ranges(sim, specs[best["effect"]], best["_fit"], mm, fmax, rule.range_chi2))
        out.combined = [stage_entry(best)]
        out.named = [named_form(best)]
        trace.append(step("largest_gain", best["effect"], {"gain_db": best["gain_db"], "named": len(named)},
                          f"verdict {best['effect']}"))
        # adequate, yet the held-out modes may keep a small real mismatch (joint springs beside a block): a
        # second physical cause is named with it only when the pair predicts the held-out modes clearly
        # better (forward selection, nested: :func:`_on_top_enough`); not tried when it cannot
        firsts = [best] if pairs_ok and _leaves_evidence(sim, specs, mm, fmax, best, causes, rule) else []
    if pairs_ok and firsts != []:
        two = _pair_search(sim, specs, mm, fmax, fits, found, judge, causes, firsts, named[0] if named else None)
        if two is not None:
            doc["pair"] = {k: two[k] for k in ("effect", "gain_db", "gain_over_first_db", "removed_over_first_chi2",
                                              "significant", "adequate", "held_out_chi2_per_mode", "one_member")}
            _trace_pair(trace, two, rule)
        if two is not None and two["significant"] and two["adequate"]:
            out.verdict, out.extended, out.error_after_db = "combined", two["_extended"], two["error_after_db"]
            _with_ranges(sim, specs, two, mm, fmax, rule)
            out.combined = [stage_entry(c) for c in two["_stages"]]
            out.named = [named_form(c) for c in two["_stages"]]
    if named and out.verdict != "combined" and named[0]["error_after_db"] - noise_db > rule.on_top_margin_db:
        out.on_top = named[0]          # adequate, yet the FRFs stay above the noise: a second, FRF-level cause?
        trace.append(step("on_top", named[0]["effect"], {"error_after_db": named[0]["error_after_db"],
                                                         "noise_db": noise_db, "on_top_margin_db": rule.on_top_margin_db},
                          "an FRF-level effect is tried on top"))
    if not out.named:
        # a cause that explains the modes but not the FRFs: an FRF-level cause (damping, a sensor) may
        # complete it; the caller tries the FRF catalogue on top of it
        modal = [c for c in found if c["significant"] and c["modes_adequate"]]
        if modal:
            out.on_top = modal[0]
        elif not modes_differ:
            out.decided = False
        out.verdict, out.extended, out.error_after_db = "unexplained", nominal, before_db
        partial = ", ".join(f"{c['effect']} ({c['gain_db']:+.1f} dB held out, {_removed_text(c['_removed'])})"
                            for c in found[:3])
        differ = (f"the measured modes differ from the simulation's (mean chi2 {base.mean():.1f} per mode)" if modes_differ
                  else f"the FRFs differ from the simulation's by {before_db - noise_db:.1f} dB above the noise")
        out.reason = (f"{differ} but no physical cause, alone or with one other, is both significant and adequate; "
                      f"best partial causes: {partial}{_beyond_text(doc.get('pair'), rule)}")
        trace.append(step("adequacy", None, {"significant": sum(bool(c["significant"]) for c in found),
                                             "modes_adequate": len(modal), "modes_differ": modes_differ},
                          "unexplained" if out.decided else "not decided here: the FRF-level catalogue is tried"))
    close = rivals(found) if out.verdict != "combined" else _pair_rivals(two)
    if close is not None:
        a, b, why = close
        out.next_measurement = propose(sim, measured, prior, noise_db, a, b, why, modes=(mm, fmax))
    if other is not None and not out.named:
        return other
    out.causes = [{k: v for k, v in c.items() if not k.startswith("_")} for c in found]
    return out


def _with_ranges(sim: PhysicalSimulation, specs: dict, two: dict, mm: MeasuredModes, fmax: float,
                 rule: DecisionRule) -> None:
    """The named pair ``two``'s stages with the values of their parameters the modes do not tell apart (a block's
    mass beside a loose support), both causes refitted at each value (:func:`pair_ranges`)."""
    fit: PairFit = two["_pair"]
    for stage, ranges in zip(two["_stages"], pair_ranges(sim, [specs[n] for n in fit.causes], fit, mm, fmax,
                                                         rule.range_chi2)):
        stage["parameters"].update(ranges)


def _leaves_evidence(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, best: dict,
                     names: Sequence[str] | None, rule: DecisionRule = DEFAULT_RULE) -> bool:
    """Could a second physical cause be named on top of the named single cause ``best``? Only when ``best``
    alone, cross-validated as the pairs are (:func:`_alone_cv`), leaves at least ``rule.quiet_chi2`` plus the
    least freedom of a pair, 2 ln(number of second causes refined): no pair can remove more than that
    (:func:`_on_top_enough`), so the search is skipped (the same noise scale as a first cause below both gates)."""
    others = [c for c in sim.causes() if c.name != best["effect"] and (names is None or c.name in names)]
    n = min(N_SECOND, len(others))
    return n > 0 and float(np.sum(_alone_cv(sim, specs, mm, fmax, best))) >= rule.quiet_chi2 + 2.0 * float(np.log(n))


def _alone_cv(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, first: dict) -> np.ndarray:
    """Held-out chi2 per mode of the single cause ``first`` cross-validated as a pair is (:func:`fit_pair`:
    its choice kept in every fold, its parameters refitted), kept in ``first["_alone_cv"]``: a pair is not
    credited with what searching the choice again in a fold costs the single cause."""
    if "_alone_cv" not in first:
        fa: PhysicalFit = first["_fit"]
        alone = fit_pair(sim, [specs[fa.cause]], [fa], mm, fmax)
        first["_alone_cv"], first["_alone_chi2"] = alone.cv_per_mode, alone.chi2
    return first["_alone_cv"]


def _alone_refined(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, first: dict) -> float:
    """The chi2 on all modes of the single cause ``first`` refined as :func:`_alone_cv` refines it, kept in
    ``first["_alone_chi2"]``: its folds are left for :func:`_alone_cv` to make when they are asked (from the same
    refinement, :func:`fit_pair`)."""
    if "_alone_chi2" not in first:
        fa: PhysicalFit = first["_fit"]
        first["_alone_chi2"] = fit_pair(sim, [specs[fa.cause]], [fa], mm, fmax, folds=False).chi2
    return float(first["_alone_chi2"])


def _on_top_enough(cv_first: np.ndarray, cv_pair: np.ndarray, freedom: float,
                   rule: DecisionRule = DEFAULT_RULE) -> tuple[float, float, bool]:
    """The pair's nested held-out chi2 per mode ``cv_pair`` against the first cause's alone ``cv_first``,
    cross-validated alike (leave one mode out, the choices kept and every continuous parameter refitted
    in each fold): (gain in dB, chi2 removed net of ``freedom``, enough). ``freedom`` (chi2 units) is what
    the pair chose on all modes, which no fold re-does: the second cause among those refined, 2 ln(number of them),
    and its own choice at the option it holds (:func:`choice_freedom`: a place among n, 2 ln n; every place at
    once chose none). Enough: at least
    ``rule.physical_min_gain_db`` better (a cause that only bends to fit some modes does not predict the
    left-out ones) and, net of that
    freedom, at least ``rule.quiet_chi2`` removed (one mode predicted one standard deviation better, the
    model-form floor included: a small change on top of a large one, joint springs beside a block, leaves
    little, but that little is real)."""
    over = gain_db(cv_first, cv_pair)
    removed = float(np.sum(cv_first) - np.sum(cv_pair) - freedom)
    return over, removed, bool(over >= rule.physical_min_gain_db and removed >= rule.quiet_chi2)


def compared_band_hz(doc: dict, freq_hz: np.ndarray) -> float:
    """The upper end (Hz) of the band in which a physical cause's modes were held against the measured
    ones: halfway (geometric) between the highest measured mode compared (``doc["measured_modes_hz"]``,
    the lowest ``MAX_MODES`` well-determined ones) and the next mode ``freq_hz`` of the extended
    simulation above it; inf when it has none. Above it the cause's modes are the catalogue's model of
    the change, unchecked (a point mass for a block on its joint springs), and an FRF-level effect
    fitted there on top (a damping change) would absorb their misplacement."""
    top = max(doc.get("measured_modes_hz") or [np.inf])
    above = np.sort(freq_hz[freq_hz > 1.01 * top])
    return float(np.sqrt(top * above[0])) if np.isfinite(top) and above.size else float("inf")


def _held_out_per_mode(cv: np.ndarray, judge: _Judge) -> float:
    """Held-out chi2 per counted mode (:meth:`_Judge._counted`)."""
    n = judge._counted(cv)
    return float(np.sum(cv[n]) / max(int(n.sum()), 1))


def _one_member(specs: Sequence[CauseSpec], params: Sequence[dict]) -> str | None:
    """The member both causes of a pair change (each chooses a member, the same one), else None."""
    chosen = [p.get(s.choice) if s.choice == "component" else None for s, p in zip(specs, params)]
    return chosen[0] if chosen[0] is not None and all(c == chosen[0] for c in chosen) else None


def _beyond_text(pair: dict | None, rule: DecisionRule = DEFAULT_RULE) -> str:
    """The reason's words for a significant pair of changes of one member that leaves the held-out modes
    above their uncertainty (:func:`_second_cause`)."""
    if (not pair or not pair["significant"] or pair["one_member"] is None
            or pair["held_out_chi2_per_mode"] <= rule.leaves_chi2):
        return ""
    return (f"; the best pair, {pair['effect'].replace('+', ' with ')} of {pair['one_member']}, acts as one change "
            f"of that member's geometry (its length, its section) and still leaves the held-out modes "
            f"{pair['held_out_chi2_per_mode']:.1f} chi2 per mode (above {rule.leaves_chi2:g}): a change the catalogue "
            f"does not hold, left unexplained rather than named as two")


def _pair_rivals(two: dict | None) -> tuple[list, list, str] | None:
    """The named pair and its rival when its choice is not separated by the data (:func:`pair_rivals`)."""
    fit = None if two is None else two.get("_pair")
    return None if fit is None else pair_rivals(fit.causes, fit.params, fit.chi2, fit.ranked)


def _removed_text(removed: float) -> str:
    """The share of the excess FRF error a cause removes, in words (never a negative percentage)."""
    if removed < 0:
        return "the FRF error grows"
    return f"{100 * min(removed, 1.0):.0f} % of the FRF error above the noise removed"


def _quiet_named(named: list, rule: DecisionRule, trace: list) -> list:
    """Of the causes ``named`` while neither the modes nor the FRFs differ, those that remove at least
    ``rule.quiet_chi2`` of the modes' chi2 (each decision appended to ``trace``)."""
    for c in named:
        trace.append(step("quiet", c["effect"], {"removed_chi2": c["removed_chi2"], "quiet_chi2": rule.quiet_chi2},
                          "kept" if c["removed_chi2"] >= rule.quiet_chi2 else "not named: removes too little"))
    return [c for c in named if c["removed_chi2"] >= rule.quiet_chi2]


def _trace_pair(trace: list, two: dict, rule: DecisionRule) -> None:
    """The ``second_cause`` rule's step for the best pair ``two``."""
    trace.append(step("second_cause", two["effect"],
                      {"gain_db": two["gain_db"], "gain_over_first_db": two["gain_over_first_db"],
                       "removed_over_first_chi2": two["removed_over_first_chi2"],
                       "physical_min_gain_db": rule.physical_min_gain_db, "quiet_chi2": rule.quiet_chi2,
                       **two.get("_over_first", {}), "significant": two["significant"], "adequate": two["adequate"]},
                      "both named: verdict combined" if _named_pair(two) else "not named"))


def _trace_singles(trace: list, found: list, rule: DecisionRule) -> None:
    """The physical stage's rules for each judged cause of ``found``: its significance, then its adequacy."""
    for c in found:
        _trace_single(trace, c, rule)


def _trace_single(trace: list, c: dict, rule: DecisionRule) -> None:
    """The physical stage's rules for one judged cause ``c``: its significance, then its adequacy."""
    trace.append(step("physical_significance", c["effect"],
                      {"gain_db": c["gain_db"], "physical_min_gain_db": rule.physical_min_gain_db,
                       "at_edge": c["_at_edge"]}, "significant" if c["significant"] else "not significant"))
    if c["significant"]:
        trace.append(step("adequacy", c["effect"],
                          {"modes_adequate": c["modes_adequate"], "discrepancy_chi2": rule.discrepancy_chi2,
                           "error_after_db": c["error_after_db"], "none_margin_db": rule.none_margin_db,
                           "removed": c["_removed"], "adequate_fraction": rule.adequate_fraction},
                          "adequate" if c["adequate"] else "not adequate"))


def _shown(params: dict) -> str:
    return ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in params.items())


@dataclass
class _Judge:
    """The rule of the physical stage for one candidate (one cause or two): held-out gain, significance
    and adequacy (module docstring); modes that the unchanged frame does not pair (``far``) and the
    candidate does not predict either are not counted (at most one)."""

    measured: FRFSet
    frf: Any
    weights: np.ndarray
    base: np.ndarray
    far: np.ndarray
    before_db: float
    noise_db: float
    rule: DecisionRule = DEFAULT_RULE
    #: answers of the pair search already solved in this diagnosis, asked again (:func:`_seconds`)
    kept: dict = field(default_factory=dict)

    def _counted(self, cv: np.ndarray) -> np.ndarray:
        return counted_modes(self.far & lost_modes(cv))

    def judge(self, changes: list, cv: np.ndarray, at_edge: tuple) -> dict:
        ext = self.frf(changes)
        after_db = typical_error_db(self.measured, ext.H, self.weights)
        excess = _power(self.before_db) - _power(self.noise_db)
        removed = (_power(self.before_db) - _power(after_db)) / excess if excess > 0 else 0.0
        n = self._counted(cv)
        g = gain_db(self.base[n], cv[n])
        removed_chi2 = float(np.sum(self.base[n]) - np.sum(cv[n]))
        rule = self.rule
        modes_ok = bool(np.sum(cv[n]) / n.sum() <= rule.discrepancy_chi2)
        return {"gain_db": g, "error_before_db": self.before_db, "error_after_db": after_db,
                "z": paired_z(self.base[n], cv[n]), "significant": bool(g >= rule.physical_min_gain_db and not at_edge),
                "modes_adequate": modes_ok, "removed_chi2": removed_chi2,
                "adequate": bool(modes_ok and (rule.explained(after_db, self.noise_db)
                                               or removed >= rule.adequate_fraction)),
                "_extended": ext, "_removed": removed, "_at_edge": list(at_edge)}

    def most_named_chi2(self) -> float:
        """The most held-out chi2 (summed over all modes) with which a candidate can be named: significant (its
        gain over the unchanged frame's chi2 at least ``rule.physical_min_gain_db``) and adequate (at most
        ``rule.discrepancy_chi2`` per counted mode); with a mode the unchanged frame does not pair, the one mode
        :meth:`_counted` may leave out (at most :data:`MODE_CHI2_MAX`) on top."""
        K = self.base.size
        most = min(float(np.sum(self.base)) * self.rule.physical_min_gain_factor, self.rule.discrepancy_chi2 * K)
        return most + (MODE_CHI2_MAX if bool(np.any(self.far)) else 0.0)

    def evidence(self, name: str, shown: str, cv: np.ndarray, c: dict, at_edge: tuple) -> str:
        edge = f"; at the edge of its range: {', '.join(at_edge)}" if at_edge else ""
        return (f"{name} ({shown}): mode mismatch (sum over the modes of the squared frequency and shape "
                f"residuals, in dB) {db(self.base.sum()):.1f} -> {db(np.sum(cv)):.1f} dB when each mode is "
                f"predicted from the others; FRF error {self.before_db:.1f} -> {c['error_after_db']:.1f} dB "
                f"(noise {self.noise_db:.1f} dB: {_removed_text(c['_removed'])}){edge}")

    def single(self, spec: CauseSpec, fit: PhysicalFit) -> dict:
        params = shown_params(spec, fit.params)
        c = self.judge([(fit.cause, fit.params)], fit.cv_per_mode, fit.at_edge)
        c.update({"effect": fit.cause, "kind": "physical", "parameters": params, "description": spec.description,
                  "advice": spec.advice, "_fit": fit})
        c["evidence"] = self.evidence(fit.cause, _shown(params), fit.cv_per_mode, c, fit.at_edge)
        return c


#: Second causes the freedom of a pair counts (the best by penalised chi2 on top of the first, :func:`_on_top_of`):
#: every other second cause is refined with the first too, and cross-validated only while its refined chi2 could win.
N_SECOND = 3


def _freedom(spec: CauseSpec, free: Sequence[str]) -> float:
    """The freedom of a cause fitted with the parameters ``free`` as pairs are ranked and scored, in chi2 units: 2 per
    parameter plus its choice's (:func:`choice_penalty`)."""
    return PARAMETER_CHI2 * len(free) + choice_penalty(spec)


def _seconds(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, first: PhysicalFit,
             names: Sequence[str] | None, n: int | None = N_SECOND, kept: dict | None = None) -> list[PhysicalFit]:
    """Every other cause (each nested variant) fitted on top of ``first`` on all modes, ranked by chi2
    plus a penalty for its freedom (2 per parameter, 2 ln(number of options) for a choice); the best
    variant of each cause, the ``n`` best causes (None: all), and the simulation's ``scatter_cause`` when it
    names one (a fleet's unit: the global cause its manufacturing scatter takes is always tried, for the
    first cause fitted alone absorbs part of the scatter and leaves little for it on top). ``kept``: the fits on top
    of each first cause made so far in this diagnosis (the held-open round asks them again: the same answers)."""
    return _leading(sim, _on_top_fits(sim, mm, fmax, first, names, {} if kept is None else kept)[0], n)


def _scatter_cause(sim: PhysicalSimulation) -> str | None:
    """The global cause a fleet's manufacturing scatter takes, when ``sim`` is a fleet's simulation that names one
    (its ``scatter_cause``); None for any other simulation."""
    return getattr(sim, "scatter_cause", None)


def _leading(sim: PhysicalSimulation, ranked: list[PhysicalFit], n: int | None) -> list[PhysicalFit]:
    """The ``n`` best of the second causes ``ranked`` (None: all) and the simulation's ``scatter_cause`` among the
    rest (:func:`_seconds`)."""
    scatter = _scatter_cause(sim)
    return ranked[:n] + [f for f in ranked[n:] if f.cause == scatter] if n is not None else ranked


def _on_top_specs(causes: Iterable[CauseSpec], first: PhysicalFit, names: Sequence[str] | None) -> list[CauseSpec]:
    """The second causes on top of ``first`` (:func:`besides`: each of ``causes`` at the options ``first`` leaves),
    among ``names`` (None: all), in the order of ``causes``."""
    on = (besides(c, [(first.cause, first.params)]) for c in causes)
    return [spec for spec in on if spec is not None and (names is None or spec.name in names)]


def _kinds(spec: CauseSpec) -> list[tuple[str, ...] | None]:
    """The options of ``spec`` fitted apart on top of a first cause (:func:`_on_top_fits`): every place at once
    (:attr:`CauseSpec.every`) and the places, for what a pair chose differs between them (:func:`choice_freedom`), so
    the least chi2 of all options alone would drop the other kind (the joints all softened, next to a block that took
    up part of them, fit a little worse than one joint but choose no place); None (all options at once) for any
    other cause."""
    if spec.choice is None or spec.every is None or spec.every not in spec.options or not spec.places:
        return [None]
    return [(spec.every,), spec.places]


def _on_top_fits(sim: PhysicalSimulation, mm: MeasuredModes, fmax: float, first: PhysicalFit,
                 names: Sequence[str] | None, kept: dict, hopeless: Callable[[CauseSpec], bool] | None = None,
                 n: int = N_SECOND
                 ) -> tuple[list[PhysicalFit], list[str], list[PhysicalFit]]:
    """Every other cause (among ``names``) fitted on top of ``first`` on all modes, each nested variant; the best
    variant of each cause by chi2 plus its freedom, best first (:func:`_seconds`); a cause with an option for every
    place fitted at that option and at its places apart (:func:`_kinds`), its best kind ranked and the other's best
    returned apart. Each cause's fits are kept in
    ``kept`` under ``first``'s change and asked from there again. ``hopeless(spec)``: a cause whose pairs with
    ``first`` cannot win (:func:`_hopeless`) is not fitted when its place in the ranking cannot matter either: every
    cause is among the ``n`` best (at most ``n`` of them), or ``n`` causes fitted rank strictly below the least its
    ranking key can be (its smallest variant's freedom, a chi2 being >= 0); such causes are taken after the others,
    those of fewer options (no screen) first. Returns the ranked fits, the names of
    the causes not fitted (those that would have been among the ``n`` best: all of them when every cause is) and the
    other kinds' fits."""
    changed = [(first.cause, first.params)]
    top: OnTop | None = None
    allsel = np.ones(mm.freq_hz.size, bool)
    on = _on_top_specs(sim.causes(), first, names)                          # OnTop.causes
    ranked: list[tuple[int, float, PhysicalFit]] = []
    others: list[PhysicalFit] = []
    # the causes that cannot win last, those of fewer options first: the ranks of those fitted may spare the others
    later = [] if hopeless is None else sorted((i for i, spec in enumerate(on) if hopeless(spec)),
                                               key=lambda i: len(on[i].options))
    left: list[str] = []
    for i in [*(i for i in range(len(on)) if i not in later), *later]:
        spec = on[i]
        key = ("on top", first.cause, repr(sorted(first.params.items())), spec.name)
        if i in later and key not in kept:
            least = min(_freedom(spec, free) for free in variants(spec))
            if len(on) <= n or sum(r[1] < least for r in ranked) >= n:
                left.append(spec.name)
                continue
        if key not in kept:
            top = top or OnTop(sim, changed)
            best = []
            for kind in _kinds(spec):
                fits = []
                for free in variants(spec):
                    p, chi2, _ = fit_cause(top, spec, free, mm, allsel, fmax, options=kind, best_only=True)
                    fits.append((chi2 + _freedom(spec, free),
                                 PhysicalFit(cause=spec.name, params=p, free=free, chi2=chi2)))
                best.append(min(fits, key=lambda t: t[0]))  # the best variant of the kind (the first of the least)
            best.sort(key=lambda t: t[0])                     # the best kind first (ties: every place first)
            kept[key] = best
        ranked.append((i, *kept[key][0]))
        others.extend(f for _, f in kept[key][1:])
    ranked.sort(key=lambda t: (t[1], t[0]))              # as fitted in the causes' order: ties in that order
    return ([f for _, _, f in ranked], (left if len(on) <= n else [c for c in left if c == _scatter_cause(sim)]),
            others)


def _opened(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, first: PhysicalFit,
            names: Sequence[str] | None, kept: dict | None = None
            ) -> list[tuple[SplitBound, PhysicalFit, PhysicalFit]]:
    """Second causes with the first cause's choice held open (:func:`with_options`): every other cause
    (its best variant on top of ``first``) refined together with ``first`` at each of the options its own
    fit ranked; ranked by the pair's chi2 plus the second cause's freedom, each as (its chi2 on all modes as its
    bound, :class:`SplitBound`; first at its option, second): every one is kept, and its exact score is taken
    while that chi2 could still win (:func:`_on_top_of`; the ``N_SECOND`` best are the ones the freedom counts)."""
    ranked = []
    for fb in _seconds(sim, specs, mm, fmax, first, names, n=None, kept=kept):
        fa2, fb2, chi2 = with_options(sim, [specs[first.cause], specs[fb.cause]], first, fb, mm, fmax)
        ranked.append((chi2 + _freedom(specs[fb.cause], fb.free), chi2, fa2, fb2))
    ranked.sort(key=lambda t: t[0])
    return [(SplitBound(None, chi2), a, b) for _, chi2, a, b in ranked]


def _held_seconds(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, first: PhysicalFit,
                  names: Sequence[str] | None) -> list[tuple[SplitBound, PhysicalFit, PhysicalFit]]:
    """Second causes of many options (an element's stiffness) refined with ``first`` at every option
    (:func:`held_open`), ranked by the pair's chi2 plus the second cause's freedom, each as (its chi2 on all modes
    as its bound, :class:`SplitBound`; first refined, second): the pair's exact score is taken only while that
    chi2 could still win (:func:`_on_top_of`)."""
    ranked = [(chi2 + _freedom(spec, b.free), chi2, a, b) for spec in specs.values()
              if names is None or spec.name in names
              for chi2, a, b in held_open(sim, [specs[first.cause], spec], first, mm, fmax)]
    ranked.sort(key=lambda t: t[0])
    return [(SplitBound(None, chi2), a, b) for _, chi2, a, b in ranked]


@dataclass(frozen=True)
class _Later:
    """Pairs of a search on top of a first cause made only when the search reaches them (:func:`_expanded`):
    ``make()`` gives them, each ``(bound, first, second)``, the second cause among ``causes``."""

    causes: tuple[str, ...]
    make: Callable[[], list]


def _expanded(items: Sequence, skip: Callable[[_Later], bool]) -> Iterator:
    """The pairs of ``items`` in turn, each :class:`_Later` group replaced by the pairs it makes when reached,
    unless ``skip(group)`` says none of them could win then (the search's state at that point)."""
    for item in items:
        if isinstance(item, _Later):
            if not skip(item):
                yield from item.make()
        else:
            yield item


def _hopeless(best: dict | None, top: float, first: CauseSpec, second: CauseSpec) -> bool:
    """Whether no pair of the causes ``first`` and ``second`` can win against the best named pair so far (``best``, or
    one of score ``top`` found elsewhere): a pair's score is its nested held-out chi2 (>= 0) plus both choices'
    freedom (:func:`choice_penalty`), so with that freedom alone at or above the named score it cannot
    (:func:`_win_target` is then <= 0)."""
    named_top = min(top, _named_score(best))
    return bool(np.isfinite(named_top) and named_top - choice_penalty(first) - choice_penalty(second) <= 0.0)


def _named_score(c: dict | None) -> float:
    """The score (penalised nested held-out chi2, ``_chi2_cv``) of a named pair; inf for any other (:func:`_better`:
    only a named pair of a lower score replaces a named one)."""
    return float(c["_chi2_cv"]) if _named_pair(c) else np.inf     # type: ignore[index]


def _named_pair(c: dict | None) -> bool:
    return c is not None and bool(c["significant"] and c["adequate"])


def _second_cause(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, fits: list, found: list,
                  judge: _Judge, names: Sequence[str] | None, firsts: list | None = None,
                  opened: bool = False) -> dict | None:
    """Forward selection of a second cause (:mod:`analysis.diagnosis.physical_pairs`): on top of each single cause
    that gains anything held out (the significant first, then by held-out gain; stopped once a named pair leaves the
    held-out modes within their uncertainty), the other causes (a cause of many options, a crack, also refined with
    the first at each option, :func:`_held_seconds`); the best pair by nested held-out error, judged like a
    single cause and against the first cause alone (:func:`_on_top_enough`); ``firsts`` given: on top of those only. Pairs are
    compared by nested held-out chi2 plus their choices' freedom (:func:`choice_penalty`). A pair worth
    naming has its choices made again where both causes are refined (:func:`rechoose`). Two causes that
    change one member (:func:`_one_member`) are adequate only when they also leave the held-out modes within
    their uncertainty (:func:`_held_out_per_mode` at most ``rule.leaves_chi2``): the stiffness and the mass of
    one member scaled together stand in for a change of its geometry (a longer member: EI/L^3 and its
    mass), which the catalogue does not hold and which only the modes they leave tell apart.
    With no pair found and no first cause that leaves the held-out modes within their uncertainty (at most
    ``rule.leaves_chi2`` per mode: then there is no second physical change to find), the first causes with a
    choice are tried again with their choice held open and their parameters refined with the second cause
    (``opened``, :func:`_opened`); a named first cause keeps its choice (it was named on its own) and only
    its parameters are refined with the second. When that names no pair either and no single cause was named,
    the first round's best pair's second cause, fitted alone with the parameters it took in that pair
    (:func:`_as_first`), is a first cause too (unless a first cause is that cause in that form): a cause
    fitted alone with more freedom absorbs part of the other change (the supports' translational springs
    softened for a block on the beam), which then fits nowhere alone (the block is no first cause) and
    explains nothing on top of it."""
    alone = firsts is None
    if firsts is None:
        # two changes at once may leave every single cause short of significance: then the best by held-out gain
        firsts = sorted((c for c in found if c["gain_db"] > 0), key=lambda c: not c["significant"])
    best: dict | None = None
    # a fleet's unit: the first cause its scatter takes is searched first (:func:`_scatter_first`); the firsts before
    # it are still searched, each only for a pair that beats the best named so far
    lead = _scatter_first(sim, firsts) if alone and not opened else None
    order = ([] if lead is None else [firsts[lead]]) + [c for i, c in enumerate(firsts) if i != lead]
    for k, first in enumerate(order):
        # a second cause of many options (a crack) is also refined with the first at every option (held): the
        # first fitted alone (a loose support) absorbed part of it, and on top of that fit the crack's mirror
        # element explains as much as its own (a crack beside a crack: split_choice's grid, on one member)
        held = not opened and not splits(specs[first["_fit"].cause])
        best = _better(best, _on_top_of(sim, specs, mm, fmax, first, judge, names, opened, held=held,
                                        bound=_named_score(best)))
        if _leaves_within(best, judge.rule) and (lead is None or k >= lead):
            break           # a named pair that leaves the held-out modes within their uncertainty: none does better
    # a first cause that leaves the held-out modes within their uncertainty leaves no second physical change to find
    explained = any(_held_out_per_mode(c["_fit"].cv_per_mode, judge) <= judge.rule.leaves_chi2 for c in firsts)
    first_round = best
    if not opened and not explained and not _named_pair(best):
        # a first cause fitted alone may have absorbed the second change (a mass grown at the wrong node, a
        # member's factor pulled by heavier sensors): nothing on top of it helps, refined with it the pair shows
        chosen = ([c for c in firsts if specs[c["_fit"].cause].choice is not None and len(c["_fit"].ranked) > 1]
                  if alone else [{**c, "_fit": replace(c["_fit"], ranked=[])} for c in firsts])
        more = _second_cause(sim, specs, mm, fmax, fits, found, judge, names, chosen, opened=True) if chosen else None
        if more is not None and (best is None or _named_pair(more)):
            best = more
    if alone and not opened and not explained and first_round is not None and not _leaves_within(best, judge.rule):
        # the first round's best pair's second cause as a first cause: beside the pair's other cause it took only
        # the freedom its own change needs, and fitted alone in that form it leaves the other change in the data
        name, free = first_round["_pair"].causes[1], first_round["_free"]
        if all((c["_fit"].cause, c["_fit"].free) != (name, free) for c in firsts):
            first = _as_first(sim, specs, mm, fmax, name, free)
            best = _better(best, _on_top_of(sim, specs, mm, fmax, first, judge, names, opened,
                                            bound=_named_score(best)))
    return best


def _scatter_first(sim: PhysicalSimulation, firsts: Sequence[dict]) -> int | None:
    """The place among ``firsts`` of the simulation's ``scatter_cause`` (a fleet's unit: the global cause every unit
    holds), None without one. Searched first, its pair with the unit's defect (the whole change of a fleet's
    defective unit) bounds the search on top of the firsts before it by the pairs' choices' freedom: on top of a cause
    of many options (a mass at one of ~30 nodes) every pair's score is at least that choice's freedom, above a pair
    that fits the unit to its noise, and nothing there is made (:func:`_hopeless`)."""
    scatter = _scatter_cause(sim)
    return next((i for i, c in enumerate(firsts) if c["_fit"].cause == scatter), None) if scatter else None


def _pair_search(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, fits: list, found: list,
                 judge: _Judge, names: Sequence[str] | None, firsts: list | None, named: dict | None) -> dict | None:
    """The best pair (:func:`_second_cause` on top of ``firsts``); with a named single cause ``named`` and no pair
    named on top of it, a pair of one kind in its place (:func:`_rival_pair`); for a fleet's unit, the better of it and
    another local cause with the unit's scatter (:func:`_scatter_rivals`)."""
    two = _second_cause(sim, specs, mm, fmax, fits, found, judge, names, firsts=firsts)
    if named is not None and not _named_pair(two):
        two = _rival_pair(sim, specs, mm, fmax, fits, found, judge, names, named) or two
    if named is None:
        two = _better(two, _local_pairs(sim, specs, mm, fmax, found, judge, names, two))
    return _better(two, _scatter_rivals(sim, specs, mm, fmax, found, judge, names, named, bound=_named_score(two)))


def _local(spec: CauseSpec) -> bool:
    """Whether ``spec`` is a change at one place of many (a support or a joint, with an option for each place and
    one for every place at once; an element's stiffness): a defect of the frame's own, named with its place."""
    return spec.choice is not None and (spec.every is not None or splits(spec))


def _local_firsts(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, found: list,
                  names: Sequence[str]) -> list[dict]:
    """The local causes of ``found`` (:func:`_local`, among ``names``) as first causes of a pair, each at each of its
    places: a support or a joint fitted alone at each place (every parameter free, from its fit there), cross-
    validated as the pairs are (:func:`_as_first`); an element's stiffness as fitted (its pairs on one member are
    searched on a grid of both factors, :func:`split_choice`). Fitted alone at every place, each support or joint
    stands between two defects; at its own place it leaves the other defect in the data."""
    out = []
    for c in found:
        fit: PhysicalFit = c["_fit"]
        spec = specs[fit.cause]
        if fit.cause not in names:
            continue
        if spec.every is None:
            out.append(c)
            continue
        widest = max(variants(spec), key=len)
        starts = {str(o): q for _, o, q in fit.ranked}
        for place in spec.places:
            out.append(_as_first(sim, specs, mm, fmax, fit.cause, widest, options=[place],
                                 nested=[starts[str(place)]] if str(place) in starts else []))
    out.sort(key=lambda c: c["_fit"].chi2)       # the closest first: a pair named early bounds the others
    return out


def _local_pairs(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, found: list, judge: _Judge,
                 names: Sequence[str] | None, best: dict | None) -> dict | None:
    """Two local causes (:func:`_local`: a support, a joint, an element, each at its place) when no single cause is
    named: two defects at once leave every single cause short (a loose support beside a crack on the beam, two
    cracks side by side in one column), and the first causes of :func:`_second_cause`, chosen by their held-out
    gain alone, may hold no local cause at the right place (the supports fitted at every support at once, a
    member's stiffness for two cracks). Each local cause at each of its places (:func:`_local_firsts`) is a first
    cause, the local causes on top of it (:func:`_on_top_of`), judged by the same rule as every pair. A first cause
    is skipped when no pair with it can beat ``best`` (a named pair): a pair's penalised held-out chi2 is at least
    its two choices' freedom (:func:`choice_penalty`), so with ``best``'s below that nothing is dropped that could
    win. Only a named pair is of use here (the first round's best pair stands for the unnamed): a pair that cannot
    be named is not cross-validated (:func:`_win_target`, ``named_only``). The best named pair, or None."""
    local = [n for n, s in specs.items() if _local(s) and (names is None or n in names)]
    if len(local) < 1:
        return None
    floor = min(choice_penalty(specs[n]) for n in local)
    top = best["_chi2_cv"] if _named_pair(best) else np.inf       # type: ignore[index]
    if 2.0 * floor >= top:
        return None
    out: dict | None = None
    for first in _local_firsts(sim, specs, mm, fmax, found, local):
        if choice_penalty(specs[first["_fit"].cause]) + floor >= top:
            continue
        c = _on_top_of(sim, specs, mm, fmax, first, judge, local, opened=False, held=True, top=top, named_only=True,
                       bound=top)
        out = _better(out, c)
        if _named_pair(out):
            top = min(top, out["_chi2_cv"])                       # type: ignore[index]
    return out


def _rival_pair(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, fits: list, found: list,
                judge: _Judge, names: Sequence[str] | None, best: dict) -> dict | None:
    """A pair in place of the named single cause ``best`` when no pair is named on top of it: two changes of one kind
    at two places (two cracks in one column for its mass grown 10 %), or a cause with ``best``'s own kind beside it
    (a joint at the top of a column beside a loose support at its foot: on top of the support fitted alone, the
    joint's screen chose the other joint). The pairs on top of every other single cause with a choice that gains
    anything held out (:func:`_second_cause`; each pair cross-validated only while its refined chi2 could win,
    :func:`_win_target`); the best named pair kept only when it beats ``best`` alone (:func:`_beats_named`); else
    None."""
    local = [c for c in found if c["effect"] != best["effect"] and c["gain_db"] > 0 and specs[c["effect"]].choice]
    if not local:
        return None
    two = _second_cause(sim, specs, mm, fmax, fits, found, judge, names, firsts=local)
    return _beats_named(sim, specs, mm, fmax, judge, best, two)


def _beats_named(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, judge: _Judge, best: dict,
                 two: dict | None) -> dict | None:
    """The named pair ``two``, found on top of another first cause than the named single cause ``best``, when it
    predicts the held-out modes better than ``best`` alone by the held-out gain rule (:func:`_on_top_enough` against
    ``best`` cross-validated as the pairs are; the freedom of the pair's second cause counted, and the choice of its
    first when ``best`` is not that cause): with the gain and the chi2 removed over ``best``; else None."""
    if two is None or not _named_pair(two):
        return None
    causes = two["_pair"].causes
    chosen = two["_choices_chi2"]
    freedom = (PARAMETER_CHI2 * len(two["_free"]) + chosen[1]
               + (chosen[0] if causes[0] != best["effect"] else 0.0))
    cv_best, cv_pair = _alone_cv(sim, specs, mm, fmax, best), two["_pair"].cv_per_mode
    over, removed, enough = _on_top_enough(cv_best, cv_pair, freedom, judge.rule)
    if not enough:
        return None
    return {**two, "gain_over_first_db": over, "removed_over_first_chi2": removed,
            "_over_first": {"held_out_first_chi2": float(np.sum(cv_best)), "held_out_pair_chi2": float(np.sum(cv_pair)),
                            "freedom_chi2": freedom, "modes": int(cv_pair.size)}}


def _scatter_rivals(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, found: list, judge: _Judge,
                    names: Sequence[str] | None, best: dict | None, bound: float = np.inf) -> dict | None:
    """A fleet unit's defect beside its scatter (a simulation that names a ``scatter_cause``, the global cause every
    unit holds): each local cause (:func:`_local`) that gains anything held out, other than the named single cause
    ``best``, with the global cause (and its own cause at another place) on top of it (:func:`_on_top_of`, named pairs
    only); with ``best``, kept only when it predicts the held-out modes better than ``best`` alone by the held-out gain
    rule (:func:`_on_top_enough`, ``best`` cross-validated as the pairs are, the second cause's freedom counted). The
    pair search's first causes are the named one, or the one of the largest held-out gain: the cause that took up
    most of the unit's scatter (a member's mass for the material's density; the global cause itself, with a joint's
    springs beside it for a crack next to the joint), while the defect's own cause with the scatter fits the unit to
    its noise. The best such pair (:func:`_better`), or None (not a fleet's unit: None)."""
    scatter = _scatter_cause(sim)
    if scatter is None or scatter not in specs or (names is not None and scatter not in names):
        return None
    out: dict | None = None
    for c in found:
        if c is best or c["gain_db"] <= 0 or c["effect"] == scatter or not _local(specs[c["effect"]]):
            continue
        two = _on_top_of(sim, specs, mm, fmax, c, judge, [c["effect"], scatter], opened=False, named_only=True,
                         bound=min(bound, _named_score(out)))
        out = _better(out, two if best is None else _beats_named(sim, specs, mm, fmax, judge, best, two))
    return out


def _leaves_within(c: dict | None, rule: DecisionRule) -> bool:
    """A named pair that leaves the held-out modes within their uncertainty (at most ``rule.leaves_chi2`` per
    counted mode): no other pair can do clearly better."""
    return _named_pair(c) and c["held_out_chi2_per_mode"] <= rule.leaves_chi2  # type: ignore[index]


def _better(best: dict | None, c: dict | None) -> dict | None:
    """The better of two judged pairs: named (significant and adequate) first, then the lower penalised
    nested held-out chi2 (``_chi2_cv``)."""
    if c is None:
        return best
    if best is None or (c["significant"] and c["adequate"], -c["_chi2_cv"]) > (
            best["significant"] and best["adequate"], -best["_chi2_cv"]):
        return c
    return best


def _as_first(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, name: str, free: tuple,
              options: Sequence[str] | None = None, nested: Sequence[dict] = ()) -> dict:
    """The cause ``name`` with the parameters ``free`` fitted alone on all modes (its choice searched over
    ``options``, None: every option; ``nested``: further starts, :func:`fit_cause`) as a first cause of pairs
    (:func:`_on_top_of`): refined as the pairs refine it (:func:`_alone_refined`), cross-validated so when a pair on
    top of it is (:func:`_alone_cv`, its held-out chi2 per mode then the fit's ``cv_per_mode`` too)."""
    spec = specs[name]
    p, chi2, ranked = fit_cause(sim, spec, free, mm, np.ones(mm.freq_hz.size, bool), fmax, options=options,
                                nested=nested)
    first = {"_fit": PhysicalFit(cause=name, params=p, free=free, chi2=chi2, ranked=ranked, at_edge=spec.at_edge(p, free))}
    _alone_refined(sim, specs, mm, fmax, first)
    return first


def _win_target(best: dict | None, top: float, judge: _Judge, first: dict, cv_alone: float | Callable[[], float],
                freedom: float, own: float, penalty: float, named_only: bool = False) -> float:
    """The chi2 on all modes a pair must come below to beat ``best`` (the best judged pair so far) or a named pair
    of score ``top`` found elsewhere (:func:`_better`); inf: any pair could. A pair's refined chi2 on all modes is
    at least the least chi2 ``min S`` over its parameters, and so is its nested held-out chi2: with each fit at its
    least-squares minimum, fold k's held-out chi2 is its fit's chi2 on all modes less that on the other modes, at
    least ``min S - S_-k(x*)`` (``x*`` the all-modes minimum), which sums over the folds to at least ``min S``. So a
    pair whose ``min S`` exceeds what it may keep on all modes (``first``'s chi2 alone less the second cause's
    ``own`` freedom) or held out (``cv_alone`` less ``freedom`` and ``rule.quiet_chi2``, :func:`_on_top_enough`)
    cannot be named, and its score is at least ``min S`` plus its choices' ``penalty``: one that cannot be named
    and cannot score below ``best``, or that cannot score below a named pair, cannot win. Named also means
    ``rule.physical_min_gain_db`` over ``first`` alone held out, and significant and adequate as one candidate
    (:meth:`_Judge.most_named_chi2`). ``named_only``: only a named pair is of use (the unnamed are not kept).
    ``cv_alone`` may be given as a function that makes it: asked only when the target depends on it (by the same rule,
    ``cv_alone`` is at least ``first``'s chi2 alone on all modes; where the terms of it could not be the least even
    there, or the target is the other bound whatever they are, it is not made)."""
    rule = judge.rule
    named_top = min(top, _named_score(best))
    bounded = bool(np.isfinite(named_top) or named_only)
    if not bounded and best is None:
        return np.inf
    fixed = min(first["_alone_chi2"] - own, judge.most_named_chi2())
    other = named_top - penalty if bounded else best["_chi2_cv"] - penalty    # type: ignore[index]

    def nameable(cv: float) -> float:
        return min(fixed, cv - freedom - rule.quiet_chi2, cv * rule.physical_min_gain_factor)

    if callable(cv_alone):
        least = nameable(float(first["_alone_chi2"]))
        if least == fixed:
            can = fixed                     # the terms of the held-out chi2 are not the least
        elif least >= other if bounded else fixed <= other:
            return float(other)             # the other bound decides whatever the held-out chi2 is
        else:
            can = nameable(float(cv_alone()))
    else:
        can = nameable(float(cv_alone))
    return float(min(can, other)) if bounded else float(max(can, other))


def _judged_pair(judge: _Judge, specs: dict, two: PairFit, cv_first: np.ndarray, first_chi2: float,
                 free: tuple, own_params: float, counted: float) -> dict:
    """The pair ``two`` (first cause, second cause) judged as a candidate (:meth:`_Judge.judge`) and against its first
    cause alone, of held-out chi2 per mode ``cv_first`` and chi2 on all modes ``first_chi2`` (:func:`_on_top_enough`):
    what it chose is the second cause's choice at the option it holds (:func:`choice_freedom`), its parameters
    ``free`` (their freedom ``own_params``, chi2 units) and ``counted``, 2 ln(number of second causes refined). Its
    score (``_chi2_cv``): the nested held-out chi2 plus both choices' penalty (:func:`choice_penalty`), alike at
    every option."""
    # what each choice chose at the options the pair was fitted at (one cause at every place and at one of two
    # places, said place by place below, chose one place)
    causes = [specs[n] for n in two.causes]
    chosen = [choice_freedom(spec, p) for spec, p in zip(causes, two.params)]
    freedom = counted + chosen[1]
    two = replace(two, params=as_places(causes, two.params))
    c = judge.judge(two.changes, two.cv_per_mode, two.at_edge)
    c["gain_over_first_db"], c["removed_over_first_chi2"], enough = _on_top_enough(
        cv_first, two.cv_per_mode, freedom, judge.rule)
    c["_over_first"] = {"held_out_first_chi2": float(np.sum(cv_first)),
                        "held_out_pair_chi2": float(np.sum(two.cv_per_mode)), "freedom_chi2": freedom,
                        "modes": int(cv_first.size)}
    # the second cause earns its keep on all modes too: the pair lowers chi2 there by at least its freedom (a
    # cause left near its nominal changes nothing, whatever its refits in the folds gained on held-out modes)
    kept = first_chi2 - two.chi2 >= own_params + chosen[1]
    c["significant"] = bool(c["significant"] and enough and kept)
    c["held_out_chi2_per_mode"] = _held_out_per_mode(two.cv_per_mode, judge)
    c["one_member"] = _one_member(causes, two.params)
    if c["one_member"] is not None and c["held_out_chi2_per_mode"] > judge.rule.leaves_chi2:
        c["adequate"] = False
    c["_pair"] = two
    c["_free"] = free
    c["_stages"] = [{"effect": name, "parameters": shown_params(specs[name], p), "gain_db": c["gain_db"],
                     "error_after_db": c["error_after_db"]} for name, p in two.changes]
    c["effect"] = "+".join(two.causes)
    c["_choices_chi2"] = chosen
    c["_chi2_cv"] = two.chi2_cv + sum(choice_penalty(spec) for spec in causes)
    return c


def _on_top_of(sim: PhysicalSimulation, specs: dict, mm: MeasuredModes, fmax: float, first: dict, judge: _Judge,
               names: Sequence[str] | None, opened: bool, held: bool = False, top: float = np.inf,
               named_only: bool = False, bound: float = np.inf) -> dict | None:
    """The best pair with the first cause ``first`` (a judged single cause): its second causes
    (:func:`_seconds`, or :func:`_opened` with its choice held open; the ``N_SECOND`` best of the screen first, then
    every other) refined with it, cross-validated nested and judged (:func:`_second_cause`); ``held``: also a second
    cause of many options refined with it at every option (:func:`_held_seconds`). Two changes of one cause split from ``first``
    (:func:`split_choice`) are taken in the grid's order, each while its lower bound says it could still win
    (:func:`_win_target`; ``top``: the score of a named pair found elsewhere, which only a better named pair beats);
    a pair whose refined chi2 on all modes is not below that target is not cross-validated (its nested held-out
    chi2 is at least its chi2 on all modes where the refinement reaches the least-squares minimum). ``bound`` (and
    ``top``): the score of a named pair found elsewhere; a pair whose two choices' freedom alone reaches it cannot
    beat it whatever its choices become (:func:`rechoose` keeps the causes), so it is not made (:func:`_hopeless`):
    nothing when no second cause can, and a second cause that cannot is fitted on top of the first only for its rank.
    Unlike ``top`` it does not lower the target a pair's refined chi2 must come below (a pair refined at its first
    choices may still be chosen again to a better one)."""
    fa: PhysicalFit = first["_fit"]
    on = _on_top_specs(specs.values(), fa, names)
    bound = min(bound, top)
    if all(_hopeless(None, bound, specs[fa.cause], spec) for spec in [*on, specs[fa.cause]]):
        return None                         # no pair on top of it can beat the named score ``bound`` (:func:`_hopeless`)
    progress("diagnosis: second cause on top of %s%s", fa.cause, ", its choice held open" if opened else "")
    _alone_refined(sim, specs, mm, fmax, first)

    def cv_alone() -> np.ndarray:           # made when a pair is cross-validated or a target needs it
        return _alone_cv(sim, specs, mm, fmax, first)
    unbounded = SplitBound(None)
    seconds: list[PhysicalFit] = []
    others: list[PhysicalFit] = []
    left: list[str] = []
    if not opened:
        # a second cause whose pairs with the first cannot win (:func:`_hopeless`) is fitted only for its rank
        seconds, left, others = _on_top_fits(sim, mm, fmax, fa, names, judge.kept,
                                             lambda spec: _hopeless(None, bound, specs[fa.cause], spec))
    counted = _leading(sim, seconds, N_SECOND)
    # the pairs in the order they are judged; a group of pairs made only when it is reached and one of them could
    # still win (:func:`_hopeless`): the first refitted beside a counted second cause, every two elements split from
    # the first (:func:`split_choice`), a second cause of many options refined with the first at every option
    pairs: list = (_opened(sim, specs, mm, fmax, fa, names, judge.kept) if opened else
                   [(unbounded, None, fb) for fb in counted]
                   + [(unbounded, a, b) for a, b in split_places(specs[fa.cause], fa)])
    causes = {fb.cause for _, _, fb in (pairs[:N_SECOND] if opened else pairs)} | set(left)
    if not opened and splits_in_two(specs[fa.cause], fa, across=held):
        causes.add(fa.cause)
        # made when reached, at the target a split pair has then (:func:`split_choice` leaves out those that cannot
        # come below it; the search's targets only fall)
        pairs.append(_Later((fa.cause,), lambda: split_choice(sim, specs[fa.cause], fa, mm, fmax, across=held,
                                                              below=target_of(fa))))
    if held:
        spread = tuple(n for n, spec in specs.items() if (names is None or n in names) and held_spec(spec, fa) is not None)
        causes.update(spread)
        pairs.append(_Later(spread, lambda: _held_seconds(sim, specs, mm, fmax, fa, names)))
    # the second causes the freedom counts: held open, the N_SECOND best of the screen (the others are kept by
    # their bound only)
    n_seconds = max(1, len(causes))
    # the other second causes of the screen, each refined with the first last: cross-validated only while its
    # refined chi2 on all modes could win (:func:`_win_target`), so none is dropped by its rank on the screen
    # (the other kind of a cause with an option for every place after them, :func:`_kinds`)
    todo = _expanded([*pairs, *((unbounded, None, fb) for fb in seconds if all(fb is not g for g in counted)),
                      *((unbounded, None, fb) for fb in others)],
                     lambda group: all(_hopeless(best, bound, specs[fa.cause], specs[n]) for n in group.causes))
    best: dict | None = None

    def target_of(fb: PhysicalFit) -> float:
        """The chi2 on all modes a pair with the second cause ``fb`` must come below now (:func:`_win_target`), what
        its second cause chose at its least (:func:`rechoose` may still move it)."""
        least = least_choice_freedom(specs[fb.cause])
        return _win_target(best, top, judge, first, lambda: float(np.sum(cv_alone())),
                           2.0 * float(np.log(n_seconds)) + least, PARAMETER_CHI2 * len(fb.free) + least,
                           choice_penalty(specs[fa.cause]) + choice_penalty(specs[fb.cause]), named_only)

    for below, fa2, fb in todo:
        target = target_of(fb)
        if target <= 0.0 or _hopeless(best, bound, specs[fa.cause], specs[fb.cause]) or not below.below(target):
            continue                        # its exact score cannot win (:func:`_win_target`; a chi2 is >= 0)
        if fa2 is None:
            fa2 = refit_on_top(sim, specs[fa.cause], fa, fb, mm, fmax, best_only=True)
        # each cause's variant made again beside the other (:func:`widened`); the parameters it frees count too
        n_free, own = len(fa2.free) + len(fb.free), PARAMETER_CHI2 * len(fb.free)
        fa2, fb = widened(sim, [specs[fa.cause], specs[fb.cause]], [fa2, fb], mm, fmax)
        own += PARAMETER_CHI2 * (len(fa2.free) + len(fb.free) - n_free)
        two = fit_pair(sim, [specs[fa.cause], specs[fb.cause]], [fa2, fb], mm, fmax, folds_below=target)
        if two.cv_per_mode.size < mm.freq_hz.size:
            continue                        # refined on all modes, no better than ``target``: not cross-validated
        made = [two]
        if gain_db(fa.cv_per_mode if fa.cv_per_mode.size else cv_alone(), two.cv_per_mode) >= judge.rule.physical_min_gain_db:
            again = rechoose(sim, [specs[fa.cause], specs[fb.cause]], [fa2, fb], two, mm, fmax)
            # chosen again by chi2 on all modes; the pair as refined is judged too, for the choices' freedom differs
            # between options (a joint at one place fits a little better than every joint, and chooses a place)
            made = [again] if again.params == two.params else [again, two]
        for two in made:
            c = _judged_pair(judge, specs, two, cv_alone(), first["_alone_chi2"], fb.free, own,
                             2.0 * float(np.log(n_seconds)))
            if named_only and not _named_pair(c):
                continue
            best = _better(best, c)
    return best
