"""Resonances the data show, independent of any fit, and whether a fitted model accounts for them.

The automatic fit (:func:`analysis.pipeline.fit_auto`) promises that every resonance the data
show is fitted, or named in a warning with ``success`` False. "Shown by the data" is this rule:

**Visible peak.** The curves are the magnitude of every FRF and the first CMIF curve
(:func:`analysis.mif.cmif`, the largest singular value of the FRF matrix per line). A local
maximum of a curve inside the band is a visible peak when

- its topographic prominence (how far it stands above the higher of its two neighbouring
  minima, :func:`analysis.peaks.prominences`) is at least ``VISIBLE_PROMINENCE_DB`` (10 dB),
- when the data carry coherence, it is at least ``VISIBLE_COHERENCE`` (0.9) over the peak's
  top (the lines within 3 dB of its maximum, and one more line on each side) in that FRF (for
  the CMIF: the median over the FRFs): a resonance is measured clean across its top, while a
  noise-level FRF shows "peaks" between random dips where the coherence of a few averages
  reaches 0.9 at single lines by chance. A top of ``VISIBLE_MIN_LINES`` lines or more (a
  resonance spans lines) is clean too when the coherence is at least 0.9 at the peak's line and
  in the mean over the top, and no line falls below ``VISIBLE_COHERENCE_FLOOR`` (0.85), or when
  it is at least 0.9 at the peak's line and on half the lines of a top of ``BROAD_TOP_LINES`` (5)
  lines or more (the median, without the line on each side): a weak mode's broad top may hold a
  line just below 0.9, and its flanks sink
  into the noise where the peak does not (:func:`_coherent_top`; noise of five averages reaches 0.9
  on one line in ten thousand, never on half of a broad top), and
- without coherence (or with the coherence of one average, 1 on every line), it is at least
  ``VISIBLE_MIN_LINES`` lines wide at 3 dB below its top (a resonance spans lines), or, one line
  wide, at least ``ONE_LINE_HALF_WIDTH_LINES`` lines wide at half its prominence (in dB): a lightly
  damped mode on coarse lines has flanks that stand above the noise, a noise spike has none. Without coherence only the CMIF curve
  is searched when there are more than ``MAX_CURVES_WITHOUT_COHERENCE`` FRFs: it averages the
  FRFs' noise, where each noisy FRF alone would show peaks of noise, and
- on one FRF of several (not on the CMIF, which has no phase, nor on a set's only FRF, which is its CMIF),
  its phase turns by at least ``VISIBLE_PHASE_TURN_DEG`` (45 degrees) across its top: a mode's phase turns
  90 degrees between its half-power points, and the top spans them; a hump between two antiresonances
  (each turns the phase the other way) turns it by a few degrees (ULiege: 15 degrees across a 12 dB hump
  at 101.5 Hz in one FRF of six, at least 75 across every resonance). A lone FRF is not judged so: a
  swept sine's FRF (the LADISK plate) turns its phase by 10-30 degrees across resonances of 20-40 dB.

The peaks of every curve are kept (a resonance shows in several curves). A resonance is the
structure's (:func:`structure_resonances`) when the CMIF shows it or at least ``STRUCTURE_MIN_SHARE``
of the FRFs do; peaks of a few FRFs of a large set are named, not counted.

**Accounted for.** Peaks of different curves within ``max(SAME_LINES df, SAME_FRACTION f)`` of
a peak of the resonance (the most prominent first) are one resonance seen through different FRFs
(a neighbouring mode shifts a peak by a few lines, the most prominent one too, so the reach is
measured from each of its peaks) when, on a set of several FRFs, their operating shapes (every FRF's
value at each peak's line) agree with a MAC of at least ``SAME_SHAPE_MAC`` (two peaks of one mode
show its shape at both lines, two close modes two shapes); two maxima of the same curve are always
two resonances. Each fitted
pole accounts for the resonance nearest to it within ``max(MATCH_FRACTION f, MATCH_LINES df)`` of
one of its peaks (the nearest resonance-pole pairs first: a pole between two resonances is the
nearer one's, whichever is more prominent). A resonance with no pole within that reach is still
accounted for when the model reproduces one of its peaks: over the peak's top (the lines within 3 dB of its maximum,
and one more on each side) the model's misfit in that curve is below ``REPRODUCED_FRACTION`` of
the data's energy and, when the coherence and the number of averages give the FRF's random error
(:func:`analysis.reciprocity.frf_error_variance`), within ``REPRODUCED_NOISE_FACTOR`` times that
error's energy over the top: a weak peak the model misses by a few per cent, many times the noise,
is not reproduced. A peak between two nearby antiresonances is such a case: the model's other
modes make it. A resonance not accounted for is *missed*; when the pole within reach was taken by
another resonance, the two are a *possible close pair* fitted as one pole.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from .frf import FRFSet
from .mac import mac
from .mif import cmif
from .modal import pole_from_fz
from .peaks import PEAK_RULES, find_peaks, peak_widths, prominences

__all__ = ["VisiblePeak", "visible_peaks", "unaccounted_peaks", "coherence_measured", "VISIBLE_PROMINENCE_DB",
           "VISIBLE_COHERENCE", "VISIBLE_COHERENCE_FLOOR",
           "MATCH_FRACTION", "MATCH_LINES", "MATCH_BANDWIDTHS", "reproduced", "resonances", "structure_resonances",
           "STRUCTURE_MIN_SHARE", "ONE_LINE_HALF_WIDTH_LINES", "n_averages", "coherence_bounds_nothing"]

VISIBLE_PROMINENCE_DB = PEAK_RULES["visible"].prominence_db
VISIBLE_COHERENCE = 0.9
VISIBLE_COHERENCE_FLOOR = 0.85
BROAD_TOP_LINES = 5
VISIBLE_MIN_LINES = 2
MAX_CURVES_WITHOUT_COHERENCE = 8
VISIBLE_PHASE_TURN_DEG = 45.0
MATCH_FRACTION = 0.005
MATCH_LINES = 1.5
MATCH_BANDWIDTHS = 1.0
STRUCTURE_MIN_SHARE = 0.05
ONE_LINE_HALF_WIDTH_LINES = 1.5
SAME_LINES = 2.5
SAME_FRACTION = 0.002
SAME_SHAPE_MAC = 0.5
REPRODUCED_FRACTION = 0.03
REPRODUCED_NOISE_FACTOR = 4.0


@dataclass(frozen=True)
class VisiblePeak:
    """A visible peak: frequency (Hz, the line of the maximum), prominence (dB), the curve it was
    found on ("CMIF" or "output/reference"), its index (the flat FRF index ``o * n_ref + r``, or
    -1 for the CMIF), and the span (lo, hi Hz) of its top (module docstring)."""

    freq_hz: float
    prominence_db: float
    curve: str
    curve_index: int
    top_hz: tuple = (0.0, 0.0)
    #: the operating shape at the peak's line: every FRF's value there (outputs x references, flattened);
    #: empty for a set of one FRF
    shape: tuple = field(default=(), compare=False, repr=False)


def _curves(frf: FRFSet, sel: np.ndarray) -> list[tuple[str, np.ndarray, np.ndarray | None]]:
    """(name, magnitude, coherence or None) of each curve searched, over the lines ``sel``."""
    n = frf.freq_hz.size
    # one average's coherence is 1 on every line and bounds nothing: the set is searched as without it
    coh = (None if coherence_bounds_nothing(frf)
           else np.asarray(frf.coherence, float).reshape(-1, n)[:, sel])
    out: list[tuple[str, np.ndarray, np.ndarray | None]] = []
    if coh is not None or frf.n_outputs * frf.n_references <= MAX_CURVES_WITHOUT_COHERENCE:
        H = np.asarray(frf.H).reshape(-1, n)[:, sel]   # only when the FRFs are searched one by one
        names = [f"{o}/{r}" for o in (frf.outputs or range(frf.n_outputs)) for r in
                 (frf.references or range(frf.n_references))]
        for k in range(H.shape[0]):
            out.append((str(names[k]) if k < len(names) else str(k), np.abs(H[k]), None if coh is None else coh[k]))
    s1 = cmif(frf)[sel, 0]
    out.append(("CMIF", s1, None if coh is None else np.median(coh, axis=0)))
    return out


def _top(db: np.ndarray, i: int, drop_db: float = 3.0) -> tuple[int, int]:
    """First and last index of the contiguous lines around ``i`` within ``drop_db`` of ``db[i]``."""
    lo = i
    while lo > 0 and db[lo - 1] >= db[i] - drop_db:
        lo -= 1
    hi = i
    while hi < db.size - 1 and db[hi + 1] >= db[i] - drop_db:
        hi += 1
    return lo, hi


def _coherent_top(coh: np.ndarray, at_peak: float, wide: bool) -> bool:
    """Whether a peak's top (``coh``: its lines and one more on each side) is measured clean: every
    line at least ``VISIBLE_COHERENCE``, or, for a top of ``VISIBLE_MIN_LINES`` lines or more, the peak's
    line that high and either the mean with no line below ``VISIBLE_COHERENCE_FLOOR``, or, for a top of
    ``BROAD_TOP_LINES`` lines or more, the median over the top's own lines (module docstring)."""
    if np.all(coh >= VISIBLE_COHERENCE):
        return True
    if not wide or at_peak < VISIBLE_COHERENCE:
        return False
    if np.mean(coh) >= VISIBLE_COHERENCE and np.min(coh) >= VISIBLE_COHERENCE_FLOOR:
        return True
    return bool(coh.size - 2 >= BROAD_TOP_LINES and np.median(coh[1:-1]) >= VISIBLE_COHERENCE)


def _phase_turn_deg(h: np.ndarray) -> float:
    """How far (degrees) the phase of the complex FRF values ``h`` (a peak's top, in frequency order) turns."""
    ph = np.unwrap(np.angle(np.asarray(h, dtype=complex)))
    return float(np.degrees(np.max(ph) - np.min(ph))) if ph.size else 0.0


def visible_peaks(frf: FRFSet, band: Sequence[float]) -> list[VisiblePeak]:
    """The visible peaks of ``frf`` in ``band`` (lo, hi Hz) of every curve, most prominent first
    (see module docstring)."""
    f_all = frf.freq_hz
    sel = np.flatnonzero((f_all >= float(band[0])) & (f_all <= float(band[1])) & np.all(
        np.isfinite(np.asarray(frf.H).reshape(-1, f_all.size)), axis=0))
    if sel.size < 3:
        return []
    f = f_all[sel]
    found: list[VisiblePeak] = []
    curves = _curves(frf, sel)
    H_sel = np.asarray(frf.H).reshape(-1, f_all.size)[:, sel]
    for ci, (name, mag, coh) in enumerate(curves):
        db = 20.0 * np.log10(np.maximum(mag, 1e-300))
        pk, _ = find_peaks(db)
        if pk.size == 0:
            continue
        prom = prominences(db, pk)
        for i, p in zip(pk, prom):
            if p < VISIBLE_PROMINENCE_DB:
                continue
            a, b = _top(db, int(i))
            wide = b - a + 1 >= VISIBLE_MIN_LINES
            if coh is None and not wide and peak_widths(db, [int(i)], 0.5)[0] < ONE_LINE_HALF_WIDTH_LINES:
                continue   # one line wide: a resonance only when its flanks stand above the noise too
            a, b = max(a - 1, 0), min(b + 1, f.size - 1)
            if coh is not None and not _coherent_top(coh[a:b + 1], float(coh[i]), wide):
                continue
            if (name != "CMIF" and H_sel.shape[0] > 1
                    and _phase_turn_deg(H_sel[ci, a:b + 1]) < VISIBLE_PHASE_TURN_DEG):
                continue   # a hump between two antiresonances in one FRF of several, not a resonance
            index = -1 if name == "CMIF" else ci
            shape = tuple(H_sel[:, i]) if H_sel.shape[0] > 1 else ()
            found.append(VisiblePeak(float(f[i]), float(p), name, index, (float(f[a]), float(f[b])), shape))
    found.sort(key=lambda v: -v.prominence_db)
    return found


def reproduced(frf: FRFSet, peak: VisiblePeak, synth: Callable[[np.ndarray], np.ndarray]) -> bool:
    """Whether a model reproduces ``peak``: its misfit over the peak's top, in the peak's curve
    (the CMIF: all FRFs), is below ``REPRODUCED_FRACTION`` of the data's energy there and, when the
    set carries coherence from more than one average, within ``REPRODUCED_NOISE_FACTOR`` times the
    energy of the random error there.
    ``synth(freq_hz)`` gives the model's FRFs (n_out, n_ref, n_f) as the data were measured."""
    f = frf.freq_hz
    sel = (f >= peak.top_hz[0]) & (f <= peak.top_hz[1])
    H = np.asarray(frf.H)[..., sel].reshape(-1, int(np.sum(sel)))
    G = np.asarray(synth(f[sel])).reshape(H.shape)
    var = _error_variance(frf)
    noise = None if var is None else var[..., sel].reshape(H.shape)
    if peak.curve_index >= 0:
        H, G = H[peak.curve_index], G[peak.curve_index]
        noise = None if noise is None else noise[peak.curve_index]
    data = float(np.sum(np.abs(H) ** 2))
    misfit = float(np.sum(np.abs(H - G) ** 2))
    if noise is not None and misfit > REPRODUCED_NOISE_FACTOR * float(np.sum(noise)):
        return False
    return data > 0 and misfit <= REPRODUCED_FRACTION * data


def n_averages(frf: FRFSet) -> np.ndarray:
    """The averages per FRF the set's metadata carries (empty when it does not say)."""
    return np.atleast_1d(np.asarray(frf.meta.get("n_averages", []) or [], dtype=float))


def coherence_bounds_nothing(frf: FRFSet) -> bool:
    """Whether ``frf``'s coherence says nothing about the noise: there is none, the set says it holds one
    average per FRF, or (the number of averages unknown, as from a file that does not state it) it is 1 on
    every line, as one average's is whatever the noise."""
    if frf.coherence is None:
        return True
    n = n_averages(frf)
    if n.size:
        return bool(np.all(n <= 1))
    c = np.asarray(frf.coherence, dtype=float)
    finite = c[np.isfinite(c)]
    return not finite.size or bool(np.all(finite >= 1.0 - 1e-9))


def coherence_measured(frf: FRFSet) -> bool:
    """Whether ``frf``'s coherence comes from more than one average, so that a visible peak (coherence at
    least ``VISIBLE_COHERENCE`` over its top) is response the force caused: a resonance, even on a mains
    harmonic (hum in the response is not coherent with the force and makes no such peak in H1)."""
    n = n_averages(frf)
    return frf.coherence is not None and n.size > 0 and bool(np.all(n > 1))


def _error_variance(frf: FRFSet) -> np.ndarray | None:
    """The random-error variance of each FRF line (:func:`analysis.reciprocity.frf_error_variance`), or
    None when the set carries no coherence or does not say it averaged more than one hit (one average
    has a coherence of 1 and no error estimate)."""
    from .reciprocity import frf_error_variance

    if not coherence_measured(frf):
        return None
    return frf_error_variance(frf)


def resonances(peaks: Sequence[VisiblePeak], df: float) -> list[list[VisiblePeak]]:
    """The visible ``peaks`` grouped by resonance, each group most prominent peak first: peaks of
    different curves within ``max(SAME_LINES df, SAME_FRACTION f, half the narrower top's half-power width)``
    of a peak of the group (each within the other's half-power band) are one resonance seen through
    different FRFs (module docstring)."""
    ordered = sorted(peaks, key=lambda v: -v.prominence_db)
    n = len(ordered)
    freq = np.array([v.freq_hz for v in ordered], dtype=float)
    width = np.array([_half_power_width(v, df) for v in ordered], dtype=float)
    group_of = np.full(n, -1, dtype=np.intp)        # the group of each peak placed so far
    groups: list[list[VisiblePeak]] = []
    curves: list[set[int]] = []
    for i, v in enumerate(ordered):
        reach = np.maximum(max(SAME_LINES * df, SAME_FRACTION * v.freq_hz), 0.5 * np.minimum(width[:i], width[i]))
        near = np.unique(group_of[:i][np.abs(freq[:i] - v.freq_hz) <= reach])   # in the order the groups began
        g = next((int(k) for k in near if v.curve_index not in curves[int(k)] and _same_shape(v, groups[int(k)][0])),
                 -1)
        if g < 0:
            g = len(groups)
            groups.append([])
            curves.append(set())
        groups[g].append(v)
        curves[g].add(v.curve_index)
        group_of[i] = g
    return groups


def _same_shape(a: VisiblePeak, b: VisiblePeak) -> bool:
    """Whether two peaks' operating shapes (every FRF at each peak's line) agree, MAC at least ``SAME_SHAPE_MAC``:
    two peaks of one mode show its shape at both lines; two close modes show two shapes. True when either peak
    carries no shape (a set of one FRF) or they lie on the same line."""
    if len(a.shape) < 2 or len(a.shape) != len(b.shape) or a.freq_hz == b.freq_hz:
        return True
    return mac(np.asarray(a.shape), np.asarray(b.shape)) >= SAME_SHAPE_MAC


def _half_power_width(v: VisiblePeak, df: float) -> float:
    """A visible peak's width (Hz) within 3 dB of its top (its ``top_hz`` less the line on each side)."""
    return max(v.top_hz[1] - v.top_hz[0] - 2.0 * df, df)


def structure_resonances(peaks: Sequence[VisiblePeak], n_frf: int, df: float
                         ) -> tuple[list[VisiblePeak], list[list[VisiblePeak]]]:
    """The visible ``peaks`` that are resonances of the structure, not of one FRF: ``(kept peaks, the
    groups left out)``. A resonance (:func:`resonances`) is the structure's when the CMIF shows it or
    at least ``STRUCTURE_MIN_SHARE`` of the ``n_frf`` FRFs do (one FRF of a small set): a hump that 1-3 of
    222 FRFs show is not a mode of the structure (the hammer point sits on a local feature, or the
    FRF is near an antiresonance)."""
    need = max(1, int(np.ceil(STRUCTURE_MIN_SHARE * int(n_frf) - 1e-9)))
    kept: list[VisiblePeak] = []
    left: list[list[VisiblePeak]] = []
    for g in resonances(peaks, df):
        if any(u.curve_index < 0 for u in g) or len({u.curve_index for u in g}) >= need:
            kept += g
        else:
            left.append(g)
    return kept, left


def unaccounted_peaks(peaks: Sequence[VisiblePeak], fitted_hz: np.ndarray, df: float,
                      is_reproduced: Callable[[VisiblePeak], bool] | None = None,
                      fitted_bandwidth_hz: np.ndarray | None = None,
                      ) -> tuple[list[VisiblePeak], list[tuple[VisiblePeak, float]]]:
    """Visible peaks the fitted natural frequencies ``fitted_hz`` (Hz) leave unaccounted for:
    ``(missed, pairs)``; ``pairs`` holds (peak, frequency of the pole it would share with another
    resonance). ``is_reproduced(peak)`` (e.g. :func:`reproduced` with the model) tells whether
    the model makes a peak without a pole of its own. ``fitted_bandwidth_hz``: each pole's half-power
    bandwidth ``2 zeta f`` (Hz, as the data show it), widening its reach to ``MATCH_BANDWIDTHS`` of it.
    See module docstring."""
    groups = resonances(peaks, df)
    poles = [float(x) for x in np.asarray(fitted_hz, float).ravel()]
    bws = (np.zeros(len(poles)) if fitted_bandwidth_hz is None
           else np.asarray(fitted_bandwidth_hz, float).ravel())
    free = list(range(len(poles)))

    def reach(gi: int, k: int) -> float:
        """How far pole ``k`` reaches to account for resonance ``gi`` (Hz): a fixed fraction or a few
        lines, or within the pole's half-power bandwidth (a neighbouring mode shifts an FRF's peak by up
        to that much)."""
        return max(MATCH_FRACTION * groups[gi][0].freq_hz, MATCH_LINES * df, MATCH_BANDWIDTHS * float(bws[k]))
    # each pole goes to the resonance nearest to it (the nearest pairs first), not to the most
    # prominent resonance within reach: a pole between two resonances is the nearer one's
    links = sorted((min(abs(poles[k] - u.freq_hz) for u in g), gi, k) for gi, g in enumerate(groups)
                   for k in free if min(abs(poles[k] - u.freq_hz) for u in g) <= reach(gi, k))
    owner: dict[int, int] = {}
    for _, gi, k in links:
        if gi not in owner and k not in owner.values():
            owner[gi] = k
    free = [k for k in free if k not in owner.values()]
    missed: list[VisiblePeak] = []
    pairs: list[tuple[VisiblePeak, float]] = []
    for gi, g in enumerate(groups):
        v = g[0]
        if gi in owner:
            continue
        taken = [x for k, x in enumerate(poles) if k not in free and abs(x - v.freq_hz) <= reach(gi, k)]
        if taken:
            if is_reproduced is None or not all(is_reproduced(u) for u in g):
                pairs.append((v, min(taken, key=lambda x: abs(x - v.freq_hz))))
        elif is_reproduced is None or not any(is_reproduced(u) for u in g):
            missed.append(v)
    return missed, pairs


def peak_poles(peaks: Sequence[VisiblePeak], df: float, damping: float | None = None,
               pole_shift: float = 0.0) -> np.ndarray:
    """One starting pole (rad/s, sorted by frequency) per distinct frequency of ``peaks`` (visible
    peaks, most prominent first) at the peak's line.

    Its damping is ``damping`` (a ratio: the median of the modes the diagram selected, without the
    exponential window's decay) with the window's decay ``pole_shift`` (1/s,
    :func:`analysis.frf.window_pole_shift`) added, as the data show it: the window broadens a low
    mode far more than the modes the median comes from (the frame's 12.9 Hz at 0.86 % shows 3.8 %
    through a window to 5 % at the end of a 1.28 s record). Without ``damping``: the damping the
    peak's own half-power width gives (``zeta = w / (2 f)``, ``w`` the width of its top within
    3 dB, at least a line; at most ``MAX_START_DAMPING``); the width is the fallback only, since a
    mode narrower than a few lines (the frame's 12.9 Hz, 0.22 Hz wide on 0.78 Hz lines) shows the
    line spacing and leakage there. Not the diagram's poles near the peak: it has no stable pole
    where it missed a mode, and the poles of its higher orders there are mathematical ones
    (damping 0.001 %, or none); an LSFD started from those leaves them on the edge of their
    damping trust region and drops them."""
    seen: dict[float, VisiblePeak] = {}
    for v in peaks:
        seen.setdefault(v.freq_hz, v)
    freqs = np.array(sorted(seen))
    if damping is not None:
        return pole_from_fz(freqs, np.full(freqs.size, float(damping))) - float(pole_shift)
    widths = np.array([max(seen[x].top_hz[1] - seen[x].top_hz[0] - df, df) for x in freqs])
    return pole_from_fz(freqs, np.minimum(widths / (2.0 * freqs), MAX_START_DAMPING))


#: the largest damping ratio a start from a peak's half-power width takes
MAX_START_DAMPING = 0.05
