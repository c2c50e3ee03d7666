"""Effects that live in the time data of the hits: ``double_hit``, ``overload``, ``input_noise``,
``amplitude_nonlinearity``.

Pure functions over arrays: ``force[n_hits, n]`` (N), ``responses[n_hits, n_out, n]`` (EU), sample rate
``fs_hz``. The ``detect_*`` functions return a cause dict ``{"effect", "parameters", "present",
"evidence"}`` measured from the hits themselves (a count, or a shift against its own scatter).
:func:`analysis.diagnosis.timedata_gain.diagnose_time_effects` adds, for each effect, the error of
the linear simulation before and after re-simulating the effect (nonlinearity, input noise) or
excluding the affected hits (overload, double hit), and the gain on held-out frequency lines, as the
FRF effects (``docs/diagnosis.md``).

Definitions
-----------
* pulse: the contiguous run around the force peak ``n_pk`` where ``s f >= 0.1 |F_pk|`` (``s`` the sign
  of the peak);
* double hit: after the pulse end plus a guard of one pulse width, the largest same-sign force exceeds
  10 % of ``|F_pk|``; parameters: fraction of hits, median delay (s) and ratio of the second pulse;
* overload: a channel at >= 99.9 % of its full scale (or the analyser's flag); parameter: fraction;
* input noise: the force channel's noise ``sigma_n`` (N rms, from the samples before the pulse) biases
  H1 low by ``S_ff / (S_ff + S_nn)`` with ``S_nn = sigma_n^2 n`` (rectangular window, same FFT
  scaling as ``|F(f)|^2``); parameter: ``sigma_n`` and the worst bias (dB) in the band;
* amplitude nonlinearity: hits split at the median force peak; H1 of each group; the resonance peaks
  of the summed |H1| paired between groups; parameter: the frequency change per mode (%) between the
  force levels. The scatter reference is the same computation between the odd and even hits of the
  low group; present when the mean |shift| exceeds 3 x that scatter + 0.05 %.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..peaks import PEAK_RULES

__all__ = ["pulse_bounds", "detect_double_hit", "detect_overload", "detect_input_noise",
           "detect_amplitude_nonlinearity", "diagnose_hits", "Hits", "TimeEffect", "TIME_EFFECTS", "FORCE_WINDOW_S",
           "FORCE_TAPER_S"]

PULSE_LEVEL = 0.1
NOISE_GUARD = 32
DOUBLE_HIT_MAX_DELAY_S = 0.05
FORCE_WINDOW_S = 0.0015       # force window after the pulse start used to judge double hits (s)
FORCE_TAPER_S = 0.0005        # its cosine taper (s)


def pulse_bounds(force: np.ndarray, level: float = PULSE_LEVEL) -> tuple[int, int, int]:
    """(start, peak, end) sample indices of the main pulse of one force record (end exclusive)."""
    f = np.asarray(force, float)
    k = int(np.argmax(np.abs(f)))
    s = np.sign(f[k]) or 1.0
    thr = level * abs(f[k])
    a = k
    while a > 0 and s * f[a - 1] >= thr:
        a -= 1
    b = k + 1
    while b < f.size and s * f[b] >= thr:
        b += 1
    return a, k, b


def _check_hits(force: np.ndarray) -> np.ndarray:
    f = np.asarray(force, float)
    if f.ndim != 2 or f.shape[1] < 16:
        raise ValueError(f"force must be (n_hits, n_samples) with >= 16 samples; got shape {f.shape}")
    return f


def _pre_noise(x: np.ndarray, a: int, guard: int = NOISE_GUARD) -> float | None:
    """Standard deviation (N) of the samples before ``a - guard`` (None with fewer than 8 of them)."""
    pre = x[:max(a - guard, 0)]
    return float(np.std(pre)) if pre.size >= 8 else None


def detect_double_hit(force: np.ndarray, fs_hz: float, fraction: float = 0.1,
                      max_delay_s: float = DOUBLE_HIT_MAX_DELAY_S) -> dict:
    """Double hits (module docstring): fraction of hits, median delay_s and ratio of the second pulse.

    The second pulse is searched up to ``max_delay_s`` after the first peak; it must exceed both
    ``fraction`` x the peak and 5 x the force noise of the pre-trigger samples (so noise alone does
    not make a double hit)."""
    f = _check_hits(force)
    delays, ratios, hits = [], [], []
    for i, x in enumerate(f):
        a, k, b = pulse_bounds(x)
        s = np.sign(x[k]) or 1.0
        start = b + (b - a)
        stop = min(x.size, k + int(round(max_delay_s * fs_hz)) + 1)
        if start >= stop:
            continue
        j = start + int(np.argmax(s * x[start:stop]))
        r = s * x[j] / abs(x[k])
        sn = _pre_noise(x, a) or 0.0
        if r > fraction and s * x[j] > 5 * sn:
            hits.append(i)
            delays.append((j - k) / fs_hz)
            ratios.append(float(r))
    frac = len(hits) / f.shape[0]
    params = {"fraction": frac, "delay_s": float(np.median(delays)) if delays else None,
              "ratio": float(np.median(ratios)) if ratios else None, "hits": hits}
    ev = (f"{len(hits)} of {f.shape[0]} hits struck twice (median delay {params['delay_s'] * 1e3:.2f} ms, "
          f"second pulse {100 * params['ratio']:.0f} %)" if hits else f"no double hit in {f.shape[0]} hits")
    return {"effect": "double_hit", "parameters": params, "present": bool(hits), "evidence": ev}


def detect_overload(data: np.ndarray, full_scale: Sequence[float] | None = None,
                    flags: np.ndarray | None = None) -> dict:
    """Overloaded hits: ``data[n_hits, n_ch, n]`` at >= 99.9 % of ``full_scale[n_ch]`` (EU), or ``flags``."""
    d = np.asarray(data, float)
    if flags is not None:
        over = np.asarray(flags, bool).reshape(d.shape[0], -1)
    elif full_scale is not None:
        fs = np.asarray(full_scale, float).reshape(1, -1, 1)
        over = np.any(np.abs(d) >= 0.999 * fs, axis=2)
    else:
        raise ValueError("detect_overload needs the channels' full scale (EU) or the analyser's overload flags")
    hits = [int(i) for i in np.flatnonzero(over.any(axis=1))]
    chans = [int(c) for c in np.flatnonzero(over.any(axis=0))]
    ev = f"{len(hits)} of {d.shape[0]} hits overloaded (channels {chans})" if hits else "no overload"
    return {"effect": "overload", "parameters": {"fraction": len(hits) / d.shape[0], "hits": hits, "channels": chans},
            "present": bool(hits), "evidence": ev}


def detect_input_noise(force: np.ndarray, fs_hz: float, band: Sequence[float] | None = None,
                       max_bias_db: float = 0.5, guard: int = NOISE_GUARD) -> dict:
    """Force-channel noise and the H1 bias it causes (module docstring). The noise is the rms of the
    samples up to ``guard`` samples before the pulse start (an anti-alias filter rings before a pulse)."""
    f = _check_hits(force)
    n = f.shape[1]
    noise, sff = [], []
    for x in f:
        a, _, _ = pulse_bounds(x)
        sd = _pre_noise(x, a, guard)
        if sd is not None:
            noise.append(sd)
        sff.append(np.abs(np.fft.rfft(x)) ** 2)
    if not noise:
        raise ValueError("input noise needs pre-trigger samples before the pulse (none in these hits)")
    sigma = float(np.sqrt(np.mean(np.square(noise))))
    freq = np.fft.rfftfreq(n, 1 / fs_hz)
    S = np.mean(sff, axis=0)
    snn = sigma ** 2 * n
    bias = 10 * np.log10(S / (S + snn))
    sel = np.ones(freq.size, bool) if band is None else (freq >= band[0]) & (freq <= band[1])
    k = int(np.argmin(np.where(sel, bias, 0.0)))
    worst = float(bias[k])
    present = -worst > max_bias_db
    ev = (f"force noise {sigma:.3g} N rms biases H1 by {worst:.2f} dB at {freq[k]:.4g} Hz"
          + (" (use H2 or a harder tip / stronger hits there)" if present else ""))
    return {"effect": "input_noise", "parameters": {"noise_rms_n": sigma, "worst_bias_db": worst,
                                                    "at_hz": float(freq[k])}, "present": bool(present), "evidence": ev}


def _h1_peaks(force: np.ndarray, resp: np.ndarray, fs_hz: float, band: Sequence[float]) -> np.ndarray:
    F = np.fft.rfft(force, axis=-1)
    X = np.fft.rfft(resp, axis=-1)
    freq = np.fft.rfftfreq(force.shape[-1], 1 / fs_hz)
    H = np.sum(X * np.conj(F)[:, None, :], axis=0) / np.sum(np.abs(F) ** 2, axis=0)
    sel = (freq >= band[0]) & (freq <= band[1])
    s = 20 * np.log10(np.sqrt(np.sum(np.abs(H[:, sel]) ** 2, axis=0)) + 1e-300)
    fb = freq[sel]
    idx, _ = PEAK_RULES["modal_peaks"].find(s)
    out = []
    for k in idx:
        if 0 < k < s.size - 1:
            den = s[k - 1] - 2 * s[k] + s[k + 1]
            dk = 0.5 * (s[k - 1] - s[k + 1]) / den if den != 0 else 0.0
            out.append(fb[k] + dk * (fb[1] - fb[0]))
    return np.array(out)


def _pair_shift(f_ref: np.ndarray, f_new: np.ndarray, tol: float = 0.05) -> np.ndarray:
    """Relative shift (new/ref - 1) of each reference peak that has a partner within ``tol``."""
    out = []
    for f in f_ref:
        if f_new.size:
            j = int(np.argmin(np.abs(f_new - f)))
            if abs(f_new[j] / f - 1) <= tol:
                out.append(f_new[j] / f - 1)
    return np.array(out)


def detect_amplitude_nonlinearity(force: np.ndarray, responses: np.ndarray, fs_hz: float,
                                  band: Sequence[float], min_level_ratio: float = 1.5) -> dict:
    """Frequency change between force levels (module docstring). Needs hits at two or more levels."""
    f = _check_hits(force)
    x = np.asarray(responses, float)
    if x.ndim == 2:
        x = x[:, None, :]
    peaks = np.abs(f).max(axis=1)
    order = np.argsort(peaks)
    lo, hi = order[: f.shape[0] // 2], order[f.shape[0] // 2:]
    if lo.size < 2 or hi.size < 1:
        raise ValueError("amplitude_nonlinearity needs at least 3 hits at two force levels")
    levels = (float(np.median(peaks[lo])), float(np.median(peaks[hi])))
    if levels[1] / levels[0] < min_level_ratio:
        return {"effect": "amplitude_nonlinearity", "parameters": {"force_levels_n": levels},
                "present": False, "evidence": f"one force level only (medians {levels[0]:.3g} and {levels[1]:.3g} N): "
                                              "hit at two levels (ratio >= 1.5) to test linearity"}
    p_lo = _h1_peaks(f[lo], x[lo], fs_hz, band)
    p_hi = _h1_peaks(f[hi], x[hi], fs_hz, band)
    shift = _pair_shift(p_lo, p_hi)
    ref = _pair_shift(_h1_peaks(f[lo[0::2]], x[lo[0::2]], fs_hz, band), _h1_peaks(f[lo[1::2]], x[lo[1::2]], fs_hz, band)) \
        if lo.size >= 4 else np.zeros(1)
    scatter = float(np.sqrt(np.mean(ref ** 2))) if ref.size else 0.0
    mean_abs = float(np.mean(np.abs(shift))) if shift.size else 0.0
    present = bool(shift.size and mean_abs > 3 * scatter + 5e-4)
    params = {"force_levels_n": levels, "peaks_hz": p_lo.tolist(), "df_percent": (100 * shift).tolist(),
              "mean_df_percent": float(100 * np.mean(shift)) if shift.size else 0.0,
              "scatter_percent": 100 * scatter}
    ev = (f"frequencies change by {params['mean_df_percent']:+.2f} % on average from {levels[0]:.3g} N to "
          f"{levels[1]:.3g} N (scatter within a level {100 * scatter:.3f} %)")
    return {"effect": "amplitude_nonlinearity", "parameters": params, "present": present, "evidence": ev}


@dataclass(frozen=True)
class Hits:
    """The accepted hits of one reference point: force (n_hits, n) N, responses (n_hits, n_out, n) EU,
    sample rate (Hz), the analysis band (Hz), the channels' full scales and the analyser's overload
    flags (n_hits, n_channels) when known."""

    force: np.ndarray
    responses: np.ndarray
    fs_hz: float
    band: Sequence[float]
    full_scale: Sequence[float] | None = None
    overload_flags: np.ndarray | None = None


@dataclass(frozen=True)
class TimeEffect:
    """One row of the time-data registry: name, what it is, what to do when it is found, and its
    detector ``detect(hits) -> cause dict`` (None when the hits cannot show it, e.g. no full scale); its
    level is ``"time"`` (:data:`analysis.diagnosis.effect_types.LEVELS`)."""

    name: str
    description: str
    advice: str
    detect: Callable[[Hits], dict | None]
    level: str = "time"


def _overload(h: Hits) -> dict | None:
    if h.full_scale is None and h.overload_flags is None:
        return None
    data = np.concatenate([np.asarray(h.force, float)[:, None, :], np.asarray(h.responses, float).reshape(
        np.shape(h.force)[0], -1, np.shape(h.force)[1])], axis=1)
    return detect_overload(data, h.full_scale, h.overload_flags)


#: The time-data effects. Adding one: a row and its detector (and, for a held-out gain, its
#: re-simulation in :mod:`analysis.diagnosis.timedata_gain`).
TIME_EFFECTS: dict[str, TimeEffect] = {e.name: e for e in (
    TimeEffect("double_hit", "the hammer bounced: a second pulse shortly after the first",
               "Strike with a firmer wrist or a harder tip and reject double hits (the hit check of capture), "
               "or widen the force window to keep the second pulse.",
               lambda h: detect_double_hit(h.force, h.fs_hz)),
    TimeEffect("overload", "a channel clipped at its full scale",
               "Raise the input range of the overloaded channels or strike softer; the flagged hits are not usable.",
               _overload),
    TimeEffect("input_noise", "noise on the force channel biases H1 low",
               "Use a more sensitive hammer range or a harder tip for more force in the band, or the H2 estimator.",
               lambda h: detect_input_noise(h.force, h.fs_hz, h.band)),
    TimeEffect("amplitude_nonlinearity", "the natural frequencies change with the force level",
               "The structure is not linear at these levels (a loose joint, a rattling part): test at one force "
               "level, tighten the joints, or model the nonlinearity.",
               lambda h: detect_amplitude_nonlinearity(h.force, h.responses, h.fs_hz, h.band)),
)}


def diagnose_hits(force: np.ndarray, responses: np.ndarray, fs_hz: float, band: Sequence[float], *,
                  full_scale: Sequence[float] | None = None, overload_flags: np.ndarray | None = None) -> list:
    """Every time-data cause of :data:`TIME_EFFECTS` for a set of hits at one reference, present ones first;
    each cause dict carries the row's ``description`` and ``advice``."""
    hits = Hits(force, responses, fs_hz, band, full_scale, overload_flags)
    out = []
    for e in TIME_EFFECTS.values():
        try:
            c = e.detect(hits)
        except ValueError as exc:
            c = {"effect": e.name, "parameters": {}, "present": False, "evidence": str(exc)}
        if c is not None:
            out.append({**c, "description": e.description, "advice": e.advice})
    return sorted(out, key=lambda c: not c["present"])


# --------------------------------------------------------------------------------------------------
# Re-simulation of the time-data effects and their cross-validated gain
# --------------------------------------------------------------------------------------------------
