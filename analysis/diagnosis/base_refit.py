"""The modal model of a simulation given as FRFs, refitted in receptance with its pseudo-mode above the band.

The automatic fit of the simulated FRFs works in their own quantity (accelerance for most files) with
constant residual terms; the mode just above the band, whose tail rises towards the band's end, is
then absorbed by the in-band modes' residues and poles, and on a lightly damped structure the model
can miss the simulated FRFs by several per cent over much of the band (tens of times a measurement's
noise). A mode whose driving-point residue is small (the hammer near one of its nodes) then gets badly
scaled mass-normalised shapes, and a mass at a sensor moves it by the wrong amount. Here the poles
(the fitted ones and the pseudo-mode of :mod:`.above_band`) are refined once more by nonlinear LSFD
(:func:`analysis.lsfd.fit_lsfd`) on the simulated FRFs in receptance, with the receptance's residual
terms (``UR + LR / w^2``, m/N) and per-line weights ``1 / rms_o |H_o(f)|`` (the relative error
across the band), each pole held within :data:`POLE_WINDOW` of its start. The refit is kept when it
converged and lowers the relative misfit (``sum |H - H_model|^2 / |H|^2``) of the simulated FRFs.
"""
from __future__ import annotations

import logging
import warnings
from dataclasses import replace

import numpy as np

from ..frf import FRFSet
from ..modal import ModalModel, synthesize
from .effect_types import driving_point

__all__ = ["refit_in_receptance", "POLE_WINDOW", "ABOVE_STARTS", "MIN_GAIN"]

log = logging.getLogger(__name__)

#: each pole's damped frequency is held within this fraction of its start
POLE_WINDOW = 0.1
#: iterations of each refit
MAX_ITER = 50
#: starts of a pseudo-mode above the band, times the band's end
ABOVE_STARTS = (1.1, 1.3, 1.6, 2.0)
#: a pseudo-mode found by the refit must cut the relative misfit this many times
MIN_GAIN = 4.0


def _relative_misfit(model: ModalModel, rec: FRFSet, lines: np.ndarray) -> float:
    H = rec.H[..., lines]
    e = H - synthesize(model, rec.freq_hz[lines]).H
    return float(np.sum(np.abs(e) ** 2 / (np.abs(H) ** 2 + 1e-300)))


def _refit(model: ModalModel, rec: FRFSet, band: tuple[float, float], poles: np.ndarray
           ) -> ModalModel | None:
    """The LSFD refit of ``rec`` (receptance) from ``poles`` on ``band`` (Hz), labelled and with ``model``'s
    meta; None when it fails."""
    from ..lsfd import LSFDConvergenceWarning, fit_lsfd

    rms = np.sqrt(np.mean(np.abs(rec.H) ** 2, axis=(0, 1)))
    weights = np.where(rms > 0, 1.0 / np.where(rms > 0, rms, 1.0), 0.0)
    try:
        with warnings.catch_warnings():
            # an iteration stopped at its cap leaves the model as it was (below)
            warnings.simplefilter("ignore", LSFDConvergenceWarning)
            res = fit_lsfd(rec, poles, band=band, residual_form="physical", weights=weights, max_iter=MAX_ITER,
                           correct_exp_window=False, freq_window_hz=POLE_WINDOW * poles.imag / (2 * np.pi))
    except ValueError as exc:
        log.info("simulation's modal model not refitted in receptance: %s", exc)
        return None
    if not res.success or res.model.poles.size != poles.size or not np.all(np.isfinite(res.model.residues)):
        return None
    return replace(res.model, outputs=model.outputs, references=model.references, meta=dict(model.meta))


def _driving_residue_positive(model: ModalModel, mode: int) -> bool:
    dp = driving_point(model)
    if dp is None:
        return False
    i, j = dp
    lam = complex(model.poles[mode])
    return bool(np.real(2j * lam.imag * model.residues[i, j, mode]) > 0)


def refit_in_receptance(model: ModalModel, sim: FRFSet, band_hz: tuple[float, float] | None = None) -> ModalModel:
    """``model`` (receptance, labelled as ``sim``) with its poles, residues and residual terms refitted to the
    simulated FRFs ``sim`` in receptance on ``band_hz`` (Hz; default the FRFs' lines above 0 Hz), as the
    module docstring says; ``meta`` and labels kept. The model as it is when the refit fails, does not
    converge or fits worse.

    With a driving point and no pseudo-mode above the band yet (``meta["above_band_modes"]``, whose tail
    fit may find none when few lines lie above the highest mode), one is tried here too: the refit started
    with one more pole at each of :data:`ABOVE_STARTS` times the band's end is kept when it cuts the
    relative misfit :data:`MIN_GAIN` times, its pole stays above the band and its driving-point residue is
    positive (a mode's)."""
    if model.quantity != "receptance" or model.poles.size == 0:
        return model
    rec = sim if sim.quantity == "receptance" else sim.as_quantity("receptance")
    f = rec.freq_hz
    lo, hi = (float(f[f > 0][0]), float(f[-1])) if band_hz is None else (max(float(band_hz[0]), float(f[f > 0][0])),
                                                                          float(band_hz[1]))
    lines = (f >= lo) & (f <= hi)
    if np.count_nonzero(lines) < 4 * (model.poles.size + 1) or not np.all(np.isfinite(rec.H[..., lines])):
        return model
    poles = np.asarray(model.poles, complex)
    best, best_cost = model, _relative_misfit(model, rec, lines)
    fitted = _refit(model, rec, (lo, hi), poles)
    if fitted is not None:
        c = _relative_misfit(fitted, rec, lines)
        if c < best_cost:
            best, best_cost = fitted, c
    if driving_point(model) is not None and not model.meta.get("above_band_modes"):
        zeta = float(np.clip(np.median(-poles.real / np.abs(poles)), 1e-4, 0.1))
        meta = dict(model.meta)
        meta["above_band_modes"] = 1
        grown = replace(model, meta=meta)
        for q in ABOVE_STARTS:
            wu = 2 * np.pi * q * hi
            extra = _refit(grown, rec, (lo, hi), np.append(poles, wu * (-zeta + 1j * np.sqrt(1 - zeta ** 2))))
            if extra is None or not extra.freq_hz[-1] > hi or not _driving_residue_positive(extra, -1):
                continue
            c = _relative_misfit(extra, rec, lines)
            if c * MIN_GAIN <= best_cost:
                best, best_cost = extra, c
    log.debug("simulation's modal model refitted in receptance: relative misfit %.3g", best_cost)
    return best
