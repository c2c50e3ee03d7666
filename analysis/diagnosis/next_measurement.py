"""The next measurement: the point whose FRFs would best tell two candidate causes apart.

Two candidates are *not separated* when the data cannot choose between them: two options of one
cause (an added mass at two nodes the test's sensors see alike) whose chi2 on all modes differ by less
than ``SEPARATED_CHI2``, or two causes whose held-out mode errors differ by less than that; for a named
pair, two options of its choice with the other cause applied (:func:`pair_rivals`). Then every
node and direction of the frame (:meth:`points` of the FE model, not only today's test plan) is tried
as a new hammer point: the FRFs from it to the measured outputs are predicted by both candidates
(through the measurement's processing), and the point where they differ most against the noise is
proposed::

    separation_db = 10 log10( mean_{o,k} |H_A - H_B|^2 / (|H_A|^2 + floor^2) ) - noise_db

(the weighted relative error of :mod:`analysis.diagnosis.compare` between the two predictions, above
the measured noise level). A hammer point gives the FRFs from it to every sensor; by reciprocity this is
also what a sensor there would see from the present hammer points.

The diagnosis decides between the two on the measured modes (their chi2), not on the FRFs: an FRF
difference carried by a mode the fit does not resolve (a weak mode, one the new point barely excites)
separates nothing once measured. So when the measured modes are given, the points are ranked by what
the decision will see: the chi2 of candidate ``b`` against ``a``'s modes taken as the measurement, on the
modes measured today (``a``'s modes paired with them, the measured frequency uncertainties) and their
shapes at the present hammer points and the new one (:func:`analysis.diagnosis.physical.residuals`)::

    separation_chi2(p) = sum_k r_k(b | a at refs + p)^2

the point with the largest is proposed (its FRF separation_db is reported with it); the FRF measure ranks
the points when no point changes that chi2 (or the simulation gives no modes).
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..frf import FRFSet
from .effects import predict
from .physical import MeasuredModes, pair, residuals

__all__ = ["propose", "SEPARATED_CHI2", "rivals", "pair_rivals"]

#: Two candidates whose (held-out) chi2 differ by less than this are not separated by the data
#: (chi2 is a sum of squared residuals in units of their uncertainty: 4 is two standard deviations).
SEPARATED_CHI2 = 4.0
DIRECTIONS = ("X", "Y", "Z")


def rivals(found: Sequence[dict]) -> tuple[tuple[str, dict], tuple[str, dict], str] | None:
    """The best candidate and its closest rival when the data do not separate them, with the reason;
    None when they are separated. ``found``: the physical causes as the verdict ranks them, each with
    its fit (``_fit``: ``cause``, ``params``, ``chi2``, ``chi2_cv``, ``ranked``)."""
    sig = [c for c in found if c["significant"]]
    if not sig:
        return None
    best = sig[0]["_fit"]
    options = [r for r in best.ranked[1:] if r[0] - best.chi2 < SEPARATED_CHI2]
    choice = next((k for k, v in best.params.items() if isinstance(v, str)), None)
    if options and choice is not None:
        chi2, opt, params = options[0]
        why = (f"{best.cause} at {best.params[choice]} and at {opt} fit the measured modes alike "
               f"(chi2 {best.chi2:.1f} and {chi2:.1f})")
        return (best.cause, best.params), (best.cause, params), why
    for other in sig[1:]:
        fit = other["_fit"]
        if fit.chi2_cv - best.chi2_cv < SEPARATED_CHI2:
            why = (f"{best.cause} and {fit.cause} predict the held-out modes alike (chi2 {best.chi2_cv:.1f} and "
                   f"{fit.chi2_cv:.1f})")
            return (best.cause, best.params), (fit.cause, fit.params), why
    return None


def pair_rivals(causes: Sequence[str], params: Sequence[dict], chi2: float, ranked: Sequence[Sequence]
                ) -> tuple[list, list, str] | None:
    """A named pair (``causes`` with refined ``params``, chi2 on all modes) and the same pair with one cause's
    choice at its closest rival option, when the data do not separate them (chi2 within ``SEPARATED_CHI2``),
    with the reason; None when they are separated. ``ranked``: per cause, its options searched with the
    other cause applied ([(chi2, option, params)]; :func:`analysis.diagnosis.physical_pairs.rechoose`)."""
    pair = list(zip(causes, params))
    for i, options in enumerate(ranked):
        choice = next((k for k, v in params[i].items() if isinstance(v, str)), None)
        rival = next((r for r in options if choice is not None and r[1] != params[i][choice]), None)
        if rival is not None and rival[0] - chi2 < SEPARATED_CHI2:
            other = pair[1 - i][0]
            why = (f"{causes[i]} at {params[i][choice]} and at {rival[1]} fit the measured modes alike with {other} "
                   f"(chi2 {chi2:.1f} and {rival[0]:.1f})")
            return pair, [*pair[:i], (causes[i], rival[2]), *pair[i + 1:]], why
    return None


def _relative_db(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Weighted relative squared difference (dB) of two FRF arrays per reference (last axis lines)."""
    mag2 = np.abs(a) ** 2
    floor = (0.01 * np.median(np.abs(a), axis=-1, keepdims=True)) ** 2
    e = np.mean(np.abs(a - b) ** 2 / (mag2 + floor), axis=(0, 2))
    return 10 * np.log10(np.maximum(e, 1e-30))


def _modes_of(sim: Any, c: tuple[str, dict] | list, fmax: float) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies (Hz) and shape products of candidate ``c`` (one cause or a list of them)."""
    return sim.modes_of(list(c), fmax) if isinstance(c, list) else sim.modes(c[0], c[1], fmax)


def _separation_chi2(sim: Any, measured: FRFSet, points: Sequence[str], mm: MeasuredModes, fmax: float,
                     a: tuple[str, dict] | list, b: tuple[str, dict] | list) -> np.ndarray:
    """Per point of ``points``: the chi2 of ``b`` against ``a``'s modes as the measurement, on the modes
    measured today (``mm``, their frequency uncertainties) with shapes at the measured references and
    the point (module docs)."""
    refs = list(measured.references)
    n_out, n_ref = len(measured.outputs), len(refs)
    every = sim.at_points(measured.outputs, refs + list(points))
    fa, Pa = _modes_of(every, a, fmax)
    fb, Pb = _modes_of(every, b, fmax)
    width = n_ref + len(points)
    today = (np.arange(n_out)[:, None] * width + np.arange(n_ref)[None, :]).ravel()
    idx, _ = pair(mm, fa, Pa[today])
    ok = idx >= 0
    out = np.zeros(len(points))
    if not ok.any():
        return out
    for j in range(len(points)):
        rows = (np.arange(n_out)[:, None] * width + np.r_[np.arange(n_ref), n_ref + j][None, :]).ravel()
        as_a = MeasuredModes(fa[idx[ok]], mm.freq_std_hz[ok], Pa[rows][:, idx[ok]])
        out[j] = float(np.sum(residuals(as_a, fb, Pb[rows]) ** 2))
    return out


def propose(sim: Any, measured: FRFSet, prior: Sequence, noise_db: float, a: tuple[str, dict] | list,
            b: tuple[str, dict] | list, why: str, modes: tuple[MeasuredModes, float] | None = None) -> dict | None:
    """The hammer point (``component:node:direction``) whose FRFs to the measured outputs best separate
    candidates ``a`` and ``b`` (``(cause, params)``, or a list of them: two causes at once), as
    ``{"point", "why", "separation_db", "candidates"}`` (with ``"separation_chi2"`` when ranked on the
    modes); None when the simulation cannot be evaluated at other points (no ``points`` / ``at_points``).
    ``modes``: the measured modes the diagnosis compares and the highest frequency (Hz) of the simulated
    modes paired with them; given, the points are ranked by the chi2 the decision will see (module docs)."""
    if not (hasattr(sim, "points") and hasattr(sim, "at_points")):
        return None
    done = set(measured.references)
    points = [p for p in sim.points() if p not in done]
    if not points:
        return None
    there = sim.at_points(measured.outputs, points)

    def frf(c: tuple[str, dict] | list) -> np.ndarray:
        model = there.model_of(c) if isinstance(c, list) else there.model(*c)
        return predict(model, measured.freq_hz, measured.quantity, prior,
                       outputs=measured.outputs, references=tuple(points)).H

    sep = _relative_db(frf(a), frf(b)) - noise_db
    chi2 = None if modes is None or not hasattr(sim, "modes") else _separation_chi2(sim, measured, points, *modes, a, b)
    ranked_on_modes = chi2 is not None and float(np.ptp(chi2)) > 0
    k = int(np.argmax(chi2 if ranked_on_modes and chi2 is not None else sep))
    out = {"point": points[k], "separation_db": float(sep[k]),
           "why": f"{why}; hammered at {points[k]} their FRFs to the sensors differ by {sep[k]:.1f} dB above the noise",
           "candidates": [_candidate(c) for c in (a, b)]}
    if ranked_on_modes and chi2 is not None:
        out["separation_chi2"] = float(chi2[k])
        out["why"] += f" and their measured modes by chi2 {chi2[k]:.1f}"
    return out


def _candidate(c: tuple[str, dict] | list) -> dict:
    """A candidate as the JSON lists it: ``{"effect", "parameters"}``, for two causes ``{"effect": "a+b",
    "changes": [{"effect", "parameters"}, ...]}``."""
    if isinstance(c, list):
        return {"effect": "+".join(e for e, _ in c), "changes": [_candidate(x) for x in c]}
    return {"effect": c[0], "parameters": dict(c[1])}
