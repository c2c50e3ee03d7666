"""Peaks of a sampled curve (a summed FRF magnitude, a misfit spectrum), their prominence and width.

The definitions are the usual ones (those of ``scipy.signal.find_peaks``), written here because
importing ``scipy.signal`` costs more than a whole default fit: a peak is a sample (or the middle
sample of a flat top, rounded down) with lower neighbours on both sides; its prominence is its
height above the higher of the two lowest points between it and the nearest higher sample on
either side (or the end of the curve); its width is measured at a fraction of its prominence below
its top.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["find_peaks", "prominences", "peak_widths", "PeakRule", "PEAK_RULES"]


def _local_maxima(x: np.ndarray) -> np.ndarray:
    """Indices of the local maxima of ``x`` (flat tops: the middle sample, rounded down)."""
    if x.size < 3:
        return np.zeros(0, dtype=np.intp)
    start = np.concatenate(([0], np.flatnonzero(x[1:] != x[:-1]) + 1))   # first sample of each run of equal values
    end = np.concatenate((start[1:] - 1, [x.size - 1]))
    v = x[start]
    inner = np.arange(1, v.size - 1)
    top = inner[(v[inner - 1] < v[inner]) & (v[inner + 1] < v[inner])]
    return ((start[top] + end[top]) // 2).astype(np.intp)


def _tables(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sparse tables of ``x`` (n samples) for range queries in O(1): row k, column p covers
    ``x[p:p + 2**k]`` (valid for ``p <= n - 2**k``): its maximum, and the index of its minimum
    (the first of equal minima, and the last)."""
    n = x.size
    levels = max(1, int(n).bit_length())
    top = np.empty((levels, n))
    first = np.empty((levels, n), dtype=np.intp)
    top[0] = x
    first[0] = np.arange(n)
    last = first.copy()
    for k in range(1, levels):
        w, m = 1 << (k - 1), n - (1 << k) + 1
        top[k, :m] = np.maximum(top[k - 1, :m], top[k - 1, w:w + m])
        a, b = first[k - 1, :m], first[k - 1, w:w + m]
        first[k, :m] = np.where(x[b] < x[a], b, a)
        a, b = last[k - 1, :m], last[k - 1, w:w + m]
        last[k, :m] = np.where(x[b] <= x[a], b, a)
    return top, first, last


def _argmin_range(x: np.ndarray, table: np.ndarray, lo: np.ndarray, hi: np.ndarray, last: bool) -> np.ndarray:
    """Index of the minimum of each ``x[lo:hi + 1]`` (``hi >= lo``) from a table of :func:`_tables`:
    the first of equal minima, or the last one with ``last``."""
    k = np.frexp((hi - lo + 1).astype(float))[1] - 1          # floor(log2(length)), exactly
    a, b = table[k, lo], table[k, hi - (1 << k) + 1]
    take_b = x[b] <= x[a] if last else x[b] < x[a]
    return np.where(take_b, b, a)


def _bases(x: np.ndarray, peaks: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Prominence, left and right base of each peak: the lowest point on either side before a
    higher sample or the end of ``x`` (of equal lowest points, the one nearest the peak).

    All peaks at once by binary lifting on a sparse table of maxima (the run of samples not higher
    than the peak on either side, longest power of two first) and range-minimum queries for the
    bases."""
    peaks = np.asarray(peaks, dtype=np.intp)
    if peaks.size == 0:
        return np.empty(0), np.empty(0, dtype=np.intp), np.empty(0, dtype=np.intp)
    n = x.size
    top, first, last = _tables(x)
    h = x[peaks]
    lo = peaks.copy()          # the run x[lo:peak] holds no sample higher than the peak
    hi = peaks + 1             # ... and x[peak + 1:hi]
    for k in range(top.shape[0] - 1, -1, -1):
        w = 1 << k
        c = lo - w
        ok = c >= 0
        ok[ok] = top[k, c[ok]] <= h[ok]
        lo[ok] = c[ok]
        ok = hi + w <= n
        ok[ok] = top[k, hi[ok]] <= h[ok]
        hi[ok] += w
    left = _argmin_range(x, last, lo, peaks, last=True)
    right = _argmin_range(x, first, peaks, hi - 1, last=False)
    prom = h - np.maximum(x[left], x[right])
    return prom, left, right


def prominences(x: np.ndarray, peaks: np.ndarray) -> np.ndarray:
    """The prominence of each peak (index into ``x``): its height above the higher of the lowest
    points on either side before a higher sample or the end of ``x``."""
    return _bases(np.asarray(x, dtype=float), np.asarray(peaks, dtype=np.intp))[0]


def peak_widths(x: np.ndarray, peaks: np.ndarray | list[int], rel_height: float = 0.5) -> np.ndarray:
    """Width (in samples, linearly interpolated) of each peak at ``rel_height`` of its prominence
    below its top, within its bases (as ``scipy.signal.peak_widths(...)[0]``)."""
    x = np.asarray(x, dtype=float)
    peaks = np.asarray(peaks, dtype=np.intp)
    prom, left, right = _bases(x, peaks)
    out = np.empty(len(peaks))
    for k, i in enumerate(peaks):
        height = x[i] - prom[k] * rel_height
        j = int(i)
        while left[k] < j and height < x[j]:
            j -= 1
        lo = float(j)
        if x[j] < height:
            lo += (height - x[j]) / (x[j + 1] - x[j])
        j = int(i)
        while j < right[k] and height < x[j]:
            j += 1
        hi = float(j)
        if x[j] < height:
            hi -= (height - x[j]) / (x[j - 1] - x[j])
        out[k] = hi - lo
    return out


def find_peaks(x: np.ndarray, prominence: float | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Indices of the peaks of the 1-D curve ``x`` whose prominence is at least ``prominence``
    (None: every peak), and ``{"prominences": ...}`` when a prominence was asked for (as
    ``scipy.signal.find_peaks``)."""
    x = np.asarray(x, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"find_peaks needs a 1-D curve; got shape {x.shape}")
    peaks = _local_maxima(x)
    if prominence is None:
        return peaks, {}
    prom = _bases(x, peaks)[0]
    keep = prom >= float(prominence)
    return peaks[keep], {"prominences": prom[keep]}


@dataclass(frozen=True)
class PeakRule:
    """One named rule for the peaks of a curve: the least prominence a peak needs, in dB on a dB curve
    (``prominence_db``) or, when given, as a fraction of the curve's maximum on a linear one (``fraction_of_max``),
    and what it is for. :meth:`find` applies it; :meth:`options` gives its ``find_peaks`` options."""

    name: str
    purpose: str
    prominence_db: float = 0.0
    fraction_of_max: float | None = None

    def threshold(self, x: np.ndarray) -> float:
        """The least prominence (in the curve's units) a peak of ``x`` needs."""
        if self.fraction_of_max is not None:
            return self.fraction_of_max * float(np.max(x)) if np.size(x) else 0.0
        return float(self.prominence_db)

    def options(self, prominence_db: float | None = None) -> dict[str, float]:
        """``find_peaks`` options of a dB rule (``prominence_db``: a caller's own level instead)."""
        if self.fraction_of_max is not None:
            raise ValueError(f"peak rule {self.name!r} is relative to the curve's maximum; use PeakRule.find")
        return {"prominence": float(self.prominence_db if prominence_db is None else prominence_db)}

    def find(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Indices of the peaks of the 1-D curve ``x`` this rule keeps, and their prominences."""
        x = np.asarray(x, dtype=float)
        pk, prop = find_peaks(x, prominence=self.threshold(x))
        return pk, prop["prominences"]


#: every peak rule of the analysis, by name (one place for their levels)
PEAK_RULES: dict[str, PeakRule] = {r.name: r for r in (
    PeakRule("visible", "a resonance the data show (analysis.visibility), on |H| and the CMIF in dB", 10.0),
    PeakRule("band_edge", "a resonance on the band's edge (analysis.bands), on the smoothed summed power in dB", 10.0),
    PeakRule("mode_count", "how many modes a band holds, for the stabilization's size (analysis.bands), summed power "
             "in dB", 3.0),
    PeakRule("cmif_support", "a CMIF peak that supports a fitted pole (analysis.fit_checks), first CMIF curve in dB",
             3.0),
    PeakRule("modal_peaks", "resonances picked for the half-power damping and the diagnosis (diagnosis.compare, "
             "diagnosis.timedata, driving_point), summed magnitude in dB", 6.0),
    PeakRule("level_peaks", "the strongest resonances compared between soft and hard hits (analysis.linearity), "
             "linear |H1|", fraction_of_max=0.05),
)}
