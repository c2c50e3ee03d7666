"""The frequency band of a fit (the paper's sec. 3.1): the default band from the data, the band
edges kept off resonances, and lines left out (mains harmonics).

The default band runs from the lowest reliable line (past the lowest ``LOW_LINES`` lines and any
leading low-coherence lines) to the top of what the data support (:func:`default_band`): the
analyser's flat band ``fs / 2.56``, the hammer's excitation band (force spectrum 20 dB down) and
the coherence (:func:`upper_limits`), so no pole is fitted to lines the data cannot support; an
edge the coherence sets takes a resonance whole or not at all (:func:`_coherence_edge_off_peak`).
FRFs without force spectra and without an informative coherence (a UFF export of single hits, an
analyser's FRFs alone) are bounded by their own noise floor (:func:`noise_limit_hz`).
"""
from __future__ import annotations

import logging
import warnings
from collections.abc import Sequence
from dataclasses import replace
from math import comb

import numpy as np

from .errors import FitError
from .frf import FRFSet
from .modal import damping_ratio, natural_freq_hz
from .peaks import PEAK_RULES
from .spectra import EXCITATION_DROP_DB
from .visibility import coherence_bounds_nothing, n_averages

__all__ = ["FitError", "default_band", "upper_limits", "unsupported_band_text", "measured_up_to",
           "MEASURED_LIMITS", "default_max_modes", "check_band_edges", "mains_harmonics", "exclude_lines",
           "mains_harmonic_index", "harmonic_tolerance_hz", "MAINS_HZ", "noise_limit_hz", "coherence_informative"]

log = logging.getLogger(__name__)


LOW_LINES = 5
MIN_COHERENCE = 0.8
EDGE_BANDWIDTHS = 3.0
EXCLUDE_LINES = 2.0
#: mains frequencies (Hz) whose harmonics may carry electrical lines
MAINS_HZ = (50.0, 60.0)
#: a frequency within this many lines (or k x MAINS_DEVIATION_HZ at harmonic k) of a harmonic is on it
MAINS_LINES = 2.0
MAINS_DEVIATION_HZ = 0.1
#: lines of the band per mode of the stabilization's largest model (LSCE needs more than 10)
LINES_PER_MODE = 11
#: median coherence below which the top of the band is no longer supported (after smoothing)
TAIL_COHERENCE = 0.5
#: running-mean length of the coherence, as a fraction of the lines
COHERENCE_SMOOTH_FRACTION = 0.02
#: median coherence over a resonance's half-power band that still lets a coherence edge take it in whole
TOP_COHERENCE = 0.25
#: prominence (dB) of a peak of the summed FRF power that a coherence edge must not cut
EDGE_PEAK_DB = PEAK_RULES["band_edge"].prominence_db
#: running-mean length (dB) of the summed FRF power for the edge's peaks, as a fraction of the lines
POWER_SMOOTH_FRACTION = 0.001
#: the FRFs' noise floor is taken over blocks of this fraction of the lines (at least NOISE_MIN_LINES)
NOISE_BLOCK_FRACTION = 0.01
NOISE_MIN_LINES = 15
#: order of the line-to-line differences the noise floor is estimated from (a third difference
#: leaves a resonance a few lines wide nearly untouched, and passes white noise at sqrt(20) times its level)
NOISE_DIFF_ORDER = 3
#: a block's response stands above the noise when its median magnitude is this many dB above the floor
NOISE_SNR_DB = 10.0
#: a block's differences are noise when those of the next order are at least this many times larger
#: (white noise: sqrt(C(2k+2, k+1) / C(2k, k)), 1.87 for k = 3; a smooth FRF: well below 1)
NOISE_LIKE_RATIO = 1.2
#: the floor's rise must hold over this many blocks in a row (a resonance a few lines wide lifts one or two)
NOISE_RISE_BLOCKS = 3
#: a noise floor this far below the FRF's median magnitude is no noise at all (exact synthetic data, rounding)
NOISE_RELATIVE_MIN = 1e-9


def upper_limits(frf: FRFSet) -> dict[str, float]:
    """What bounds the band from above, from the data (Hz per reason):

    - ``"data"``: the top line;
    - ``"analyser"``: the analyser's flat, alias-free band ``sample_rate_hz / 2.56`` (when the FRF
      set carries its sample rate);
    - ``"excitation"``: where the force spectrum has fallen ``EXCITATION_DROP_DB`` below its
      low-frequency level (the lowest over the measurement points; from the recording's force
      autospectra, :func:`analysis.spectra.excitation_limit_hz`);
    - ``"coherence"``: where the median coherence over the FRFs (a running mean over
      ``COHERENCE_SMOOTH_FRACTION`` of the lines) falls below ``TAIL_COHERENCE`` for good
      (only when it is informative: :func:`coherence_informative`);
    - ``"noise"``: only without force spectra and without an informative coherence: where the
      FRFs' own noise floor ends the band (:func:`noise_limit_hz`).
    """
    f = frf.freq_hz
    out = {"data": float(f[-1])}
    if frf.analyser_band_hz is not None:
        out["analyser"] = float(frf.analyser_band_hz)
    exc = [float(x) for x in np.atleast_1d(np.asarray(frf.meta.get("excitation_limit_hz") or [], dtype=object))
           if x is not None and np.isfinite(float(x))]
    if exc:
        out["excitation"] = min(exc)
    informative = coherence_informative(frf)
    if informative and f.size >= 16:
        c = np.nanmedian(np.asarray(frf.coherence).reshape(-1, f.size), axis=0)
        n = max(5, int(COHERENCE_SMOOTH_FRACTION * f.size))
        smooth = np.convolve(np.nan_to_num(c), np.ones(n) / n, mode="same")
        good = np.flatnonzero(smooth >= TAIL_COHERENCE)
        if good.size and good[-1] < f.size - 1:
            out["coherence"] = float(f[good[-1]])
    if not exc and not informative:
        noise = noise_limit_hz(frf)
        if noise is not None:
            out["noise"] = noise
    return out


#: the upper limits (keys of :func:`upper_limits`) beyond which a hit measures nothing: the hammer's
#: excitation and the analyser's flat band (the coherence's edge is a judgement of the data, not such a limit)
MEASURED_LIMITS = ("excitation", "analyser")


def measured_up_to(limits: dict[str, float]) -> float | None:
    """The highest frequency (Hz) a hit measures, from :func:`upper_limits`: the lowest of
    :data:`MEASURED_LIMITS` known, or None when neither is."""
    known = [v for k, v in limits.items() if k in MEASURED_LIMITS]
    return min(known) if known else None


def unsupported_band_text(hi_hz: float, limits: dict[str, float], where: str = "the structure",
                          continuous: bool = False) -> str | None:
    """The one rule for a band that reaches above what a hit measures: the hammer's excitation
    (``limits["excitation"]``, the force spectrum ``EXCITATION_DROP_DB`` down; with ``continuous`` a shaker's
    continuous excitation, whose band ends there) or the analyser's flat band (``limits["analyser"]``) below
    the band's top ``hi_hz`` (Hz). Returns the warning (what limits the band, what to do) or None when the
    band stays within both. ``where`` names the struck point(s)."""
    tol = 1e-9 * abs(hi_hz)
    exc, ana = limits.get("excitation"), limits.get("analyser")
    parts = []
    if exc is not None and exc < hi_hz - tol:
        parts.append(f"the excitation's band ends at {exc:.0f} Hz" if continuous
                     else f"the hammer excites {where} only up to {exc:.0f} Hz")
    if ana is not None and ana < hi_hz - tol:
        parts.append(f"the analyser's flat band ends at {ana:.0f} Hz")
    if not parts:
        return None
    top = measured_up_to(limits)
    remedy = "excite a wider band" if continuous else "use a harder tip"
    return (f"{' and '.join(parts)}, below the band's top {hi_hz:.0f} Hz: modes above {top:.0f} Hz are not measured "
            f"well (fit below {top:.0f} Hz, or {remedy})")


def coherence_informative(frf: FRFSet) -> bool:
    """Whether the coherence of ``frf`` says anything about the noise: the set carries one, it is not
    1 on every line, and the set does not say it holds one average per FRF (the coherence of a single
    hit is 1 whatever the noise)."""
    return not coherence_bounds_nothing(frf)


def noise_limit_hz(frf: FRFSet) -> float | None:
    """The top of the band (Hz) from the FRFs' own noise floor, for FRFs that carry neither force
    spectra nor an informative coherence; None when the noise bounds nothing.

    The lines are cut in blocks of ``NOISE_BLOCK_FRACTION`` of the lines (at least
    ``NOISE_MIN_LINES``; an edge is interpolated between the blocks' middles). Per FRF and block:

    - the *noise floor*: the median magnitude of the ``NOISE_DIFF_ORDER``-th line-to-line
      difference ``k`` of the complex FRF, scaled to the noise per line (``/ sqrt(C(2k, k) ln 2)``,
      the RMS of complex noise): a resonance is smooth over its bandwidth and its differences are
      small, noise is not; floored at ``NOISE_RELATIVE_MIN`` of the FRF's median magnitude. A block
      counts only where its differences are noise's: those of order ``k + 1`` at least
      ``NOISE_LIKE_RATIO`` times those of order ``k`` (noise grows with the order, a smooth FRF
      shrinks); elsewhere the FRF is cleaner than the differences can tell and stands above its noise;
    - the *level*: the block's median magnitude.

    Two limits, the lower one is taken:

    - **the structure drowns**: the band ends with the last block whose level (median over the FRFs)
      stands ``NOISE_SNR_DB`` above its noise floor; above it the FRFs are noise;
    - **the force has ended** (FRFs that say they hold one average each, where the coherence is 1 and
      cannot show it): an H1 estimate's noise is the response's noise over the force spectrum, so its
      floor rises as the force falls. The band ends where the floor first stands ``EXCITATION_DROP_DB``
      (the force spectrum's rule, :func:`analysis.spectra.excitation_band`) above its lowest level at
      lower frequencies (median rise over the FRFs) and stays so for ``NOISE_RISE_BLOCKS`` blocks.
      The response's noise is additive: its floor changes less from block to block than its ratio to
      the FRF's level. Where the ratio is the steadier one (noise relative to the FRF, as noise on the
      force gives), the ratio's rise is taken instead: a floor that only follows the FRF's
      resonances and antiresonances says nothing about the force.
      On the LADISK beam's single hit exported to UFF the floor tracks the force within a few dB
      and ends the band at 6.67 kHz; the force is 20 dB down at 6.42 kHz.

    FRFs whose averages are not stated (an analyser's export) are not cut by the rise: their span is
    the operator's choice, and their modes stand 10-20 dB clear of a floor that rises 30 dB (ModeLAB's
    beam).
    """
    f = frf.freq_hz
    n = f.size
    k = NOISE_DIFF_ORDER
    w = max(NOISE_MIN_LINES, int(NOISE_BLOCK_FRACTION * n))
    start = LOW_LINES
    n_blocks = (n - start - k) // w
    if n_blocks < 3:
        return None
    H = np.asarray(frf.H).reshape(-1, n)
    mag_all = np.where(np.isfinite(H), np.abs(H), np.nan)   # a non-finite line (0/0 at DC) is left out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)   # an FRF of NaN only: left out below
        typical = np.nanmedian(mag_all, axis=1, keepdims=True)   # not the RMS: one line near a force zero can be huge
    keep = np.isfinite(typical[:, 0]) & (typical[:, 0] > 0)
    if not np.any(keep):
        return None
    H, mag_all, typical = H[keep], mag_all[keep], typical[keep]
    shape = (H.shape[0], n_blocks, w)
    dk = np.abs(np.diff(H[:, start:], n=k, axis=1))[:, :n_blocks * w].reshape(shape)
    dk1 = np.abs(np.diff(H[:, start:], n=k + 1, axis=1))[:, :n_blocks * w].reshape(shape)
    mag = mag_all[:, start + k // 2:start + k // 2 + n_blocks * w].reshape(shape)
    with np.errstate(divide="ignore", invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)   # an all-NaN block: its floor is NaN, not counted
        med_k, med_k1 = np.nanmedian(dk, axis=2), np.nanmedian(dk1, axis=2)
        # the noise per line (RMS): the median of a complex Gaussian's magnitude is sqrt(ln 2) of its RMS
        floor = np.fmax(med_k / np.sqrt(comb(2 * k, k) * np.log(2.0)), NOISE_RELATIVE_MIN * typical)
        # a block whose differences are not noise's (smoother than noise: the floor lies below what they show)
        noise_like = med_k1 >= NOISE_LIKE_RATIO * med_k
        floor_db = np.where(noise_like, 20.0 * np.log10(floor), np.nan)
        level_db = 20.0 * np.log10(np.fmax(np.nanmedian(mag, axis=2), NOISE_RELATIVE_MIN * typical))
    centre = f[start + k // 2 + np.arange(n_blocks) * w + w // 2]   # each block's middle line (Hz)
    edges: list[float] = []
    snr = np.nan_to_num(_nanmedian0(level_db - floor_db), nan=np.inf)   # no noise seen: the response stands above it
    above = np.flatnonzero(snr >= NOISE_SNR_DB)
    if above.size and above[-1] < n_blocks - 1:
        edges.append(_crossing(centre, snr, int(above[-1]), NOISE_SNR_DB))
    n_avg = n_averages(frf)
    if n_avg.size and np.all(n_avg <= 1):
        noise_db = floor_db
        if _roughness_db(floor_db - level_db) < _roughness_db(floor_db):
            noise_db = floor_db - level_db   # relative noise (the floor follows the FRF): its ratio to the FRF rises
        lowest = np.fmin.accumulate(np.where(np.isnan(noise_db), np.inf, noise_db), axis=1)
        rise = np.nan_to_num(_nanmedian0(noise_db - lowest), nan=-np.inf)
        up = rise >= EXCITATION_DROP_DB
        runs = np.flatnonzero(np.convolve(up, np.ones(NOISE_RISE_BLOCKS, dtype=int), mode="valid") == NOISE_RISE_BLOCKS)
        if runs.size and runs[0] > 0:
            edges.append(_crossing(centre, rise, int(runs[0]) - 1, EXCITATION_DROP_DB))
    if not edges:
        return None
    log.info("the FRFs' noise floor ends the band at %.6g Hz", min(edges))
    return min(edges)


def _nanmedian0(x: np.ndarray) -> np.ndarray:
    """The median over axis 0 without NaN values (NaN where a column holds nothing else), silently."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.asarray(np.nanmedian(x, axis=0))


def _roughness_db(x_db: np.ndarray) -> float:
    """How much ``x_db`` (n_frf, n_blocks; dB, NaN for no value) changes from block to block: the median
    over the FRFs of the median absolute step (dB)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return float(np.nanmedian(np.nanmedian(np.abs(np.diff(x_db, axis=1)), axis=1)))


def _crossing(x: np.ndarray, y: np.ndarray, j: int, level: float) -> float:
    """Where ``y`` crosses ``level`` between samples ``j`` and ``j + 1`` (linear in ``x``)."""
    y0, y1 = float(y[j]), float(y[j + 1])
    t = (level - y0) / (y1 - y0) if y1 != y0 else 0.0
    return float(x[j] + (x[j + 1] - x[j]) * min(max(t, 0.0), 1.0))


def default_band(frf: FRFSet) -> tuple[float, float]:
    """Default band (Hz) from what the data support: from the lowest reliable line (past the lowest
    ``LOW_LINES`` lines and leading low-coherence lines) to the lowest of :func:`upper_limits`
    (the analyser's band, the hammer's excitation band, the coherence, the FRFs' noise floor), never
    narrower than 16 lines."""
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
    lo_line = float(f[f >= lo - 1e-9 * abs(lo)][0])
    limits = upper_limits(frf)
    hi = min(limits.values())
    hard = min(v for k, v in limits.items() if k != "coherence")   # the noise limit is hard too
    if hi < hard:   # the coherence ends the band: not on a resonance's flank
        hi = _coherence_edge_off_peak(frf, lo_line, hi, hard)
    i_lo = int(np.searchsorted(f, lo_line))
    hi = max(hi, float(f[min(i_lo + 15, f.size - 1)]))
    hi_line = float(f[f <= hi + 1e-9 * abs(hi)][-1])
    return lo_line, hi_line


def _coherence_edge_off_peak(frf: FRFSet, lo: float, hi: float, cap: float) -> float:
    """The band's upper edge ``hi`` (Hz), set by the coherence, moved off the flank of a resonance;
    ``lo`` is the band's lower edge and ``cap`` the highest the other limits (analyser, excitation,
    data) allow (Hz).

    The coherence's edge falls where the coherence fades, and it often fades on the flank of a mode
    near the top of the excitation: the fit would see half a resonance, whose pole is biased (the
    paper's sec. 3.1, Fig. 4), or leave the mode to the upper residual while it pulls its neighbours.
    A modal-test engineer takes a mode in whole or not at all, so an edge within ``EDGE_BANDWIDTHS``
    half-power bandwidths of a peak of the summed FRF power (a running mean over
    ``POWER_SMOOTH_FRACTION`` of the lines, in dB, standing ``EDGE_PEAK_DB`` above its minima; the
    bandwidth: its lines within 3 dB of its top, at most 10 % of its frequency) moves ``EDGE_BANDWIDTHS``
    bandwidths (the margin :func:`check_band_edges` asks of a fitted mode)

    - past the peak, only when the whole margin fits under ``cap`` (a margin the data's end cuts short
      keeps the mode on the flank the move was to take it off; the mode is then left out whole as below:
      the UNESP beam's 478.1 Hz mode at 0.30 V, 11.3 Hz wide at the edge's reckoning, would need the band
      to 512.06 Hz, its fitted pole's 12 Hz to 514.3 Hz, and the data end at 512 Hz), when
      the median coherence over the peak's half-power band is at least ``TOP_COHERENCE``, and so is it
      over the peak's own lines (the smoothing's width: a narrow line the measured input does not explain,
      such as a mains harmonic in the response, has a coherence near 0 there, the UNESP beam's 480 Hz,
      8 x 60 Hz, 0.01-0.14, under a broad hump of 0.36): the
      resonance lifts the response out of the noise where the coherence fades around it, and the
      averages leave a random error (for H1 of ``n`` averages ``sqrt((1 - g^2) / (2 n g^2))`` of the
      FRF per line) that the fit spreads over the mode's many lines;
    - before the peak otherwise: the mode is left out (the residual terms take it), as long as the
      band keeps 16 lines.

    The lower edge is not moved here: below it lie the lines the module's docstring leaves out
    (record length, high-pass filters), and a mode near it is kept off the edge from its fitted pole
    (:func:`check_band_edges`). Neither are the analyser's band, the excitation band and the end of
    the data: they are hard limits.
    """
    if frf.coherence is None:
        return hi
    f = frf.freq_hz
    n = f.size
    db = _summed_power_db(frf.H.reshape(-1, n))
    w = max(3, int(POWER_SMOOTH_FRACTION * n)) | 1
    db = np.convolve(np.pad(db, w // 2, mode="edge"), np.ones(w) / w, mode="valid")
    peaks, _ = PEAK_RULES["band_edge"].find(db)
    near = []
    for p in peaks[np.abs(hi - f[peaks]) < EDGE_BANDWIDTHS * 0.1 * f[peaks]]:   # bandwidths <= 10 % of f
        a, b = int(p), int(p)   # the peak's flanks down to EDGE_PEAK_DB below its top (within its bases)
        while a > 0 and db[a] > db[p] - EDGE_PEAK_DB:
            a -= 1
        while b < n - 1 and db[b] > db[p] - EDGE_PEAK_DB:
            b += 1
        top = a + np.flatnonzero(db[a:b + 1] >= db[p] - 3.0)   # its half-power lines (a noise dip does not end them)
        a, b = int(top[0]), int(top[-1])
        bw = max(float(top.size) * frf.line_spacing_hz, frf.line_spacing_hz)
        if bw <= 0.1 * f[p] and abs(hi - f[p]) < EDGE_BANDWIDTHS * bw:
            near.append((abs(hi - f[p]), int(p), a, b, bw))
    if not near:
        return hi
    _, p, a, b, bw = min(near)
    median_coh = np.nanmedian(np.asarray(frf.coherence).reshape(-1, n), axis=0)
    coh = median_coh[a:b + 1]
    i_past = int(np.searchsorted(f, f[p] + EDGE_BANDWIDTHS * bw, side="right")) - 1
    i_before = int(np.searchsorted(f, f[p] - EDGE_BANDWIDTHS * bw))
    i_lo = int(np.searchsorted(f, lo)) + 15
    # the peak's own lines (the smoothing's width) must be coherent too: a narrow line there that the input does not
    # explain (a mains harmonic in the response, coherence near 0 on its lines) is no resonance to take whole
    core = median_coh[max(p - w // 2, 0):p + w // 2 + 1]
    lifted = float(np.nanmedian(core)) >= TOP_COHERENCE
    if float(np.nanmedian(coh)) >= TOP_COHERENCE and lifted and f[p] + EDGE_BANDWIDTHS * bw <= cap and i_past > b:
        new = float(f[i_past])
    elif max(i_before, i_lo) < a:
        new = float(f[max(i_before, i_lo)])
    else:
        return hi
    log.info("band edge %.6g Hz moved to %.6g Hz off the resonance at %.6g Hz", hi, new, f[p])
    return new

def _summed_power_db(H: np.ndarray) -> np.ndarray:
    """10 log10 of the summed power of the FRFs ``H`` (n_frf, n_lines) per line (dB re 1 unit of H squared),
    NaN values left out, floored 240 dB below the largest line. Summed in place (einsum): a large set
    makes no squared copy."""
    p2 = np.einsum("ij,ij->j", H.real, H.real) + np.einsum("ij,ij->j", H.imag, H.imag)
    if not np.all(np.isfinite(p2)):
        p2 = np.nansum(H.real ** 2 + H.imag ** 2, axis=0)
    return 10.0 * np.log10(np.maximum(p2, np.max(p2) * 1e-24 + 1e-300)) if p2.size else p2


def default_max_modes(frf: FRFSet, band: tuple[float, float]) -> int:
    """Largest model size for the stabilization: ``2 * peaks + 8`` clipped to [12, 60], where
    ``peaks`` counts the peaks of the summed FRF magnitude (dB) with 3 dB prominence in ``band``,
    and never more than the band's lines support (``lines // LINES_PER_MODE``: LSCE's Hankel
    matrix needs more than ten lines per mode)."""
    sel = (frf.freq_hz >= band[0]) & (frf.freq_hz <= band[1])
    i = np.flatnonzero(sel)
    H = frf.H[..., i[0]:i[-1] + 1].reshape(-1, i.size) if i.size else frf.H[..., sel].reshape(-1, 0)
    peaks, _ = PEAK_RULES["mode_count"].find(_summed_power_db(H))
    return int(max(1, min(np.clip(2 * peaks.size + 8, 12, 60), int(sel.sum()) // LINES_PER_MODE)))


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


def harmonic_tolerance_hz(k: int, df: float) -> float:
    """How far (Hz) a line may lie from the k-th mains harmonic and still be on it: ``MAINS_LINES``
    line spacings ``df`` (Hz) or the grid's frequency deviation ``k MAINS_DEVIATION_HZ``."""
    return max(MAINS_LINES * float(df), k * MAINS_DEVIATION_HZ)


def mains_harmonic_index(freq_hz: float, mains: Sequence[float], df: float) -> tuple[int, float] | None:
    """``(k, m)`` when ``freq_hz`` lies on the k-th harmonic of the mains frequency ``m`` (Hz), within
    :func:`harmonic_tolerance_hz`; else None."""
    for m in mains:
        k = int(round(float(freq_hz) / m))
        if k >= 1 and abs(freq_hz - k * m) <= harmonic_tolerance_hz(k, df):
            return k, float(m)
    return None

