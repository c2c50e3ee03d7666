"""The decision rule of the diagnosis, written once as data: :class:`DecisionRule`, its helpers and its trace.

Every threshold that decides a verdict is a field of one frozen :class:`DecisionRule`; the one object
given to :func:`analysis.diagnosis.diagnose` (``rule=``) reaches every stage that uses a field: the
FRF-level catalogue (:mod:`.verdict`), the physical causes (:mod:`.physical`, :mod:`.physical_verdict`),
the mode-by-mode vote (:mod:`.mode_vote`) and the time-data stage (:mod:`.timedata_gain`). Two stages
that need different values have two named fields (``min_gain_db`` for the FRF lines, where the noise is
known line by line; ``physical_min_gain_db`` for the modes, a handful of numbers).

The helpers are the rule's arithmetic, one each: :func:`db` (a power in decibels), :func:`gain_db` (a
held-out gain), :func:`paired_z` (the paired z-score of held-out errors) and
:meth:`DecisionRule.significant` (the significance rule of a held-out gain). The held-out fold loop over
the lines is :func:`analysis.diagnosis.compare.held_out_errors`.

What decided a verdict is written as it happens: each rule applied appends a :func:`step`
``{"rule", "cause", "values", "outcome"}`` to the result's ``trace`` (:attr:`Diagnosis.trace`), in the
order the rules were applied. Rule names are the :data:`RULES` keys.

Not fields: the accuracy of the simulation's model form (:data:`analysis.diagnosis.physical.FREQ_FLOOR`,
used in every mode residual; a property of the FE model, not of the decision) and the searches' sizes
(grid points, starts, options screened), which decide how hard a fit looks, not what its result means.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

__all__ = ["DecisionRule", "DEFAULT_RULE", "RULES", "db", "gain_db", "paired_z", "step", "why_lines"]


@dataclass(frozen=True)
class DecisionRule:
    """The thresholds of the diagnosis (``docs/diagnosis.md``), each with its unit and why.

    FRF-level catalogue and time-data effects (held-out gain over alternating blocks of lines):

    z_min : paired z-score (dimensionless) of the held-out errors an effect must reach (with
        ``min_gain_db``): 3 standard errors, a chance of about 1e-3 under noise alone.
    min_gain_db : held-out gain (dB) an FRF-level or time-data effect must reach: 0.5 dB is an 11 %
        smaller held-out error; noise alone gives a few hundredths of a dB.
    strong_gain_db : held-out gain (dB) that is significant whatever its z: 3 dB halves the held-out
        error (an effect acting on a few lines, one missing mode, has heavy-tailed differences and a
        modest z although its gain is tens of dB).
    none_margin_db : an FRF error (dB, typical over lines) within this of the noise level is explained:
        the verdict ``none`` without a significant effect, a named cause ``adequate``, no further stage
        tried, no band listed as unexplained. 3 dB: twice the noise power.
    max_stages : FRF-level effects accepted one on top of another (count), the first named.
    resonator_over_mass_db : a local resonator and a mass at a sensor both significant: the resonator
        (whose stiff limit is that mass) counts only when it gains this much more (dB; 3 dB: the error
        the mass leaves halved).
    separation_z : a mode's region separates two causes' predictions when their difference is this many
        standard deviations of what the noise adds to it (dimensionless, :mod:`.mode_vote`).

    Physical causes (held-out chi2 of the measured modes, leave one mode out):

    physical_min_gain_db : held-out gain (dB, chi2 of the unchanged simulation over the cause's) a
        physical cause must reach to be significant; also what a refinement (one parameter more), a
        second cause over the first alone, and an FRF-level effect on top of a named physical cause must
        earn. 3 dB: the modes' mismatch halved (a handful of modes, each with its own uncertainty).
    adequate_fraction : a significant cause is adequate when its FRF error is within ``none_margin_db``
        of the noise or it removes at least this fraction of the FRF error's excess over the noise (in
        power; 0.8).
    discrepancy_chi2 : mean chi2 per paired mode (dimensionless) of the unchanged simulation above which
        the modes differ (about 2 standard deviations per mode); a cause's held-out modes must come back
        within it to be adequate.
    quiet_chi2 : chi2 (summed over the modes) a cause must remove when neither the modes nor the FRFs
        differ, and a second cause over the first: one mode predicted one standard deviation better (the
        simulation's own discretisation leaves about 0.3 in all modes together).
    leaves_chi2 : held-out chi2 per counted mode within which a cause leaves the modes within their
        uncertainty (about one standard deviation per mode): no second physical change is searched for,
        and two changes of one member must reach it.
    on_top_margin_db : a named physical cause whose FRF error stays more than this (dB) above the noise is
        tried with an FRF-level effect on top.
    range_chi2 : chi2 (summed over the modes) above the least within which the values of a named cause's
        parameter fit the measured modes alike (the profile over it, its refinements refitted: a block's
        mass with its rotary inertia, :mod:`.param_range`): 1, one standard deviation of one parameter (the
        profile likelihood's 68 % interval). It names a range; it decides nothing.

    Hits before the comparison (:mod:`.stray_hits`):

    stray_excess_db : a hit whose FRF stands this far (dB) beyond its point's spread from the consensus hit
        measured another FRF (struck elsewhere) and is left out: 6 dB is four times the spread; clean hits
        stand within about 1.3 dB, hits struck on a neighbouring node 10-20 dB out.
    stray_min_hits : hits (count) a point needs before one can be told apart from the others (two that
        disagree have no majority).
    """

    z_min: float = 3.0
    min_gain_db: float = 0.5
    strong_gain_db: float = 3.0
    none_margin_db: float = 3.0
    max_stages: int = 3
    resonator_over_mass_db: float = 3.0
    separation_z: float = 3.0
    physical_min_gain_db: float = 3.0
    adequate_fraction: float = 0.8
    discrepancy_chi2: float = 4.0
    quiet_chi2: float = 1.0
    leaves_chi2: float = 1.0
    on_top_margin_db: float = 1.0
    range_chi2: float = 1.0
    stray_excess_db: float = 6.0
    stray_min_hits: int = 3

    def __post_init__(self) -> None:
        for k, v in asdict(self).items():
            if not np.isfinite(float(v)) or float(v) < 0:
                raise ValueError(f"DecisionRule.{k} = {v!r}: give a finite number >= 0")
        if self.max_stages < 1:
            raise ValueError(f"DecisionRule.max_stages = {self.max_stages!r}: give at least 1")

    def significant(self, gain: float, z: float) -> bool:
        """The significance rule of a held-out gain on lines (FRF-level and time-data effects):
        ``gain >= min_gain_db`` and (``z >= z_min`` or ``gain >= strong_gain_db``); ``gain`` in dB,
        ``z`` the paired z-score (:func:`paired_z`)."""
        return bool(gain >= self.min_gain_db and (z >= self.z_min or gain >= self.strong_gain_db))

    @property
    def physical_min_gain_factor(self) -> float:
        """The factor (dimensionless, at most 1) a held-out chi2 must come down by to gain ``physical_min_gain_db``:
        ``10^(-physical_min_gain_db / 10)`` (a chi2 is a power, :func:`db`)."""
        return float(10 ** (-self.physical_min_gain_db / 10))

    def explained(self, error_db: float, noise_db: float) -> bool:
        """An FRF error (dB) within ``none_margin_db`` of the noise level (dB)."""
        return bool(error_db - noise_db <= self.none_margin_db)

    def as_dict(self) -> dict:
        """The fields as a JSON-able dict."""
        return asdict(self)


#: The rule with its documented defaults.
DEFAULT_RULE = DecisionRule()

#: The named rules a trace step may cite, with what each decides.
RULES: dict[str, str] = {
    "same_structure": "the measured modes pair with the simulation's (else unexplained: another structure)",
    "discrepancy": "the modes (mean chi2 per mode) or the FRFs (error over the noise) differ from the simulation",
    "physical_significance": "a physical cause's held-out gain on the modes reaches physical_min_gain_db, "
                             "no parameter at the edge of its range",
    "adequacy": "a significant physical cause leaves the held-out modes within discrepancy_chi2 and the FRF error "
                "within none_margin_db of the noise or removes adequate_fraction of its excess",
    "quiet": "neither the modes nor the FRFs differ: a cause must remove quiet_chi2 of the modes' chi2",
    "second_cause": "a second physical cause gains physical_min_gain_db over the first alone and removes "
                    "quiet_chi2, both named when the pair is significant and adequate",
    "largest_gain": "of the causes named, the one with the largest held-out gain gives the verdict",
    "on_top": "an FRF-level effect on top of a physical cause, named with it when the pair is adequate",
    "significance": "an effect's held-out gain reaches min_gain_db and its z reaches z_min, or the gain "
                    "strong_gain_db",
    "range_edge": "veto: a fitted parameter at the edge of the effect's physical range",
    "hum_on_a_mode": "veto: mains hum whose held-out gain one harmonic carries alone (the rest not significant), "
                     "that harmonic inside a mode's half-power band, and not significant fitted again off that "
                     "harmonic's reach and the mode's band",
    "resonator_beyond_mass": "veto: a resonator gains less than resonator_over_mass_db more than a mass at a sensor",
    "mass_or_stiffness": "veto: the modes that separate a mass at every sensor from a stiffness change favour "
                         "the other",
    "below_model_form": "veto: a frequency scaling below the model form's accuracy",
    "further_stage": "a further effect on top of the accepted ones while the error stays above none_margin_db",
    "none_margin": "no effect significant: none when the error is within none_margin_db of the noise, else "
                   "unexplained",
    "time_data": "an unexplained verdict becomes the time-data cause that counts",
    "joint_nonlinearity": "a nonlinear joint named by the hits' force levels replaces the verdict",
    "stray_hits": "a hit standing stray_excess_db beyond its point's spread is left out before the comparison "
                  "(fewer than half of the point's hits, at least stray_min_hits hits)",
    "levels": "measurements at several drive levels: modes moving beyond their uncertainty between levels "
              "name joint_nonlinearity in place of the verdict",
}


def db(power: float) -> float:
    """A power (or a mean squared error) in decibels: ``10 log10(power)``, floored at 1e-30 (-300 dB)."""
    return float(10 * np.log10(max(float(power), 1e-30)))


def gain_db(before: Any, after: Any) -> float:
    """Held-out gain (dB) of ``after`` over ``before`` (errors per line, per mode, ...: summed)."""
    return db(float(np.sum(before))) - db(float(np.sum(after)))


def paired_z(before: Any, after: Any) -> float:
    """Paired z-score of held-out errors: ``mean(d) / (std(d) / sqrt(N))`` of ``d = before - after``
    (0 when the differences do not scatter or there is one)."""
    d = np.asarray(before, float) - np.asarray(after, float)
    sd = float(np.std(d, ddof=1)) if d.size > 1 else 0.0
    return float(np.mean(d) / (sd / np.sqrt(d.size))) if sd > 0 else 0.0


def held_out_db(before: Any, after: Any) -> tuple[float, float, float]:
    """Held-out errors ``before`` and ``after`` an effect (per line, |H|^2 units) as a verdict reports them: their
    means in dB (before, after; the gain is their difference) and their paired z-score (:func:`paired_z`)."""
    return db(float(np.mean(before))), db(float(np.mean(after))), paired_z(before, after)


def step(rule: str, cause: str | None, values: Mapping, outcome: str) -> dict:
    """One step of a trace: the named ``rule`` (a :data:`RULES` key) applied to ``cause`` (None: the
    verdict as a whole) with the ``values`` it compared (numbers, names) and its ``outcome``."""
    if rule not in RULES:
        raise KeyError(f"unknown rule {rule!r}; the rules are {', '.join(RULES)}")
    clean = {k: (float(v) if isinstance(v, (float, np.floating)) else int(v) if isinstance(v, (np.integer,))
                 else bool(v) if isinstance(v, np.bool_) else v) for k, v in values.items()}
    return {"rule": rule, "cause": cause, "values": clean, "outcome": outcome}


def _shown(v: Any) -> str:
    """A trace value in words: numbers with 3 significant digits, lists joined."""
    if isinstance(v, bool) or v is None:
        return str(v).lower()
    if isinstance(v, float):
        return f"{v:.3g}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_shown(x) for x in v) + "]"
    return str(v)


def _line(s: Mapping) -> str:
    who = f" {s['cause']}" if s.get("cause") else ""
    values = ", ".join(f"{k} {_shown(v)}" for k, v in (s.get("values") or {}).items())
    return f"{s['rule']}{who}: {s['outcome']}" + (f" ({values})" if values else "")


def why_lines(trace: Sequence[Mapping]) -> list[str]:
    """"Why this verdict": one line per step of a ``trace`` (:attr:`Diagnosis.trace`, or its JSON form), in
    its order; a run of effects found not significant is one line (each with its held-out gain)."""
    out: list[str] = []
    run: list[str] = []
    for s in trace:
        if s["rule"] in ("significance", "physical_significance") and s["outcome"] == "not significant":
            gain = (s.get("values") or {}).get("gain_db")
            run.append(f"{s['cause']} {gain:+.2f} dB" if isinstance(gain, (int, float)) else str(s["cause"]))
            continue
        if run:
            out.append(f"not significant: {', '.join(run)}")
            run = []
        out.append(_line(s))
    if run:
        out.append(f"not significant: {', '.join(run)}")
    return out
