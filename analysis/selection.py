"""Automatic, hint-free selection of the physical poles from a stabilization diagram.

The rule
--------
1. Candidates: every pole of class >= ``min_class`` (default: stable in frequency and
   damping) with damping ratio in ``(min_damping, max_damping)`` and damped frequency
   inside the band.
2. Clusters: complete-linkage clustering of the candidates with the distance

       d(a, b) = max(|f_a - f_b| / (f_ab tol_freq),
                     |zeta_a - zeta_b| / max(zeta_ab tol_damp, abs_tol_damp))

   (f_ab, zeta_ab the larger of the two), cut at d = 1. The damping part is
   relative-plus-absolute (``abs_tol_damp`` default 0.1 % of critical): the damping estimate
   of a very lightly damped mode scatters by more than its own size from order to order.
   Complete linkage means every pair in a cluster is within the tolerances, so two modes a
   few percent apart are never chained together through scattered spurious poles.
3. Persistence: a cluster counts the *distinct* model orders it holds; it is kept when it
   holds at least ``min_fraction`` of the orders from its first appearance to the last
   order, and at least ``min_orders`` orders.
4. Representative: the pole with the median frequency and median damping of the cluster
   (``pole_from_fz(median f, median zeta)``).
5. Ranking: by presence (distinct orders), ties by the smaller relative frequency spread.
   Two kept clusters closer than ``tol_freq`` in frequency are merged (the higher ranked
   wins). With ``n_modes`` given, the ``n_modes`` first clusters are returned.

The user overrides the selection by giving poles (or frequencies, see
:func:`poles_from_frequencies`) instead.
"""
from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from .clustering import complete_linkage_labels
from .modal import damping_ratio, natural_freq_hz, pole_from_fz
from .stabilization import STABLE_DAMP, StabilizationResult

__all__ = ["select_poles", "SelectedCluster", "select_clusters", "poles_from_frequencies", "faster_than_window"]

log = logging.getLogger(__name__)

#: absolute damping-ratio tolerance of the clustering (0.1 % of critical)
ABS_TOL_DAMP_CLUSTER = 1e-3


def _f_hz(pole: complex) -> float:
    """Natural frequency (Hz) of one pole (rad/s)."""
    return float(natural_freq_hz(np.asarray(pole)))


class SelectedCluster(NamedTuple):
    """A kept cluster: representative pole (rad/s), number of orders, spreads of f (Hz) and zeta."""

    pole: complex
    n_orders: int
    freq_spread_hz: float
    damping_spread: float


def select_clusters(
    stab: StabilizationResult,
    *,
    min_class: int = STABLE_DAMP,
    tol_freq: float | None = None,
    tol_damp: float = 0.25,
    min_damping: float = 0.0,
    max_damping: float | None = None,
    min_orders: int = 3,
    min_fraction: float = 0.5,
    abs_tol_damp: float = ABS_TOL_DAMP_CLUSTER,
) -> list[SelectedCluster]:
    """The persistent clusters of stable poles, most persistent first (ties: the smaller relative
    frequency spread first); see the module docstring for the rule and the criteria."""
    tol_f = stab.tol_freq if tol_freq is None else float(tol_freq)
    zmax = stab.max_damping if max_damping is None else float(max_damping)
    p, orders = stab.stable_poles(min_class)
    if p.size == 0:
        return []
    f, z = natural_freq_hz(p), damping_ratio(p)
    fd = p.imag / (2 * np.pi)
    lo, hi = stab.band
    keep = (z > min_damping) & (z < zmax) & (fd >= lo) & (fd <= hi)
    p, f, z, orders = p[keep], f[keep], z[keep], orders[keep]
    if p.size == 0:
        return []
    if p.size == 1:
        labels = np.array([1])
    else:
        dfm = np.abs(f[:, None] - f[None, :]) / (np.maximum(f[:, None], f[None, :]) * tol_f)
        dzm = np.abs(z[:, None] - z[None, :]) / np.maximum(np.maximum(z[:, None], z[None, :]) * tol_damp, abs_tol_damp)
        labels = complete_linkage_labels(np.maximum(dfm, dzm), 1.0)
    last = max(stab.orders)
    out: list[SelectedCluster] = []
    for lab in np.unique(labels):
        k = labels == lab
        ords = np.unique(orders[k])
        span = last - ords.min() + 1
        if ords.size < min_orders or ords.size < min_fraction * span:
            continue
        fm, zm = float(np.median(f[k])), float(np.median(z[k]))
        out.append(
            SelectedCluster(complex(pole_from_fz(fm, zm)), int(ords.size), float(np.ptp(f[k])), float(np.ptp(z[k])))
        )
    out.sort(key=lambda c: (-c.n_orders, c.freq_spread_hz / max(_f_hz(c.pole), 1e-300)))
    # merge survivors closer than tol_freq (keep the more persistent)
    kept: list[SelectedCluster] = []
    for c in out:
        fc = _f_hz(c.pole)
        if all(abs(fc - _f_hz(k.pole)) / fc >= tol_f for k in kept):
            kept.append(c)
    return kept


def select_poles(
    stab: StabilizationResult,
    n_modes: int | None = None,
    **kwargs: Any,
) -> np.ndarray:
    """Physical poles (rad/s, sorted by frequency) picked automatically from a stabilization result.

    Parameters
    ----------
    stab : the stabilization diagram.
    n_modes : if given, keep the n_modes most persistent clusters; otherwise all that pass.
    kwargs : criteria of :func:`select_clusters` (min_class, tol_freq, tol_damp, min_damping,
        max_damping, min_orders, min_fraction, abs_tol_damp).
    """
    clusters = select_clusters(stab, **kwargs)
    if n_modes is not None:
        if int(n_modes) < 1:
            raise ValueError(f"n_modes must be >= 1; got {n_modes}")
        if len(clusters) < int(n_modes):
            log.warning("asked for %d modes but only %d stable clusters were found", n_modes, len(clusters))
        clusters = clusters[: int(n_modes)]
    poles = np.array([c[0] for c in clusters], dtype=complex)
    return poles[np.argsort(natural_freq_hz(poles))] if poles.size else poles


def poles_from_frequencies(
    freqs_hz: Sequence[float] | np.ndarray, stab: StabilizationResult | None = None, *, default_damping: float = 0.01,
    window_shift: float = 0.0,
) -> np.ndarray:
    """Poles (rad/s, as measured) for user-given natural frequencies (Hz).

    With a stabilization result, each frequency takes the damping of the nearest stable poles (within
    5 %) so its damping is estimated from the data; otherwise ``default_damping`` is used (of the
    structure: the measured start adds the window's decay). ``window_shift`` (1/s,
    :func:`analysis.frf.window_pole_shift`): the decay an exponential window adds to every measured pole;
    a stabilization pole that decays no faster than the window alone would have negative damping once the
    window is removed, so it cannot give a start and is not used.
    """
    fr = np.asarray([float(x) for x in freqs_hz], dtype=float)
    if fr.size == 0 or np.any(~np.isfinite(fr)) or np.any(fr <= 0):
        raise ValueError("frequencies must be positive numbers in Hz; got "
                         f"{', '.join(f'{x:.6g}' for x in fr)} Hz")
    out = pole_from_fz(fr, np.full(fr.size, default_damping)) - float(window_shift)
    if stab is not None:
        p, _ = stab.stable_poles(STABLE_DAMP)
        if p.size == 0:
            p, _ = stab.stable_poles(1)
        p = p[-p.real > float(window_shift)] if p.size else p   # decays faster than the window: a structure's pole
        if p.size:
            f = natural_freq_hz(p)
            for i, x in enumerate(fr):
                k = np.abs(f - x) / x < 0.05
                if np.any(k):
                    z = float(np.median(damping_ratio(p[k][np.argsort(np.abs(f[k] - x))[:10]])))
                    out[i] = pole_from_fz(x, z)
    return faster_than_window(out, window_shift, default_damping)


def faster_than_window(poles: np.ndarray, window_shift: float, default_damping: float = 0.01) -> np.ndarray:
    """Start poles (rad/s, as measured) that all decay faster than the exponential window alone: a pole
    whose decay rate is not above ``window_shift`` (1/s, :func:`analysis.frf.window_pole_shift`) would
    have zero or negative damping once the window is removed; it gets the window's decay plus
    ``default_damping`` of the structure at its natural frequency. A copy; the others unchanged."""
    out = np.array(poles, dtype=complex)
    slow = -out.real <= float(window_shift)
    if np.any(slow):
        f = natural_freq_hz(out[slow])
        out[slow] = pole_from_fz(f, float(window_shift) / (2 * np.pi * f) + default_damping)
    return out
