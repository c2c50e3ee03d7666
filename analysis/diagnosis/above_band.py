"""The mode just above the band of a simulation given as FRFs, as one pseudo-mode of its modal model.

A fitted modal model holds the modes in its band; the next mode above it shows in the FRFs only as a
tail that rises towards the band's end (what a fit's upper residual absorbs). A mass or a resonator on
the structure moves that mode too, often into or next to the band, and a model that keeps its tail as
a fixed term cannot follow. Here the tail left by the fitted modes (receptance, ``corr``) is fitted per
FRF by one real mode above the band, ``A_or / (w_u^2 - w^2 + 2 j zeta w_u w)``, beside complex
multiples of ``1``, ``1/w``, ``1/w^2`` and ``1/w^4`` per FRF (the modes further above and below and
the residual terms of a fit in another quantity, which stay fixed); ``w_u`` is searched on a
grid from the band's end to twice it, ``zeta`` is the fitted modes' median. The coefficients are scaled
by the driving point into mass-normalised shapes, ``psi_o = A_od / sqrt(A_dd)`` at the outputs and
``psi_r = A_dr / sqrt(A_dd)`` at the references, and the pseudo-mode is the real mode with those
shapes (receptance residue ``psi_o psi_r / (2 j w_d)``), so the effects that re-analyse the modes
move it as the physics moves the mode it stands for.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.optimize import minimize_scalar

from ..frf import FRFSet
from ..modal import ModalModel
from .effect_types import driving_point

__all__ = ["above_band_mode", "with_above_band_mode", "MIN_GAIN"]

MIN_GAIN = 4.0          # the pseudo-mode must cut the tail's weighted squared error at least 4 times (6 dB)
MAX_RATIO = 2.0         # searched up to twice the band's end
GRID = 80
MIN_TAIL = 1e-4         # a tail below this relative rms error (of the FRFs) is not fitted
TAIL_FROM = 0.6         # the tail is fitted on the band's upper part only (above its highest mode, at least this far up)


def _fit(w: np.ndarray, C: np.ndarray, sw: np.ndarray, w_u: float | None, zeta: float
         ) -> tuple[float, np.ndarray]:
    """Weighted squared error of the best fit of every FRF of ``C`` (n_out, n_ref, n_freq) by the basis
    (the mode at ``w_u`` rad/s if given, real; complex multiples of ``1, 1/w^2, 1/w^4, 1/w``) and the mode's coefficients
    (n_out, n_ref) (zeros without a mode)."""
    ones = np.ones_like(w, dtype=complex)
    slow = [ones, 1.0 / w ** 2, 1.0 / w ** 4, 1.0 / w]
    cols = slow + [1j * c for c in slow]
    if w_u is not None:
        cols.insert(0, 1.0 / (w_u ** 2 - w ** 2 + 2j * zeta * w_u * w))
    B = np.stack(cols, axis=1)
    total = 0.0
    A = np.zeros(C.shape[:2])
    for o in range(C.shape[0]):
        for r in range(C.shape[1]):
            s = sw[o, r]
            M = np.vstack([(B * s[:, None]).real, (B * s[:, None]).imag])
            y = np.concatenate([(C[o, r] * s).real, (C[o, r] * s).imag])
            scale = np.linalg.norm(M, axis=0)
            scale[scale == 0] = 1.0
            x, *_ = np.linalg.lstsq(M / scale, y, rcond=None)
            x = x / scale
            total += float(np.sum((y - M @ x) ** 2))
            if w_u is not None:
                A[o, r] = x[0]
    return total, A


def above_band_mode(corr: FRFSet, weights: np.ndarray, zeta: float, driving: tuple[int, int],
                    lines: np.ndarray | None = None) -> tuple[complex, np.ndarray] | None:
    """The pseudo-mode above the band of the receptance tail ``corr`` (what the fitted modes miss of the
    simulated FRFs, receptance, m/N): its pole (rad/s) and receptance residues (n_out, n_ref), rank one
    through the driving point ``driving`` = (output index, reference index); ``weights`` (n_out, n_ref,
    n_freq) of the relative squared error; ``lines`` (boolean, default all) the lines fitted, the
    highest of them the band's end. None when the tail is below ``MIN_TAIL`` (relative rms), when no mode
    above the band cuts the tail's error ``MIN_GAIN`` times, when the best lies at the search's upper
    end, or when the driving point's coefficient is not positive (not a mode's tail)."""
    f = np.asarray(corr.freq_hz, float)
    keep = (f > 0) if lines is None else (f > 0) & np.asarray(lines, bool)
    w = 2 * np.pi * f[keep]
    C = np.asarray(corr.H, complex)[..., keep]
    sw = np.sqrt(np.asarray(weights, float)[..., keep])
    if w.size < 8 or not np.all(np.isfinite(C)):
        return None
    base_cost, _ = _fit(w, C, sw, None, zeta)
    if not base_cost > MIN_TAIL ** 2 * C.size:
        return None
    ratios = np.geomspace(1.002, MAX_RATIO, GRID)
    costs = np.array([_fit(w, C, sw, float(q * w[-1]), zeta)[0] for q in ratios])
    i = int(np.argmin(costs))
    if i == ratios.size - 1:
        return None
    lo, hi = ratios[max(i - 1, 0)], ratios[min(i + 1, ratios.size - 1)]
    res = minimize_scalar(lambda q: _fit(w, C, sw, float(q * w[-1]), zeta)[0], bounds=(lo, hi), method="bounded",
                          options={"xatol": 1e-5})
    q = float(res.x) if res.fun < costs[i] else float(ratios[i])
    cost, A = _fit(w, C, sw, q * w[-1], zeta)
    if not cost * MIN_GAIN <= base_cost:
        return None
    i_d, j_d = driving
    a_d = A[i_d, j_d]
    if not a_d > 0:
        return None
    psi_o, psi_r = A[:, j_d] / np.sqrt(a_d), A[i_d, :] / np.sqrt(a_d)
    w_u = q * w[-1]
    pole = complex(w_u * (-zeta + 1j * np.sqrt(1 - zeta ** 2)))
    return pole, np.outer(psi_o, psi_r) / (2j * pole.imag)


def with_above_band_mode(model: ModalModel, sim: FRFSet, weights: np.ndarray,
                         band_hz: tuple[float, float] | None = None) -> ModalModel:
    """``model`` (receptance, labelled as ``sim``) with the pseudo-mode of :func:`above_band_mode` fitted to
    what it misses of ``sim`` (the simulated FRFs) where its tail shows: from the highest fitted mode in
    ``band_hz`` (Hz, the band the model was fitted in; default the FRFs' lines), or from ``TAIL_FROM`` of
    the band's end if that is higher, to the band's end; ``meta["above_band_modes"]`` counts it. The model
    as it is without a driving point or without such a mode."""
    from ..modal import synthesize

    dp = driving_point(model)
    if dp is None or model.quantity != "receptance":
        return model
    syn = synthesize(model, sim.freq_hz)
    same = sim if sim.quantity == syn.quantity else sim.as_quantity(syn.quantity)
    corr = replace(same, H=same.H - syn.H, coherence=None)
    lam = np.asarray(model.poles, complex)
    zeta = float(np.median(-lam.real / np.abs(lam))) if lam.size else 0.01
    f = sim.freq_hz
    lo, hi = (float(f[0]), float(f[-1])) if band_hz is None else (float(band_hz[0]), float(band_hz[1]))
    below = model.freq_hz[model.freq_hz < hi]
    start = max(lo, TAIL_FROM * hi, float(below.max()) * 1.03 if below.size else lo)
    lines = (f >= start) & (f <= hi)
    if np.count_nonzero(lines) < 16:
        lines = (f >= max(lo, TAIL_FROM * hi)) & (f <= hi)
    found = above_band_mode(corr, weights, float(np.clip(zeta, 1e-4, 0.1)), dp, lines)
    if found is None:
        return model
    pole, R = found
    meta = dict(model.meta)
    meta["above_band_modes"] = 1
    return replace(model, poles=np.append(lam, pole), residues=np.concatenate([model.residues, R[:, :, None]], axis=2),
                   meta=meta)
