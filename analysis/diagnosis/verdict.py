"""Cross-validated gain of each effect, its significance, and the verdict.

Rule (documented in ``docs/diagnosis.md``):

1. **Cross-validation.** The lines of the band are split into two folds of alternating blocks of
   four contiguous lines (:func:`analysis.diagnosis.compare.line_folds`: not single interleaved
   lines, whose noise is correlated with their neighbours'; mains lines are cross-validated by
   harmonics instead). Each effect is fitted on one fold and scored on the other, both ways, so every
   line is scored once by a model that did not see it. ``before_i`` and ``after_i`` are the weighted
   squared errors (see :mod:`analysis.diagnosis.compare`) of the simulation and of the extended
   simulation on held-out line/FRF ``i``. ``gain_db = 10 log10(mean before / mean after)``.
   A flexible effect that only fits noise cannot predict the other fold, so its held-out gain is
   about zero or negative.
2. **Significance** (:meth:`analysis.diagnosis.rule.DecisionRule.significant`; every threshold is a
   field of the one :class:`~analysis.diagnosis.rule.DecisionRule`). The paired differences
   ``d_i = before_i - after_i`` give ``z = mean(d) / (std(d) / sqrt(N))``. An effect's gain is
   significant when ``gain_db >= min_gain_db`` (0.5 dB, an 11 % smaller held-out error) *and* either
   ``z >= z_min`` (3) or ``gain_db >= strong_gain_db`` (3 dB: the held-out error halved; an effect that
   acts on a few lines only, e.g. one missing mode, gives heavy-tailed ``d`` and a modest ``z`` although
   its gain is tens of dB). Vetoes (named rules): a parameter at the edge of its physical range, a
   resonator that gains little more than a mass, a mass or a stiffness the modes disfavour. Under noise
   alone the held-out gain is a few hundredths of a dB (measured in the benchmark's null cases), far
   below both thresholds.
3. **Verdict.** The significant effect with the largest gain (a mass at every sensor and a stiffness
   change, both significant, are first held against each other mode by mode: :func:`_mass_or_stiffness`,
   :mod:`analysis.diagnosis.mode_vote`). With none significant: ``none`` when
   the typical error of the simulation (median over lines of ``w |e|^2`` / ln 2, robust to a few
   antiresonance lines) is within ``none_margin_db`` (3 dB) of the noise level estimated from the
   data by the same statistic of second differences along frequency (with coherence: the larger of
   that and the coherence estimate), else ``unexplained`` with the bands where the error stands above
   the noise.
"""
from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..frf import FRFSet
from ..modal import ModalModel
from ..progress import progress
from ..threads import limits_blas_threads
from .compare import band_errors, compare, effective_noise_db, held_out_errors, line_weights, noise_level, typical_error_db
from .effect_types import applied, named, stage_entry
from .effects import EFFECTS, EffectError, FitContext, predict
from .rule import DEFAULT_RULE, DecisionRule, held_out_db, step
from .verdict_part import VerdictPart

if TYPE_CHECKING:
    from .physical import MeasuredModes, PhysicalSimulation

__all__ = ["Diagnosis", "diagnose_frfs", "named_verdict"]

log = logging.getLogger(__name__)


@dataclass
class Diagnosis(VerdictPart):
    """Outcome of :func:`analysis.diagnosis.diagnose`.

    verdict : the named cause's name, ``"combined"`` when two causes are named, ``"none"`` or
        ``"unexplained"`` (or a time-data cause when the FRFs leave the difference unexplained, or
        ``"joint_nonlinearity"`` when the hits' force levels name a nonlinear joint).
    named : the named causes, ``{"effect", "parameters"}`` each (at most two).
    causes : one dict per effect tried, sorted by held-out gain: ``effect``, ``parameters`` (fitted on
        all lines), ``gain_db``, ``error_before_db``, ``error_after_db``, ``z``, ``significant``, ``evidence``.
    error_before_db, error_after_db : held-out error of the simulation and of the verdict's extension.
    noise_db : noise level estimates (dB). comparison : :func:`analysis.diagnosis.compare.compare`.
    unexplained : bands where the best model's error stays above the noise.
    combined : the accepted effects stage by stage (verdict first), each with its held-out gain on top
        of the previous ones; ``error_after_db`` is the last stage's.
    measured, simulated, extended : the FRF sets (extended = simulation with the accepted effects).
    level_dependence : a recording's soft against hard hits and the ``joint_nonlinearity`` cause
        (:func:`analysis.diagnosis.joint_nonlinearity.level_dependence`), None without levels to compare.
    linear_verdict : the verdict of the FRF comparison when ``joint_nonlinearity`` replaced it, else None.
    trace : the rules that decided, in the order they were applied, each ``{"rule", "cause", "values",
        "outcome"}`` (:func:`analysis.diagnosis.rule.step`; the rules: :data:`analysis.diagnosis.rule.RULES`).
    rule : the :class:`~analysis.diagnosis.rule.DecisionRule` the verdict was reached with.
    """

    noise_db: dict
    comparison: dict
    unexplained: list
    measured: FRFSet
    simulated: FRFSet
    skipped: dict = field(default_factory=dict)
    physical: dict = field(default_factory=dict)
    time_data: list = field(default_factory=list)
    time_data_verdict: str | None = None
    level_dependence: dict | None = None
    linear_verdict: str | None = None
    trace: list = field(default_factory=list)
    rule: DecisionRule = DEFAULT_RULE

    @property
    def bands(self) -> list[dict]:
        """The error per band, as the report and ``bands.png`` draw it: ``lo_hz``, ``hi_hz`` (Hz),
        ``simulation_db`` (the comparison's band error) and ``extended_db`` (the same bands of the
        extension: :attr:`extended`, the simulation with the accepted effects), dB."""
        simulation = (self.comparison or {}).get("bands") or []
        measured: Any = self.measured
        if measured is None or self.extended is None:   # assembled without its FRF sets: the extension unknown
            return [{"lo_hz": b["lo_hz"], "hi_hz": b["hi_hz"], "simulation_db": b["error_db"], "extended_db": None}
                    for b in simulation]
        after = band_errors(measured, self.extended.H, line_weights(measured))
        return [{"lo_hz": b["lo_hz"], "hi_hz": b["hi_hz"], "simulation_db": b["error_db"], "extended_db": a["error_db"]}
                for b, a in zip(simulation, after)]

    @property
    def noise_level_db(self) -> float:
        """The noise level (dB) the verdict was judged against: :func:`~analysis.diagnosis.compare.effective_noise_db`
        of :attr:`noise_db`."""
        return effective_noise_db(self.noise_db)

    def to_json(self) -> dict:
        """The JSON document of ``python -m analysis diagnose``."""
        doc = {
            "verdict": self.verdict,
            "named": [named(c) for c in self.named],
            "causes": [{k: c[k] for k in ("effect", "parameters", "gain_db", "evidence", "error_before_db",
                                          "error_after_db", "z", "significant")}
                       | {k: c[k] for k in ("kind", "adequate", "description", "advice") if k in c} for c in self.causes],
            "error_before_db": self.error_before_db,
            "error_after_db": self.error_after_db,
            "noise_db": self.noise_db,
            "unexplained": self.unexplained,
            "skipped": self.skipped,
            "combined": self.combined,
            "reason": self.reason,
            "physical": _jsonable(self.physical),
            "comparison": _jsonable(self.comparison),
            "trace": _jsonable(self.trace),
            "rule": self.rule.as_dict(),
            "bands": self.bands,
        }
        if self.next_measurement is not None:
            doc["next_measurement"] = _jsonable(self.next_measurement)
        if self.time_data:
            doc["time_data"] = self.time_data
            doc["time_data_verdict"] = self.time_data_verdict
        if self.level_dependence is not None:
            doc["level_dependence"] = _jsonable(self.level_dependence)
        if self.linear_verdict is not None:
            doc["linear_verdict"] = self.linear_verdict
        return doc


def named_verdict(named: Sequence[dict]) -> str:
    """The verdict of the named causes: the cause's name for one, ``"combined"`` for two."""
    return named[0]["effect"] if len(named) == 1 else "combined"


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items() if k != "vector"}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return x


def _held_out(ctx: FitContext, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Per line/FRF weighted squared errors (before, after) on held-out lines, both folds. With the
    default folds each is the raveled (n_out, n_ref, n_freq) array of every line's error as predicted by
    the fit on the other fold (an effect's own cross-validation may give another layout)."""
    eff = EFFECTS[name]
    own = eff.held_out(ctx) if eff.held_out is not None else None
    if own is not None:
        return own
    m = ctx.measured

    def fitted_on(train: np.ndarray) -> np.ndarray:
        return predict(ctx.base, m.freq_hz, m.quantity, ctx.effects({"effect": name, **eff.fit(ctx, train)}),
                       outputs=m.outputs, references=m.references).H
    return held_out_errors(m.H, ctx.sim.H, ctx.weights, fitted_on)


def _evidence(name: str, params: dict, before_db: float, after_db: float, z: float, band_gain: list) -> str:
    top = max(band_gain, key=lambda b: b[2]) if band_gain else None
    where = f"; largest change {top[2]:.1f} dB in {top[0]:.3g}-{top[1]:.3g} Hz" if top else ""
    show = {k: v for k, v in params.items() if not isinstance(v, (list, dict))}
    ps = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in show.items())
    return (f"{name} ({ps}): held-out error {before_db:.1f} -> {after_db:.1f} dB, z = {z:.1f}{where}")


def _stage(ctx: FitContext, names: Sequence[str], rule: DecisionRule, trace: list,
           min_gain_db: float | None = None) -> tuple[list, dict]:
    """Fit every effect in ``names`` on top of ``ctx.prior`` with cross-validation; causes sorted by gain.
    Each effect's significance (``rule``; ``min_gain_db``: another gain floor than ``rule.min_gain_db``, e.g.
    on top of a named physical cause) and its vetoes are appended to ``trace``."""
    floor = rule.min_gain_db if min_gain_db is None else min_gain_db
    m, w = ctx.measured, ctx.weights
    causes, skipped = [], {}
    for i, name in enumerate(names, start=1):
        progress("diagnosis: effect %d/%d, %s", i, len(names), name)
        eff = EFFECTS[name]
        missing = [k for k in eff.needs if k not in ctx.base.meta]
        if missing:
            skipped[name] = _missing_needs(name, missing, ctx)
            continue
        why = eff.applies(ctx) if eff.applies is not None else ""
        if why:
            from .effect_types import NOT_APPLICABLE

            skipped[name] = f"{NOT_APPLICABLE}: {why}"
            log.info("effect %s not applicable: %s", name, why)
            continue
        try:
            before, after = _held_out(ctx, name)
            params = eff.fit(ctx, np.ones(m.freq_hz.size, bool))
        except (EffectError, np.linalg.LinAlgError, ValueError) as exc:
            skipped[name] = f"fit failed: {exc}"
            log.info("effect %s skipped: %s", name, exc)
            continue
        b_db, a_db, z = held_out_db(before, after)
        gain = b_db - a_db
        ext = predict(ctx.base, m.freq_hz, m.quantity, ctx.effects({"effect": name, **params}),
                      outputs=m.outputs, references=m.references)
        bb = band_errors(m, ctx.sim.H, w)
        ba = band_errors(m, ext.H, w)
        band_gain = [(x["lo_hz"], x["hi_hz"], x["error_db"] - y["error_db"]) for x, y in zip(bb, ba)]
        causes.append({
            "effect": name, "parameters": params, "gain_db": gain, "error_before_db": b_db,
            "error_after_db": a_db, "z": z,
            "significant": replace(rule, min_gain_db=floor).significant(gain, z),
            "evidence": _evidence(name, params, b_db, a_db, z, band_gain), "_extended": ext,
            "_held_out_after": after, "_held_out_before": before,
        })
        trace.append(step("significance", name, {"gain_db": gain, "z": z, "min_gain_db": floor, "z_min": rule.z_min,
                                                 "strong_gain_db": rule.strong_gain_db},
                          "significant" if causes[-1]["significant"] else "not significant"))
        edge = eff.at_range_edge(params, (float(m.freq_hz[0]), float(m.freq_hz[-1])))
        if edge and causes[-1]["significant"]:
            causes[-1]["significant"] = False
            causes[-1]["evidence"] += f"; {edge} at the edge of its physical range"
            trace.append(step("range_edge", name, {"parameter": edge}, "vetoed: not significant"))
        if name == "mains_hum" and causes[-1]["significant"]:
            _hum_on_a_mode(causes[-1], ctx, replace(rule, min_gain_db=floor), trace)
    _resonator_beyond_mass(causes, rule, trace)
    causes.sort(key=lambda c: c["gain_db"], reverse=True)
    return causes, skipped


def _hum_on_a_mode(c: dict, ctx: FitContext, rule: DecisionRule, trace: list) -> None:
    """A significant ``mains_hum`` whose held-out gain one harmonic carries alone
    (:func:`analysis.diagnosis.mains.carried_by_one_harmonic`: the gain on every other line not significant by
    ``rule``) and that harmonic inside a mode's half-power band (:func:`analysis.diagnosis.mains.half_power_mode`,
    the simulation's modes): a line there fits what the simulation leaves of a mode it misplaces (a mode a little
    off in frequency leaves a lobe a line's shape follows), which one harmonic cannot tell from interference.
    Not significant; the veto is appended to ``trace``."""
    from .mains import carried_by_one_harmonic, half_power_mode

    one = carried_by_one_harmonic(ctx, c["parameters"], c["_held_out_before"], c["_held_out_after"], rule.significant)
    mode = None if one is None else half_power_mode(ctx.base, one["harmonic_hz"])
    if one is None or mode is None:
        return
    kept, off = _hum_beside_the_mode(c, ctx, rule, one, mode)
    if kept:
        trace.append(step("hum_on_a_mode", "mains_hum", {**one, **mode, **off},
                          "kept: significant off the mode, fitted there"))
        return
    c["significant"] = False
    c["evidence"] += (f"; {100 * one['share']:.0f} % of its gain from the one harmonic at {one['harmonic_hz']:.2f} Hz, "
                      f"inside the half-power band of the mode at {mode['mode_hz']:.2f} Hz "
                      f"(+-{mode['half_power_hz']:.2f} Hz)")
    trace.append(step("hum_on_a_mode", "mains_hum", {**one, **mode, **off}, "vetoed: not significant"))


def _hum_beside_the_mode(c: dict, ctx: FitContext, rule: DecisionRule, one: dict, mode: dict) -> tuple[bool, dict]:
    """Real interference whose fit locked onto a misplaced mode's lobe: the hum fitted and cross-validated again
    with the lines of that harmonic and of the mode's half-power band weighted out
    (:func:`analysis.diagnosis.mains.off_the_mode`). Significant there by ``rule`` (the lines at the other harmonics
    hold interference of their own): ``c`` becomes that fit (parameters, held-out errors and gain on the lines kept,
    prediction), True. Else False (the veto stands): a lobe leaves nothing at the other harmonics, and a hum fitted
    there is held to the same rule as on any band. With the gain and z off the mode (the trace's values)."""
    from .mains import fit_mains_hum, held_out_mains_hum, off_the_mode

    m = ctx.measured
    keep = off_the_mode(np.asarray(m.freq_hz, float), m.line_spacing_hz, one["harmonic_hz"],
                        float(c["parameters"]["base_hz"]), mode)
    off = replace(ctx, weights=np.where(keep, ctx.weights, 0.0))
    before, after = held_out_mains_hum(off)
    lines = np.broadcast_to(keep, (before.size // keep.size, keep.size)).ravel()
    if before.size != lines.size:
        return False, {}
    b_db, a_db, z = held_out_db(before[lines], after[lines])
    values = {"gain_off_the_mode_db": b_db - a_db, "z_off_the_mode": z}
    if not rule.significant(b_db - a_db, z):
        return False, values
    params = fit_mains_hum(off, np.ones(m.freq_hz.size, bool))
    if EFFECTS["mains_hum"].at_range_edge(params, (float(m.freq_hz[0]), float(m.freq_hz[-1]))):
        return False, values
    c.update({"parameters": params, "gain_db": b_db - a_db, "error_before_db": b_db, "error_after_db": a_db, "z": z,
              "_held_out_before": before, "_held_out_after": after,
              "_extended": predict(ctx.base, m.freq_hz, m.quantity, ctx.effects({"effect": "mains_hum", **params}),
                                   outputs=m.outputs, references=m.references)})
    c["evidence"] = (_evidence("mains_hum", params, b_db, a_db, z, []) +
                     f"; fitted with the harmonic at {one['harmonic_hz']:.2f} Hz and the half-power band of the mode at "
                     f"{mode['mode_hz']:.2f} Hz (+-{mode['half_power_hz']:.2f} Hz) left out: the fit there followed the "
                     f"mode's lobe, the other harmonics hold interference of their own")
    return True, values


def _resonator_beyond_mass(causes: list, rule: DecisionRule = DEFAULT_RULE, trace: list | None = None) -> None:
    """A spring-mass tuned high acts in the band as a mass at its point: ``mass_loading`` is the
    ``local_resonator``'s stiff limit, and the resonator's own frequency and free coupling can also stand in
    for what a mass model leaves (modes just above the band it moves). With both significant the resonator
    counts only when it gains ``rule.resonator_over_mass_db`` more than the mass (the error the mass leaves
    halved); the veto is appended to ``trace``."""
    by = {c["effect"]: c for c in causes}
    res, mass = by.get("local_resonator"), by.get("mass_loading")
    if res is None or mass is None or not (res["significant"] and mass["significant"]):
        return
    more = res["gain_db"] - mass["gain_db"]
    vetoed = more < rule.resonator_over_mass_db
    if trace is not None:
        trace.append(step("resonator_beyond_mass", "local_resonator",
                          {"gain_over_mass_db": more, "resonator_over_mass_db": rule.resonator_over_mass_db},
                          "vetoed: not significant" if vetoed else "kept"))
    if vetoed:
        res["significant"] = False
        res["evidence"] += (f"; {more:.1f} dB more than a mass at a sensor (its stiff limit), less than "
                            f"{rule.resonator_over_mass_db:g} dB")


def _mass_or_stiffness(causes: list, ctx: FitContext, noise_db: float, rule: DecisionRule = DEFAULT_RULE,
                       trace: list | None = None) -> None:
    """With both a mass at every sensor and a stiffness change significant, the one the modes name: each
    scored mode by mode on its held-out errors where the two predictions differ beyond the noise
    (:func:`analysis.diagnosis.mode_vote.mode_vote`); the one with the larger gain stays the verdict
    unless the other has the smaller held-out error at more of those modes, and then it is not
    significant (``noise_db``: the noise level, dB)."""
    from .mode_vote import mode_vote

    by = {c["effect"]: c for c in causes}
    st, ma = by.get("stiffness_shift"), by.get("mass_loading")
    if st is None or ma is None or not (st["significant"] and ma["significant"]):
        return
    if ma["parameters"].get("sensor") not in (None, "all"):
        return
    m = ctx.measured
    if st["_held_out_after"].size != m.H.size or ma["_held_out_after"].size != m.H.size:
        return
    vote = mode_vote(m.freq_hz, ctx.base.freq_hz, st["_held_out_after"].reshape(m.H.shape),
                     ma["_held_out_after"].reshape(m.H.shape), st["_extended"].H, ma["_extended"].H,
                     ctx.weights, noise_db, z=rule.separation_z)
    count = {"stiffness_shift": vote["a"], "mass_loading": vote["b"]}
    first, second = (st, ma) if st["gain_db"] >= ma["gain_db"] else (ma, st)
    said = (f"mode by mode, of {vote['separable']} modes that separate a mass at every sensor from a stiffness "
            f"change, {count['mass_loading']} favour the mass and {count['stiffness_shift']} the stiffness")
    for c in (st, ma):
        c["evidence"] += f"; {said}"
    vetoed = count[second["effect"]] > count[first["effect"]]
    if trace is not None:
        trace.append(step("mass_or_stiffness", first["effect"],
                          {"separable_modes": vote["separable"], "favour_mass": count["mass_loading"],
                           "favour_stiffness": count["stiffness_shift"], "separation_z": rule.separation_z},
                          "vetoed: not significant" if vetoed else "kept"))
    if vetoed:
        first["significant"] = False


def _at_range_edge(name: str, params: dict, band_hz: tuple[float, float] | None = None) -> str:
    """The parameter of an FRF-level fit that stopped at the edge of its physical range ("" if none), from
    the effect's row (:attr:`analysis.diagnosis.effect_types.Effect.ranges`; ``band_hz``: the analysed band,
    Hz, for ranges relative to it). The data then want more than the effect can physically be, as with the
    physical causes: such a fit is not evidence of that effect (a simulation far off elsewhere is)."""
    return EFFECTS[name].at_range_edge(params, band_hz)


def _missing_needs(name: str, missing: Sequence[str], ctx: FitContext) -> str:
    """Why ``name`` could not be fitted and which measurement would allow it. Mode shapes at the outputs
    come with a frame configuration, or, for a simulation given as FRFs, from a driving point: the
    response measured at the hammer's point in its direction scales the residues to mass-normalised
    shapes (:func:`analysis.diagnosis.entry.driving_point_shapes`)."""
    if "output_shapes" not in missing:
        return f"needs {', '.join(missing)} in the simulation"
    refs = list(ctx.measured.references)
    what = ("the sensors' mass" if name == "mass_loading" else name)
    if "frf_correction" in ctx.base.meta:
        return (f"{what} not tried: the simulation is given as FRFs and the test has no driving point, so its "
                "mode shapes cannot be scaled to mass-normalised ones; measure the driving point "
                f"{' or '.join(refs)} (an accelerometer at the hammer's point, in its direction) and give the "
                "simulated FRF there too, or simulate from a frame configuration (TOML)")
    return (f"{what} not tried: the simulation carries no mass-normalised mode shapes at the outputs "
            "(model.meta['output_shapes']); simulate from a frame configuration (TOML), or give the simulation "
            f"as FRFs with the driving point {' or '.join(refs)} measured")


def _frf_on_top(ctx: FitContext, physical: PhysicalSimulation, outcome: Any, names: Sequence[str],
                min_gain_db: float, noise_db: float, rule: DecisionRule, trace: list) -> tuple[list, FRFSet] | None:
    """A physical cause that explains the modes but leaves the FRFs above the noise, completed by one
    FRF-level effect (a damping change, a sensor): the catalogue fitted on top of the physical cause's
    model with the same cross-validation and rule (held-out gain at least ``min_gain_db``) on the lines up
    to where the physical cause's modes were compared with the measured ones
    (:func:`analysis.diagnosis.physical_verdict.compared_band_hz`); named as a pair when the pair is
    adequate on every line (the FRF error within ``rule.none_margin_db`` of the noise or
    ``rule.adequate_fraction`` of its excess removed). None otherwise. The rules applied go to ``trace``."""
    from .physical_verdict import compared_band_hz

    first = outcome.on_top
    fit = first["_fit"]
    base = physical.model(fit.cause, fit.params)
    m, w = ctx.measured, ctx.weights
    # fitted where the physical cause's modes were compared with the measured ones, judged on every line
    hi = min(compared_band_hz(outcome.doc, base.freq_hz), float(m.freq_hz[-1]))
    lines = m.freq_hz <= hi
    ctx2 = FitContext(measured=m.band(float(m.freq_hz[0]), hi), base=base, weights=w[..., lines],
                      sim=first["_extended"].band(float(m.freq_hz[0]), hi), prior=ctx.prior)
    more, _ = _stage(ctx2, names, rule, trace, min_gain_db)
    sig = [c for c in more if c["significant"] and c["gain_db"] >= min_gain_db]
    if not sig:
        trace.append(step("on_top", first["effect"], {"min_gain_db": min_gain_db}, "no FRF-level effect significant"))
        return None
    nxt = sig[0]
    nxt["_extended"] = predict(base, m.freq_hz, m.quantity, ctx.effects(applied(nxt)),
                               outputs=m.outputs, references=m.references)
    after = typical_error_db(m, nxt["_extended"].H, w)
    before = outcome.error_before_db
    excess = 10 ** (before / 10) - 10 ** (noise_db / 10)
    removed = (10 ** (before / 10) - 10 ** (after / 10)) / excess if excess > 0 else 0.0
    adequate = rule.explained(after, noise_db) or removed >= rule.adequate_fraction
    trace.append(step("on_top", f"{first['effect']}+{nxt['effect']}",
                      {"error_after_db": after, "noise_db": noise_db, "none_margin_db": rule.none_margin_db,
                       "removed": removed, "adequate_fraction": rule.adequate_fraction},
                      "named as a pair" if adequate else "not adequate"))
    if not adequate:
        return None
    combined = [stage_entry(first), stage_entry(nxt, after)]
    return combined, nxt["_extended"]


def _other_structure(comparison: dict) -> str:
    """A reason when the measured peaks do not pair with the simulation's (fewer than half of at least
    three pair by frequency and MAC, :func:`analysis.diagnosis.compare.pair_modes`), else ""."""
    modes = comparison.get("modes") or {}
    pairs, only = modes.get("pairs", []), modes.get("only_measured", [])
    n = len(pairs) + len(only)
    if n >= 3 and 2 * len(pairs) < n:
        return (f"not the same structure: only {len(pairs)} of the {n} measured resonance peaks pair with the "
                "simulation's by frequency (within 15 %) and MAC (>= 0.5); check that the measured points are the "
                "simulation's points and that both describe the same structure")
    return ""


def _below_model_form(causes: list, trace: list) -> None:
    """With the FE model as simulation, a frequency scaling smaller than the model form's accuracy
    (:data:`analysis.diagnosis.physical.FREQ_FLOOR`) is not evidence of a change: not significant."""
    from .physical import FREQ_FLOOR

    for c in causes:
        if c["effect"] == "stiffness_shift" and c["significant"] and abs(float(c["parameters"]["factor"]) - 1) < FREQ_FLOOR:
            c["significant"] = False
            c["evidence"] += f"; a frequency change below the model's accuracy ({100 * FREQ_FLOOR:.1f} %)"
            trace.append(step("below_model_form", c["effect"], {"factor": c["parameters"]["factor"],
                                                                "freq_floor": FREQ_FLOOR}, "vetoed: not significant"))


def known_processing(measured: FRFSet) -> tuple:
    """What the measurement's own processing does to the structure's FRFs, as effects applied to the
    simulation before it is compared: the finite record (``measured.record_s``, ``measured.pretrigger_s``
    as a recording stores them) and the exponential window recorded with the FRFs."""
    out: list = []
    record, pre = measured.record_s, measured.pretrigger_s or 0.0
    if isinstance(record, (int, float)) and record > 0 and isinstance(pre, (int, float)):
        out.append({"effect": "record_length", "record_s": float(record), "pretrigger_s": float(pre)})
    tau = measured.exp_window_tau_s
    if tau:
        out.append({"effect": "exponential_window", "exp_window_tau_s": float(tau)})
    return tuple(out)


@limits_blas_threads
def diagnose_frfs(
    measured: FRFSet,
    base: ModalModel,
    *,
    effects: Sequence[str] | None = None,
    physical: PhysicalSimulation | None = None,
    measured_modes: MeasuredModes | None = None,
    extra_noise_db: dict | None = None,
    rule: DecisionRule = DEFAULT_RULE,
) -> Diagnosis:
    """Compare ``measured`` with the simulation ``base`` (a :class:`ModalModel` at the measured points,
    any quantity), fit every catalogue effect with cross-validation and give the verdict (module
    docstring). Neither input is modified. The simulation is seen through the measurement's own
    processing (:func:`known_processing`) before anything is compared.

    With ``physical`` (the simulation's FE model, :mod:`analysis.diagnosis.physical`), the measured
    modes (``measured_modes``, else the automatic fit of ``measured``) are first held against it: when
    they do not pair, the verdict is ``unexplained`` (not the same structure); when their frequencies
    differ beyond the model's accuracy, the physical causes are fitted and a cause is named only if it
    is significant (held-out gain) and adequate (brings the FRF error near the noise); otherwise the
    FRF-level catalogue is tried as without ``physical``.

    ``extra_noise_db``: further noise estimates (dB, same scale), e.g. ``{"hits": ...}`` from the scatter
    of a recording's hits (:func:`analysis.diagnosis.hit_noise.hit_scatter_noise_db`); the largest counts.

    ``rule``: the decision rule (:class:`analysis.diagnosis.rule.DecisionRule`), the same for every stage;
    the rules applied are listed in ``Diagnosis.trace`` in the order they decided.

    Further stages: while the extended model still leaves the typical error more than
    ``rule.none_margin_db`` above the noise, the remaining effects are fitted on top of the accepted ones
    (up to ``rule.max_stages`` effects in all); each accepted effect is listed in ``Diagnosis.combined``
    with its own held-out gain. The verdict and ``Diagnosis.named`` are the first stage's (the largest
    single cause). Two causes are named (verdict ``"combined"``) by the physical stage: two physical
    causes, or a physical cause that explains the modes completed by an FRF-level effect.
    """
    names = list(EFFECTS) if effects is None else list(effects)
    physical_names = [c.name for c in physical.causes()] if physical is not None else []
    for n in names:
        if n not in EFFECTS and n not in physical_names:
            raise EffectError(f"unknown effect {n!r}; the catalogue has {', '.join([*EFFECTS, *physical_names])}")
    names = [n for n in names if n in EFFECTS]          # the physical causes among them go to the physical stage
    if base.residues.shape[:2] != measured.H.shape[:2]:
        raise ValueError(f"the simulation has {base.residues.shape[:2]} (outputs, references) but the "
                         f"measurement {measured.H.shape[:2]}; select the common points first")
    if not np.all(np.isfinite(measured.H)):
        raise ValueError("the measured FRFs hold NaN/inf lines; restrict the band to finite lines")
    w = line_weights(measured)
    prior = known_processing(measured)
    sim = predict(base, measured.freq_hz, measured.quantity, prior, outputs=measured.outputs,
                  references=measured.references)
    ctx = FitContext(measured=measured, base=base, weights=w, sim=sim, prior=prior)
    noise = noise_level(measured, w)
    noise.update({k: float(v) for k, v in (extra_noise_db or {}).items() if v is not None})
    noise_db = effective_noise_db(noise)   # with coherence (or the hits' scatter), the largest estimate
    if physical is not None and hasattr(physical, "refined_model"):
        # the simulation's own discretisation error: what a finer mesh alone removes of the typical error
        # is not evidence of a physical change; the level is raised by it ("model_form")
        fine = predict(physical.refined_model(), measured.freq_hz, measured.quantity, prior).H
        allowance = typical_error_db(measured, sim.H, w) - typical_error_db(measured, fine, w)
        if allowance > 0:
            noise["model_form"] = noise_db + allowance
            noise_db = noise["model_form"]
    comparison = compare(measured, sim, w)
    trace: list = []
    common: dict[str, Any] = dict(noise_db=noise, comparison=comparison, measured=measured, simulated=sim,
                                  trace=trace, rule=rule)
    phys_doc: dict = {}
    partial_reason = ""
    if physical is None:
        other = _other_structure(comparison)
        modes = comparison.get("modes") or {}
        trace.append(step("same_structure", None, {"paired_peaks": len(modes.get("pairs", [])),
                                                   "measured_peaks": len(modes.get("pairs", []))
                                                   + len(modes.get("only_measured", []))},
                          "unexplained: not the same structure" if other else "same structure"))
        if other:
            return Diagnosis(verdict="unexplained", causes=[], error_before_db=comparison["error_db"],
                             error_after_db=comparison["error_db"], unexplained=[], extended=sim, reason=other,
                             **common)
    if physical is not None:
        from .physical_verdict import physical_verdict

        outcome = physical_verdict(measured, physical, prior, w, noise_db, measured_modes, causes=effects, rule=rule)
        phys_doc = outcome.doc
        trace.extend(outcome.trace)
        if outcome.on_top is not None:
            # on top of a cause already named alone, a second must gain as much as a physical cause must
            # (not missing_mode: with an FE model a mode the model lacks shows in the pairing; on top of a
            # physical cause an extra mode only patches a mode the cause misplaces)
            top = _frf_on_top(ctx, physical, outcome, [n for n in names if EFFECTS[n].on_top_of_physical],
                              rule.physical_min_gain_db if outcome.named else rule.min_gain_db, noise_db, rule, trace)
            if top is not None:
                combined, ext = top
                return Diagnosis(verdict="combined", causes=outcome.causes, error_before_db=outcome.error_before_db,
                                 error_after_db=combined[-1]["error_after_db"],
                                 unexplained=[b for b in band_errors(measured, ext.H, w)
                                              if not rule.explained(b["error_db"], noise_db)],
                                 extended=ext, combined=combined, physical=phys_doc,
                                 named=[named(c) for c in combined],
                                 **common)
        if outcome.decided and outcome.extended is not None:
            return Diagnosis(unexplained=[b for b in band_errors(measured, outcome.extended.H, w)
                                          if not rule.explained(b["error_db"], noise_db)],
                             physical=phys_doc, **outcome.verdict_fields(), **common)
        partial_reason = outcome.reason
        # the physical cause of that name covers it
        names = [n for n in names if EFFECTS[n].covered_by_physical != "always"]
        if outcome.causes:
            # fitted, none named: listed with the physical stage, on its own (mode-level) gain scale, and
            # their FRF-level versions are not tried again
            phys_doc = {**phys_doc, "causes": outcome.causes}
            names = [n for n in names if not EFFECTS[n].covered_by_physical]
    causes, skipped = _stage(ctx, names, rule, trace)
    _mass_or_stiffness(causes, ctx, noise_db, rule, trace)
    if physical is not None:
        _below_model_form(causes, trace)
    error_before = causes[0]["error_before_db"] if causes else comparison["error_db"]
    sig = [c for c in causes if c["significant"]]
    combined = []
    if sig:
        best = sig[0]
        verdict, extended, after_db = best["effect"], best["_extended"], best["error_after_db"]
        accepted = [*prior, applied(best)]
        combined.append(stage_entry(best))
        trace.append(step("largest_gain", best["effect"], {"gain_db": best["gain_db"], "significant": len(sig)},
                          f"verdict {verdict}"))
        left = [n for n in names if n != best["effect"]]
        while len(combined) < rule.max_stages and left:
            typical = typical_error_db(measured, extended.H, w)
            if rule.explained(typical, noise_db):
                trace.append(step("further_stage", None, {"error_db": typical, "noise_db": noise_db,
                                                          "none_margin_db": rule.none_margin_db},
                                  "explained: no further stage"))
                break
            ctx2 = FitContext(measured=measured, base=base, weights=w, sim=extended, prior=tuple(accepted))
            more, _ = _stage(ctx2, left, rule, trace)
            more = [c for c in more if c["significant"]]
            trace.append(step("further_stage", more[0]["effect"] if more else None,
                              {"error_db": typical, "noise_db": noise_db, "none_margin_db": rule.none_margin_db,
                               "stage": len(combined) + 1},
                              "accepted on top (listed, not named)" if more else "no further effect significant"))
            if not more:
                break
            nxt = more[0]
            accepted.append(applied(nxt))
            extended, after_db = nxt["_extended"], nxt["error_after_db"]
            combined.append(stage_entry(nxt))
            left.remove(nxt["effect"])
    else:
        extended, after_db = sim, error_before
        typical = typical_error_db(measured, sim.H, w)
        verdict = "none" if rule.explained(typical, noise_db) else "unexplained"
        trace.append(step("none_margin", None, {"error_db": typical, "noise_db": noise_db,
                                                "none_margin_db": rule.none_margin_db}, f"verdict {verdict}"))
    unexplained = [b for b in band_errors(measured, extended.H, w) if not rule.explained(b["error_db"], noise_db)]
    for c in causes:
        c.pop("_extended")
        c.pop("_held_out_after", None)
    reason = ("" if verdict != "unexplained" else partial_reason or
              "no effect of the catalogue gains significantly on held-out lines, and the error stays "
              f"{typical_error_db(measured, sim.H, w) - noise_db:.1f} dB above the noise")
    if verdict != "none" and "mass_loading" in skipped and "not tried" in skipped["mass_loading"]:
        # a verdict reached without the sensors' mass says so, and which measurement would allow it
        reason = f"{reason}; " if reason else ""
        reason += skipped["mass_loading"]
    # the FRF-level further stages are listed (``combined``) but not named: only the first is
    return Diagnosis(verdict=verdict, causes=causes, error_before_db=error_before, error_after_db=after_db,
                     unexplained=unexplained, extended=extended, skipped=skipped, combined=combined,
                     reason=reason, physical=phys_doc, named=[named(c) for c in combined[:1]], **common)
