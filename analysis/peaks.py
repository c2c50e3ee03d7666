"""Peaks of a sampled curve (a summed FRF magnitude, a misfit spectrum), their prominence and width.

The definitions are the usual ones (those of ``scipy.signal.find_peaks``), written here because
importing ``scipy.signal`` costs more than a whole default fit: a peak is a sample (or the middle
sample of a flat top, rounded down) with lower neighbours on both sides; its prominence is its
height above the higher of the two lowest points between it and the nearest higher sample on
either side (or the end of the curve); its width is measured at a fraction of its prominence below
its top.
"""
from __future__ import annotations

import numpy as np

__all__ = ["find_peaks", "prominences", "peak_widths"]


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


def _bases(x: np.ndarray, peaks: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Prominence, left and right base of each peak: the lowest point on either side before a
    higher sample or the end of ``x`` (of equal lowest points, the one nearest the peak)."""
    prom = np.empty(len(peaks))
    left = np.empty(len(peaks), dtype=np.intp)
    right = np.empty(len(peaks), dtype=np.intp)
    for k, i in enumerate(np.asarray(peaks, dtype=np.intp)):
        h = x[i]
        higher_left = np.flatnonzero(x[:i] > h)
        lo = higher_left[-1] + 1 if higher_left.size else 0
        higher_right = np.flatnonzero(x[i + 1:] > h)
        hi = i + 1 + higher_right[0] if higher_right.size else x.size
        seg_l = x[lo:i + 1][::-1]
        seg_r = x[i:hi]
        left[k] = i - int(np.argmin(seg_l))
        right[k] = i + int(np.argmin(seg_r))
        prom[k] = h - max(float(x[left[k]]), float(x[right[k]]))
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
