"""Is the structure reciprocal, and are the sensors' calibrations consistent? H_ij against H_ji.

Wherever a point is both struck and measured in the same direction (a roving-hammer test that
strikes sensor points), the FRF set holds ``H_ij`` (response at i, force at j) and ``H_ji``; a linear
structure has ``H_ij = H_ji``. Their difference is compared with the FRFs' own random error per line,
from the coherence and the number of averages (Bendat and Piersol: the complex error variance of an
H1 estimate is ``|H|^2 (1 - gamma^2) / ((n - 1) gamma^2)`` for n averages):

    r(f) = |H_ij - H_ji|^2 / (var_ij + var_ji),   mean over a band ~ 1 +- 1/sqrt(lines)

A band (of at least ``MIN_LINES`` good lines) is flagged when its mean ``r`` exceeds both
``1 + z / sqrt(lines)`` and ``MIN_R`` (the error formula is approximate for few averages) and the median
magnitude ratio or relative difference exceeds ``min_ratio_error``. A sensor calibration error ``c_i`` makes
``|H_ij / H_ji| = c_i / c_j`` at every line: with three or more struck sensor points the log ratios are
solved for every sensor's relative calibration (least squares, median sensor = 1), which names the
sensor that is off.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .frf import FRFSet
from .points import PointLabelError, parse_point

__all__ = ["ReciprocityPair", "ReciprocityResult", "reciprocity", "same_dof", "frf_error_variance",
           "default_bands", "finite_or_none"]

MIN_COHERENCE = 0.5
MIN_RATIO_ERROR = 0.03
MIN_LINES = 20
MIN_R = 3.0


def finite_or_none(x: float) -> float | None:
    """``float(x)``, or None when it is not finite (JSON has no NaN)."""
    v = float(x)
    return v if np.isfinite(v) else None


def same_dof(a: str, b: str) -> int:
    """+1 or -1 when the labels name the same point and axis (the sign of their directions' product), 0 otherwise."""
    try:
        pa, pb = parse_point(a), parse_point(b)
    except PointLabelError:
        return 0
    if (pa.component, pa.node, pa.axis) != (pb.component, pb.node, pb.axis):
        return 0
    return pa.sign * pb.sign


def frf_error_variance(frf: FRFSet) -> np.ndarray | None:
    """Complex random-error variance (FRF units^2) of each H1 line from its coherence and the number of
    averages (``meta["n_averages"]``, one per reference or one for all); None without coherence."""
    if frf.coherence is None:
        return None
    n = frf.meta.get("n_averages", 1)
    navg = np.ones(frf.n_references)
    if isinstance(n, (list, tuple)):
        vals = [float(x) if x else 1.0 for x in n]
        if len(vals) == frf.n_references:
            navg = np.asarray(vals)
    elif n:
        navg[:] = float(n)
    g = np.clip(np.asarray(frf.coherence, float), 1e-6, 1.0)
    # n - 1 degrees of freedom: the small-sample form (one average has no error estimate)
    return np.abs(frf.H) ** 2 * (1.0 - g) / (g * np.maximum(navg - 1.0, 1.0)[None, :, None])


def default_bands(freq_hz: np.ndarray, lo: float, hi: float, n_bands: int = 4) -> list[tuple[float, float]]:
    """``n_bands`` bands of equal log width from lo to hi (Hz)."""
    lo = max(lo, float(freq_hz[freq_hz > 0][0]))
    edges = np.geomspace(lo, hi, n_bands + 1)
    return [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:])]


@dataclass(frozen=True)
class ReciprocityPair:
    """One pair of points ``i`` and ``j`` (labels as outputs): per band (Hz) the mean normalised difference
    ``r`` (1 = the noise), the lines used, the median ``|H_ij / H_ji|`` and ``flagged``."""

    i: str
    j: str
    bands: tuple
    r: tuple
    lines: tuple
    ratio: tuple
    flagged: tuple

    @property
    def any_flagged(self) -> bool:
        return any(self.flagged)

    def to_dict(self) -> dict:
        return {"i": self.i, "j": self.j,
                "bands": [{"band_hz": list(b), "r": finite_or_none(r), "lines": int(n), "ratio": finite_or_none(q),
                           "flagged": bool(f)}
                          for b, r, n, q, f in zip(self.bands, self.r, self.lines, self.ratio, self.flagged)]}


@dataclass(frozen=True)
class ReciprocityResult:
    """All reciprocal pairs, the sensors' relative calibrations (None with fewer than three points) and
    the sensors whose calibration is off by more than ``min_ratio_error`` (``suspects``)."""

    pairs: tuple
    calibration: dict | None
    suspects: tuple
    verdict: str  # "reciprocal", "not reciprocal" or "no pairs"

    def to_dict(self) -> dict:
        return {"verdict": self.verdict, "pairs": [p.to_dict() for p in self.pairs],
                "calibration": None if self.calibration is None else {k: float(v) for k, v in self.calibration.items()},
                "suspects": list(self.suspects)}


def _pairs(frf: FRFSet) -> list[tuple[int, int, int, int, int]]:
    """(out_i, ref_j, out_j, ref_i, sign) for every unordered pair of distinct points both struck and measured."""
    ref_of: dict[int, tuple[int, int]] = {}
    for o, lab in enumerate(frf.outputs):
        for r, rl in enumerate(frf.references):
            s = same_dof(lab, rl)
            if s:
                ref_of[o] = (r, s)
    out = []
    keys = sorted(ref_of)
    for a_i, a in enumerate(keys):
        for b in keys[a_i + 1:]:
            (ra, sa), (rb, sb) = ref_of[a], ref_of[b]
            if np.all(np.isfinite(frf.H[a, rb])) and np.all(np.isfinite(frf.H[b, ra])):
                out.append((a, rb, b, ra, sa * sb))
    return out


def reciprocity(
    frf: FRFSet, bands: Sequence[Sequence[float]] | None = None, *, z: float = 4.0,
    min_ratio_error: float = MIN_RATIO_ERROR, min_coherence: float = MIN_COHERENCE,
) -> ReciprocityResult:
    """Compare ``H_ij`` with ``H_ji`` for every pair of points both struck and measured (module docstring).

    ``bands``: list of (lo, hi) Hz (default: :func:`default_bands` over the set's span from 2 % of its top
    line). Lines whose coherence is below ``min_coherence`` in either FRF are left out. Inputs are not modified.
    """
    f = frf.freq_hz
    if bands is None:
        hi = float(frf.meta.get("excitation_limit_hz") or f[-1]) if not isinstance(
            frf.meta.get("excitation_limit_hz"), (list, tuple)) else float(f[-1])
        bands = default_bands(f, 0.02 * hi, hi)
    var = frf_error_variance(frf)
    pairs: list[ReciprocityPair] = []
    logs: list[tuple[int, int, float]] = []
    for a, rb, b, ra, sign in _pairs(frf):
        h1, h2 = frf.H[a, rb], sign * frf.H[b, ra]
        if var is not None and frf.coherence is not None:
            v = var[a, rb] + var[b, ra]
            good = (frf.coherence[a, rb] >= min_coherence) & (frf.coherence[b, ra] >= min_coherence) & (v > 0)
        else:
            v = np.full(f.size, np.nan)
            good = np.ones(f.size, bool)
        rs, ns, qs, fl = [], [], [], []
        for lo, hi_b in bands:
            sel = good & (f >= lo) & (f <= hi_b) & (np.abs(h2) > 0)
            n = int(sel.sum())
            if n < MIN_LINES:
                rs.append(float("nan"))
                ns.append(n)
                qs.append(float("nan"))
                fl.append(False)
                continue
            r = float(np.mean(np.abs(h1[sel] - h2[sel]) ** 2 / v[sel])) if var is not None else float("nan")
            q = float(np.median(np.abs(h1[sel] / h2[sel])))
            big = abs(q - 1.0) > min_ratio_error or float(np.median(np.abs(h1[sel] - h2[sel]) / np.abs(h2[sel]))) > \
                2 * min_ratio_error
            noisy = (r > max(1.0 + z / np.sqrt(n), MIN_R)) if np.isfinite(r) else True
            rs.append(r)
            ns.append(n)
            qs.append(q)
            fl.append(bool(big and noisy))
        pairs.append(ReciprocityPair(frf.outputs[a], frf.outputs[b], tuple(tuple(map(float, bd)) for bd in bands),
                                     tuple(rs), tuple(ns), tuple(qs), tuple(fl)))
        okq = [(q, n) for q, n in zip(qs, ns) if n > 0 and np.isfinite(q)]
        if okq:
            logs.append((a, b, float(np.log(np.median([q for q, _ in okq])))))
    calibration, suspects = _calibrations(frf, logs, min_ratio_error)
    if not pairs:
        verdict = "no pairs"
    else:
        verdict = "not reciprocal" if any(p.any_flagged for p in pairs) else "reciprocal"
    return ReciprocityResult(tuple(pairs), calibration, suspects, verdict)


def _calibrations(frf: FRFSet, logs: list[tuple[int, int, float]], tol: float
                  ) -> tuple[dict | None, tuple]:
    """Relative sensor calibrations from log(c_i / c_j) of the pairs (least squares, median 1)."""
    nodes = sorted({a for a, _, _ in logs} | {b for _, b, _ in logs})
    if len(nodes) < 3:
        return None, ()
    A = np.zeros((len(logs), len(nodes)))
    y = np.zeros(len(logs))
    for k, (a, b, lr) in enumerate(logs):
        A[k, nodes.index(a)], A[k, nodes.index(b)], y[k] = 1.0, -1.0, lr
    x = np.linalg.lstsq(A, y, rcond=None)[0]
    x -= np.median(x)
    cal = {frf.outputs[n]: float(np.exp(v)) for n, v in zip(nodes, x)}
    return cal, tuple(k for k, c in cal.items() if abs(c - 1.0) > tol)
