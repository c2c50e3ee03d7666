"""Deciding between a mass at every sensor and a stiffness change, mode by mode.

Both causes have one parameter and both lower (or raise) every natural frequency: a stiffness change
scales every mode by one factor, a mass ``m`` at every sensor lowers mode r by its own amount
(``omega_r^2 / (1 + m sum_o phi_or^2)``). Where the simulation's shapes at the sensors are known well
the mass places each mode where it is; where a mode's shapes are poorly scaled (the driving point near
a node of that mode: its residue there is small and its relative error large, and every output's shape
is divided by its square root) the mass misplaces that one mode by several half-power bandwidths. The
squared error of a misplaced peak saturates (two peaks, one measured and one predicted, whatever the
distance), so one or two such modes can cost the mass more on the summed held-out error than a common
factor that places no mode exactly but none far off either.

Each mode is therefore scored on its own: the lines are split into the simulation's modes' regions
(:func:`mode_regions`), each cause's held-out error (every line predicted by the fit on the other fold,
:func:`analysis.diagnosis.verdict.diagnose_frfs`) is summed per region, and a region counts when the
two causes' predictions differ there by more than the noise can hide (:func:`separable`); the cause with
the smaller held-out error in more of those regions is the one the data point to (:func:`mode_vote`).
"""
from __future__ import annotations

import numpy as np

from .rule import DEFAULT_RULE

__all__ = ["mode_regions", "separable", "mode_vote"]

# A region separates the two causes when their predictions' weighted squared difference ``D`` there is
# ``z`` standard deviations of what the noise adds to the difference of their errors (``sqrt(2 p D)`` for
# noise of weighted power ``p`` per line and FRF): ``D >= 2 p z^2``, ``z`` the decision rule's
# ``separation_z`` (:class:`analysis.diagnosis.rule.DecisionRule`).


def mode_regions(freq_hz: np.ndarray, mode_hz: np.ndarray) -> np.ndarray:
    """Index of the mode whose region holds each line (Hz in, int per line): the modes ``mode_hz``
    sorted, the regions split at the geometric means of neighbouring modes (the lines below the first
    mode belong to it, those above the last to it)."""
    f = np.asarray(freq_hz, float)
    modes = np.sort(np.asarray(mode_hz, float))
    if modes.size == 0:
        raise ValueError("mode_regions needs at least one mode frequency")
    edges = np.sqrt(modes[:-1] * modes[1:])
    return np.searchsorted(edges, f)


def separable(difference: np.ndarray, noise_power: float, z: float = DEFAULT_RULE.separation_z) -> np.ndarray:
    """Which regions separate two predictions: their summed weighted squared difference ``difference``
    (per region) at least ``2 noise_power z^2`` (``noise_power``: the mean weighted squared noise of a
    line and FRF, the scale of :func:`analysis.diagnosis.compare.noise_level`)."""
    return np.asarray(difference, float) >= 2.0 * float(noise_power) * z ** 2


def mode_vote(freq_hz: np.ndarray, mode_hz: np.ndarray, held_out_a: np.ndarray, held_out_b: np.ndarray,
              pred_a: np.ndarray, pred_b: np.ndarray, weights: np.ndarray, noise_db: float,
              z: float = DEFAULT_RULE.separation_z) -> dict:
    """Mode-by-mode comparison of two causes a and b.

    freq_hz : the lines (Hz); mode_hz : the simulation's modes (Hz) whose regions are scored.
    held_out_a, held_out_b : each cause's held-out weighted squared error per line and FRF, shape
        (n_out, n_ref, n_freq) like the weights.
    pred_a, pred_b : each cause's prediction fitted on every line (same shape, complex).
    weights : the line weights; noise_db : the noise level (dB, :func:`analysis.diagnosis.compare.noise_level`).

    Returns ``{"a": modes where a's held-out error is smaller, "b": likewise, "separable": the regions
    that separate them, "regions": per scored mode (Hz) the two held-out errors and the difference}``
    over the regions that hold lines."""
    label = mode_regions(freq_hz, mode_hz)
    modes = np.sort(np.asarray(mode_hz, float))
    ea = np.sum(held_out_a, axis=(0, 1))
    eb = np.sum(held_out_b, axis=(0, 1))
    dd = np.sum(np.asarray(weights) * np.abs(np.asarray(pred_a) - np.asarray(pred_b)) ** 2, axis=(0, 1))
    n = modes.size
    sa = np.bincount(label, ea, n)
    sb = np.bincount(label, eb, n)
    sd = np.bincount(label, dd, n)
    held = np.bincount(label, minlength=n) > 0
    sep = separable(sd, 10 ** (noise_db / 10), z) & held
    regions = [{"mode_hz": float(modes[i]), "error_a": float(sa[i]), "error_b": float(sb[i]),
                "difference": float(sd[i]), "separable": bool(sep[i])} for i in np.flatnonzero(held)]
    return {"a": int(np.sum(sep & (sa < sb))), "b": int(np.sum(sep & (sb < sa))), "separable": int(np.sum(sep)),
            "regions": regions}
