"""The frequency band of a fit (the paper's sec. 3.1): the default band from the data, the band
edges kept off resonances, and lines left out (mains harmonics).

The default band runs from the lowest reliable line (past the lowest ``LOW_LINES`` lines and any
leading low-coherence lines) to the top of what the data support (:func:`default_band`).
"""
from __future__ import annotations

import logging
from dataclasses import replace
from typing import Sequence

import numpy as np
from scipy.signal import find_peaks

from .errors import ImpactlabError
from .frf import FRFSet
from .modal import damping_ratio, natural_freq_hz

__all__ = ["FitError", "default_band", "default_max_modes", "check_band_edges", "mains_harmonics", "exclude_lines"]

log = logging.getLogger(__name__)


class FitError(ImpactlabError, ValueError):
    """The data cannot be fitted as asked (too few lines, nothing stable...)."""


LOW_LINES = 5
MIN_COHERENCE = 0.8
EDGE_BANDWIDTHS = 3.0
EXCLUDE_LINES = 2.0


def default_band(frf: FRFSet) -> tuple[float, float]:
    """Default band (Hz): skip the lowest ``LOW_LINES`` lines and leading low-coherence lines."""
    f = frf.freq_hz
    if f.size < 16:
        raise FitError(f"the FRFs hold only {f.size} lines; at least 16 are needed")
    df = frf.line_spacing_hz
    lo = max(float(f[0]), LOW_LINES * df)
    if frf.coherence is not None and np.any(np.isfinite(frf.coherence)):
        c = np.nanmedian(frf.coherence.reshape(-1, f.size), axis=0)
        head = np.flatnonzero(f <= f[0] + 0.1 * (f[-1] - f[0]))
        ok = head[c[head] >= MIN_COHERENCE]
        # a leading run of low coherence (within the lowest 10 % of the span) moves the edge
        if ok.size and ok[0] > 0:
            lo = max(lo, float(f[ok[0]]))
    lo_line = f[f >= lo - 1e-9 * abs(lo)][0]
    return float(lo_line), float(f[-1])


def default_max_modes(frf: FRFSet, band: tuple[float, float]) -> int:
    """Largest model size for the stabilization: ``2 * peaks + 8`` clipped to [12, 60], where
    ``peaks`` counts the peaks of the summed FRF magnitude (dB) with 3 dB prominence."""
    sel = (frf.freq_hz >= band[0]) & (frf.freq_hz <= band[1])
    s = np.sqrt(np.nansum(np.abs(frf.H[..., sel].reshape(-1, int(sel.sum()))) ** 2, axis=0))
    s = 20 * np.log10(np.maximum(s, np.max(s) * 1e-12 + 1e-300))
    peaks, _ = find_peaks(s, prominence=3.0)
    return int(np.clip(2 * peaks.size + 8, 12, 60))


def check_band_edges(
    poles: np.ndarray, band: tuple[float, float], limits: tuple[float, float], movable: tuple[bool, bool]
) -> tuple[tuple[float, float], list[str]]:
    """Move band edges away from resonances (see module docstring, step 4).

    poles : rad/s; band : current (lo, hi) Hz; limits : how far each edge may go (Hz);
    movable : whether each edge may move. Returns the new band and the warnings.
    """
    lo, hi = band
    warn: list[str] = []
    f = natural_freq_hz(poles)
    bw = 2.0 * damping_ratio(poles) * f
    for fi, b in zip(f, bw):
        margin = EDGE_BANDWIDTHS * b
        if fi - lo < margin:
            want = fi - margin
            if movable[0] and want >= limits[0]:
                lo = want
            else:
                warn.append(
                    f"the mode at {fi:.4g} Hz lies within {EDGE_BANDWIDTHS:g} half-power bandwidths of the lower "
                    f"band edge {lo:.4g} Hz; its estimate may be biased (lower the edge below {want:.4g} Hz if the "
                    "data allow, or raise it above the mode)"
                )
        if hi - fi < margin:
            want = fi + margin
            if movable[1] and want <= limits[1]:
                hi = want
            else:
                warn.append(
                    f"the mode at {fi:.4g} Hz lies within {EDGE_BANDWIDTHS:g} half-power bandwidths of the upper "
                    f"band edge {hi:.4g} Hz; its estimate may be biased (raise the edge above {want:.4g} Hz if the "
                    "data allow, or lower it below the mode)"
                )
    return (lo, hi), warn


def mains_harmonics(mains_hz: float, band: Sequence[float]) -> list[float]:
    """Multiples ``k * mains_hz`` (Hz, k >= 1) inside ``band`` = (lo, hi) Hz."""
    m = float(mains_hz)
    if not np.isfinite(m) or m <= 0:
        raise ValueError(f"the mains frequency must be > 0 Hz; got {mains_hz!r}")
    lo, hi = float(band[0]), float(band[1])
    k0 = max(1, int(np.ceil(lo / m)))
    return [k * m for k in range(k0, int(np.floor(hi / m)) + 1)]


def exclude_lines(frf: FRFSet, freqs_hz: Sequence[float], n_lines: float = EXCLUDE_LINES) -> tuple[FRFSet, int]:
    """The FRFs without the lines within ``n_lines`` line spacings of any of ``freqs_hz`` (Hz),
    and how many lines were left out. Dropping a line is the same as weighting it zero in the
    least-squares cost (``sum_k |w_k e_k|^2``); it also keeps the per-FRF weights usable."""
    x = np.asarray(freqs_hz, dtype=float).ravel()
    if x.size and not np.all(np.isfinite(x)):
        raise ValueError(f"frequencies to exclude must be finite (Hz); got {list(freqs_hz)!r}")
    f = frf.freq_hz
    tol = (n_lines + 1e-6) * frf.line_spacing_hz
    drop = np.zeros(f.size, dtype=bool)
    for v in x:
        drop |= np.abs(f - v) <= tol
    if not np.any(drop):
        return frf, 0
    keep = ~drop
    if int(keep.sum()) < 16:
        raise FitError(f"excluding the lines around {list(x)} Hz leaves only {int(keep.sum())} lines; exclude fewer")
    coh = None if frf.coherence is None else np.asarray(frf.coherence)[..., keep]
    return replace(frf, freq_hz=f[keep], H=frf.H[..., keep], coherence=coh), int(drop.sum())
