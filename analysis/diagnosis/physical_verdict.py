"""The verdict of the physical causes (:mod:`analysis.diagnosis.physical`) for :func:`diagnose`.

Steps, each one able to decide:

1. Measured modes: the automatic LSFD fit of the measurement (or the modes given).
2. Same structure? Fewer than half of the measured modes pair with the simulation's by frequency
   and MAC: ``unexplained``, with that reason, and nothing is fitted. Measured modes that pair with
   no simulated mode (``unpaired_measured_hz``) or stand for a close pair the fit did not resolve
   (``merged_measured_hz``, :func:`merged_pairs`) are reported and left out of the fit.
3. Discrepancy? Mean chi2 per mode of the nominal simulation (frequency errors in units of their
   uncertainty with the model-form floor, and shape mismatch) at most ``DISCREPANCY_CHI2`` and the
   typical FRF error within the margin of the noise: nothing to explain here; the FRF-level catalogue
   is tried (not decided here).
4. Causes: every physical cause fitted, nested variants and choices selected by leave-one-mode-out
   chi2. Named: the cause with the largest held-out gain among those that are significant
   (gain >= ``MIN_GAIN_DB``, no parameter at the edge of its range) and adequate (the held-out modes
   agree, mean chi2 per mode <= ``DISCREPANCY_CHI2``, and the extended simulation's FRFs, through the
   measurement's processing, leave the typical error within ``ADEQUATE_MARGIN_DB`` of the noise or
   remove ``ADEQUATE_FRACTION`` of the excess error in power). None named: when the modes differ,
   ``unexplained`` with the best partial causes (no FRF-level effect moves natural frequencies);
   when only the FRFs differ, not decided here: the FRF-level catalogue is tried, and the physical
   causes are listed in ``Diagnosis.physical["causes"]``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional, Sequence

import numpy as np

from ..frf import FRFSet
from .compare import typical_error_db
from .effects import predict
from .physical import (ADEQUATE_FRACTION, ADEQUATE_MARGIN_DB, DISCREPANCY_CHI2, MIN_GAIN_DB, MeasuredModes,
                       PhysicalSimulation, gain_db, pair, paired_well, physical_causes, residuals, same_structure,
                       shown_params, z_score)

__all__ = ["PhysicalOutcome", "physical_verdict", "measure_modes"]

#: Candidate modes are computed up to this multiple of the highest measured mode used (modes that may pair).
FMAX_FACTOR = 1.5


@dataclass
class PhysicalOutcome:
    """decided: the physical stage gives the verdict (else the FRF catalogue is tried). verdict,
    causes (dicts as :class:`Diagnosis` lists them), extended FRFs, errors (dB), reason, doc (JSON)."""

    decided: bool
    verdict: str = "none"
    causes: list = field(default_factory=list)
    extended: Optional[FRFSet] = None
    error_before_db: float = float("nan")
    error_after_db: float = float("nan")
    combined: list = field(default_factory=list)
    reason: str = ""
    doc: dict = field(default_factory=dict)


def measure_modes(measured: FRFSet) -> MeasuredModes:
    """The measured modes from the automatic fit (:func:`analysis.pipeline.fit_auto`)."""
    from ..pipeline import fit_auto

    res = fit_auto(measured)
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
                     noise_db: float, none_margin_db: float,
                     measured_modes: Optional[MeasuredModes] = None,
                     causes: Optional[Sequence[str]] = None) -> PhysicalOutcome:
    """Steps 1-4 of the module docstring; ``causes`` limits the physical causes tried (None: all)."""
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

    def frf(cause: Optional[str], params: dict) -> FRFSet:
        return predict(sim.model(cause, params), measured.freq_hz, measured.quantity, prior,
                       outputs=measured.outputs, references=measured.references)

    nominal = frf(None, {})
    before_db = typical_error_db(measured, nominal.H, weights)
    good = paired_well(mm, f0, P0)
    same, why = same_structure(mm, f0, P0, good)
    if not same:
        return PhysicalOutcome(decided=True, verdict="unexplained", extended=nominal, error_before_db=before_db,
                               error_after_db=before_db, reason=why, doc={**doc, "same_structure": False})
    # a measured mode with no counterpart at all (a local mode of something not modelled, a spurious
    # peak) is reported, not fitted: no change of the catalogue could bring a mode from nowhere
    doc["unpaired_measured_hz"] = mm.freq_hz[~good].tolist()
    merged = merged_pairs(mm, f0, P0)
    doc["merged_measured_hz"] = mm.freq_hz[merged & good].tolist()
    mm = mm.subset(good & ~merged)
    if mm.freq_hz.size < 3:
        return PhysicalOutcome(decided=False, doc={**doc, "skipped": "fewer than 3 measured modes pair with the simulation's"})
    base = np.sum(residuals(mm, f0, P0) ** 2, axis=1)
    doc["chi2_per_mode"] = float(base.mean())
    modes_differ = bool(base.mean() > DISCREPANCY_CHI2)
    frfs_differ = bool(before_db - noise_db > none_margin_db)
    doc["discrepancy"] = {"modes": modes_differ, "frfs": frfs_differ}
    if not (modes_differ or frfs_differ):
        return PhysicalOutcome(decided=False, doc=doc)
    specs = {c.name: c for c in sim.causes()}
    fits = physical_causes(sim, mm, fmax, causes)
    if not fits:
        return PhysicalOutcome(decided=False, doc=doc)
    excess = _power(before_db) - _power(noise_db)
    found: list[dict[str, Any]] = []
    for fit in fits:
        spec = specs[fit.cause]
        ext = frf(fit.cause, fit.params)
        after_db = typical_error_db(measured, ext.H, weights)
        removed = (_power(before_db) - _power(after_db)) / excess if excess > 0 else 0.0
        g = gain_db(base, fit.cv_per_mode)
        significant = bool(g >= MIN_GAIN_DB and not fit.at_edge)
        adequate = bool((after_db - noise_db <= ADEQUATE_MARGIN_DB or removed >= ADEQUATE_FRACTION)
                        and fit.chi2_cv / base.size <= DISCREPANCY_CHI2)
        params = shown_params(spec, fit.params)
        shown = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in params.items())
        edge = f"; at the edge of its range: {', '.join(fit.at_edge)}" if fit.at_edge else ""
        evidence = (f"{fit.cause} ({shown}): held-out mode error {10 * np.log10(max(base.sum(), 1e-30)):.1f} -> "
                    f"{10 * np.log10(max(fit.chi2_cv, 1e-30)):.1f} dB (leave one mode out), FRF error "
                    f"{before_db:.1f} -> {after_db:.1f} dB (noise {noise_db:.1f} dB, {100 * removed:.0f} % of the "
                    f"excess removed){edge}")
        found.append({"effect": fit.cause, "kind": "physical", "parameters": params, "gain_db": g,
                       "error_before_db": before_db, "error_after_db": after_db, "z": z_score(base, fit.cv_per_mode),
                       "significant": significant, "adequate": adequate, "description": spec.description,
                       "evidence": evidence, "_extended": ext, "_removed": removed})
    found.sort(key=lambda c: c["gain_db"], reverse=True)
    named = [c for c in found if c["significant"] and c["adequate"]]
    # frequencies that differ cannot be explained by an FRF-level effect: then unexplained is decided here
    out = PhysicalOutcome(decided=bool(named) or modes_differ, error_before_db=before_db, doc=doc)
    if named:
        best = named[0]
        out.verdict, out.extended, out.error_after_db = best["effect"], best["_extended"], best["error_after_db"]
        out.combined = [{"effect": best["effect"], "parameters": best["parameters"], "gain_db": best["gain_db"],
                         "error_after_db": best["error_after_db"]}]
    else:
        out.verdict, out.extended, out.error_after_db = "unexplained", nominal, before_db
        partial = ", ".join(f"{c['effect']} ({c['gain_db']:+.1f} dB held out, {100 * c['_removed']:.0f} % of the excess "
                            f"FRF error removed)" for c in found[:3])
        differ = (f"the measured modes differ from the simulation's (mean chi2 {base.mean():.1f} per mode)" if modes_differ
                  else f"the FRFs differ from the simulation's by {before_db - noise_db:.1f} dB above the noise")
        out.reason = f"{differ} but no physical cause is both significant and adequate; best partial causes: {partial}"
    for c in found:
        c.pop("_extended")
        c.pop("_removed")
    out.causes = found
    return out
