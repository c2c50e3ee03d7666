"""What the simulation gets wrong: errors per band and channel, paired modes, lone peaks, doubtful lines.

Error measure (used throughout the diagnosis). Every line of every FRF gets the weight

    w_ork = 1 / (|H_meas,ork|^2 + floor_or^2),   floor_or = FLOOR_FRACTION * median_k |H_meas,ork|

so that ``sum w |H_meas - H_model|^2 / n`` is a mean squared *relative* error: each line counts
alike whether it lies at a resonance or far below it (a sensor roll-off at 2 Hz matters as much as
a peak), and the floor keeps antiresonance lines (where the measurement is mostly noise) from
dominating. With coherence, lines whose H1 variance ``(1 - g^2)/(2 n_avg g^2)`` exceeds 1 % are
down-weighted in proportion (see :func:`line_weights`).
``error_db = 10 log10(mean w |e|^2)``; a 1 % complex noise gives about -40 dB.

Noise level without a model: the second difference along frequency ``d_k = H_{k-1} - 2 H_k + H_{k+1}``
removes the smooth FRF and keeps white noise with variance ``6 sigma^2``; the median over lines of
``w |d|^2 / 6`` divided by ln 2 (median of an exponential variable) estimates ``mean w |noise|^2``.
With coherence, the H1 variance ``(1 - g^2) / (2 n_avg g^2) |H|^2`` gives a second estimate.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from ..frf import FRFSet, window_pole_shift
from ..mac import mac as mac_of
from ..peaks import PEAK_RULES, find_peaks
from .rule import db

__all__ = [
    "BLOCK_LINES",
    "line_folds",
    "held_out_errors",
    "FLOOR_FRACTION",
    "line_weights",
    "averages",
    "coherence_variance",
    "error_db",
    "typical_error_db",
    "second_difference_gain",
    "noise_level",
    "effective_noise_db",
    "band_errors",
    "channel_errors",
    "pick_peaks",
    "pair_modes",
    "doubtful_coherence",
    "compare",
    "common_points",
]

FLOOR_FRACTION = 0.01
REFERENCE_NOISE = 0.01


def averages(measured: FRFSet) -> float:
    """Averages behind the measured FRFs: ``meta["n_averages"]`` as a recording stores it (a list per
    point after a merge: the smallest counts), else ``meta["averages"]``, else 5."""
    n = measured.meta.get("n_averages", measured.meta.get("averages"))
    if isinstance(n, (list, tuple)):
        n = min((float(x) for x in n if x), default=None)
    try:
        return float(n) if n and float(n) >= 1 else 5.0
    except (TypeError, ValueError):
        return 5.0


def coherence_variance(measured: FRFSet) -> np.ndarray | None:
    """Relative variance of the H1 estimate from the coherence, ``(1 - g^2) / (2 n_avg g^2)``
    (``n_avg`` from :func:`averages`), or None without coherence."""
    if measured.coherence is None or not np.all(np.isfinite(measured.coherence)):
        return None
    g2 = np.clip(measured.coherence, 1e-6, 1.0)
    n_avg = averages(measured)
    return (1 - g2) / (2 * n_avg * g2)


def line_weights(measured: FRFSet, floor_fraction: float = FLOOR_FRACTION,
                 reference_noise: float = REFERENCE_NOISE) -> np.ndarray:
    """Weights (n_out, n_ref, n_freq) of the relative squared error (module docstring).

    With coherence, a line whose H1 relative variance ``v`` exceeds ``reference_noise^2`` is
    down-weighted in proportion: ``w = 1 / (|H|^2 (1 + v / reference_noise^2) + floor^2)``
    (inverse-variance weighting where the measurement is doubtful). A line that is not finite (the
    0 Hz line of an accelerance turned into receptance) gets weight 0 and stays out of the floor's median,
    so one such line does not turn every weight of its FRF into NaN."""
    finite = np.isfinite(measured.H)
    mag = np.where(finite, np.abs(measured.H), np.nan)
    some = np.any(finite, axis=2, keepdims=True)
    with np.errstate(invalid="ignore"):
        mid = np.nanmedian(np.where(some, mag, 0.0), axis=2, keepdims=True)
    floor = floor_fraction * mid
    v = coherence_variance(measured)
    scale = 1.0 if v is None else 1.0 + v / reference_noise ** 2
    w = 1.0 / (np.where(finite, mag, 0.0) ** 2 * scale + floor ** 2 + 1e-300)
    w[~finite] = 0.0
    return w


def error_db(measured: FRFSet, model_H: np.ndarray, weights: np.ndarray, lines: np.ndarray | None = None) -> float:
    """10 log10 of the mean weighted squared error over ``lines`` (boolean mask, default all)."""
    sel = np.ones(measured.freq_hz.size, bool) if lines is None else lines
    e = measured.H[..., sel] - model_H[..., sel]
    return db(float(np.mean(weights[..., sel] * np.abs(e) ** 2)))


def typical_error_db(measured: FRFSet, H: np.ndarray, weights: np.ndarray) -> float:
    """Median over lines of ``w |H_meas - H|^2`` / ln 2 (dB): the error of a typical line, robust to a
    few antiresonance lines; comparable with :func:`noise_level`."""
    return db(float(np.median(weights * np.abs(measured.H - H) ** 2)) / np.log(2))


def second_difference_gain(measured: FRFSet) -> float:
    """Variance of the second difference ``n[k-1] - 2 n[k] + n[k+1]`` of the FRF noise over the noise
    variance: 6 for noise independent from line to line (a rectangular record), less when the
    measurement's exponential window ``exp(-a t)`` (``a = 1/tau``, recorded with the FRFs) makes
    neighbouring lines correlated. For white noise windowed over the record ``T = 1 / line spacing``
    the correlation of lines m apart is ``rho_m = 2 a T / (2 a T + 2 pi j m)`` (the window's squared
    transform at the DFT lines, ``exp(-2 a T)`` neglected), and the gain is
    ``6 - 8 Re rho_1 + 2 Re rho_2``; a 5 % window (a T = 3) gives 2.5 instead of 6, which would
    otherwise underestimate the noise by 3.7 dB."""
    tau, df = measured.exp_window_tau_s, measured.line_spacing_hz
    if not tau or not df or not np.isfinite(tau) or tau <= 0:
        return 6.0
    x = 2.0 / (tau * df)
    rho = [x / complex(x, 2 * np.pi * m) for m in (1, 2)]
    return float(6.0 - 8.0 * rho[0].real + 2.0 * rho[1].real)


def noise_level(measured: FRFSet, weights: np.ndarray) -> dict:
    """Noise estimates (dB, same scale as :func:`error_db`): ``"difference"`` always (second
    differences along frequency, scaled by :func:`second_difference_gain`), ``"coherence"`` when the
    data carry coherence (:func:`averages`)."""
    H = measured.H
    d2 = H[..., :-2] - 2 * H[..., 1:-1] + H[..., 2:]
    q = weights[..., 1:-1] * np.abs(d2) ** 2 / second_difference_gain(measured)
    out = {"difference": db(float(np.median(q)) / np.log(2))}
    v = coherence_variance(measured)
    if v is not None:
        out["coherence"] = db(float(np.mean(weights * v * np.abs(H) ** 2)))
    return out


def effective_noise_db(noise_db: Mapping[str, float | None]) -> float:
    """The one noise level (dB) the diagnosis judges errors against: the largest of the estimates in
    ``noise_db`` (those of :func:`noise_level`, and the hits' scatter, the simulation's own noise or the
    model-form allowance when known); an estimate that is None is unknown and left out."""
    known = [float(v) for v in noise_db.values() if v is not None]
    if not known:
        raise ValueError("no noise estimate is known: give the measured FRFs (the difference estimate always exists)")
    return max(known)


def band_errors(measured: FRFSet, model_H: np.ndarray, weights: np.ndarray, n_bands: int = 8) -> list[dict]:
    """Error (dB) in ``n_bands`` log-spaced bands (linear when the band starts at 0 Hz)."""
    f = measured.freq_hz
    if f[0] > 0:
        edges = np.geomspace(f[0], f[-1], n_bands + 1)
    else:
        edges = np.linspace(f[0], f[-1], n_bands + 1)
    out = []
    for i in range(n_bands):
        sel = (f >= edges[i]) & ((f < edges[i + 1]) | (i == n_bands - 1))
        if sel.sum() == 0:
            continue
        out.append({"lo_hz": float(edges[i]), "hi_hz": float(edges[i + 1]),
                    "error_db": error_db(measured, model_H, weights, sel)})
    return out


def channel_errors(measured: FRFSet, model_H: np.ndarray, weights: np.ndarray) -> list[dict]:
    """Error (dB) per (output, reference) FRF."""
    out = []
    for o, lo in enumerate(measured.outputs):
        for r, lr in enumerate(measured.references):
            e = measured.H[o, r] - model_H[o, r]
            out.append({"output": lo, "reference": lr,
                        "error_db": db(float(np.mean(weights[o, r] * np.abs(e) ** 2)))})
    return out


def pick_peaks(frf: FRFSet, prominence_db: float | None = None, window_shift: float | None = None) -> list[dict]:
    """Resonance peaks of the summed magnitude: frequency (Hz, parabolic interpolation), half-power
    damping ratio, peak magnitude and the complex FRF vector at the peak (for MAC).

    The half-power frequencies are interpolated between lines (linearly in power), and the decay an
    exponential window added (``window_shift`` 1/s, by default ``frf.exp_window_tau_s``'s,
    :func:`analysis.frf.window_pole_shift`) is taken off, so the damping is the structure's as the fit
    reports it; a peak narrower than the window alone makes (resolution-limited) gives None."""
    f = frf.freq_hz
    s = np.sqrt(np.sum(np.abs(frf.H) ** 2, axis=(0, 1)))
    sdb = 20 * np.log10(s + 1e-300)
    shift = window_pole_shift(frf.exp_window_tau_s) if window_shift is None else float(window_shift)
    idx, _ = find_peaks(sdb, **PEAK_RULES["modal_peaks"].options(prominence_db))
    peaks = []
    for k in idx:
        if 0 < k < f.size - 1:
            y0, y1, y2 = sdb[k - 1], sdb[k], sdb[k + 1]
            den = y0 - 2 * y1 + y2
            dk = 0.5 * (y0 - y2) / den if den != 0 else 0.0
            fk = float(f[k] + dk * (f[k + 1] - f[k - 1]) / 2)
        else:
            fk = float(f[k])
        half = s[k] / np.sqrt(2)
        i = k
        while i > 0 and s[i] > half:
            i -= 1
        j = k
        while j < f.size - 1 and s[j] > half:
            j += 1
        zeta = _half_power_damping(f, s ** 2, i, j, fk, shift, k)
        peaks.append({"freq_hz": fk, "damping": zeta, "magnitude": float(s[k]),
                      "vector": frf.H[..., k].ravel().copy()})
    return peaks


def _half_power_damping(f: np.ndarray, p: np.ndarray, i: int, j: int, fk: float, shift: float,
                        k: int) -> float | None:
    """Damping ratio from the half-power band of the power curve ``p`` around its peak line ``k`` at
    ``fk`` Hz, whose lines ``i+1..j-1`` lie above half the peak line's power, less the window's decay
    ``shift`` (1/s); None when nothing is left of it. Near a resonance ``1 / p`` is a parabola in
    frequency (a Lorentzian), so the width follows from the three lines at the top whatever the line
    spacing: ``2 sqrt(min / curvature)``; when they do not make an upward parabola, the half-power
    crossings interpolated between lines."""
    if not fk > 0:
        return None
    if 0 < k < f.size - 1 and np.all(p[k - 1:k + 2] > 0):
        a, b, c = np.polyfit(f[k - 1:k + 2] - f[k], 1.0 / p[k - 1:k + 2], 2)
        low = c - b * b / (4 * a) if a > 0 else -1.0
        if low > 0:
            zeta = float(np.sqrt(low / a)) / fk - shift / (2.0 * np.pi * fk)
            return zeta if zeta > 0 else None
    half = float(np.max(p[i:j + 1])) / 2.0

    def cross(a: int, b: int) -> float:
        if p[a] == p[b] or not (min(p[a], p[b]) <= half <= max(p[a], p[b])):
            return float(f[a])
        return float(f[a] + (half - p[a]) / (p[b] - p[a]) * (f[b] - f[a]))

    width = cross(j - 1, j) - cross(i, i + 1) if j - i >= 2 else float(f[j] - f[i])
    zeta = width / (2.0 * fk) - shift / (2.0 * np.pi * fk)
    return float(zeta) if zeta > 0 else None


def pair_modes(measured: FRFSet, simulated: FRFSet, max_rel_df: float = 0.15, min_mac: float = 0.5) -> dict:
    """Pair the peaks of both FRF sets by frequency and MAC (greedy on MAC x frequency closeness).

    Returns ``{"pairs": [...], "only_measured": [...], "only_simulated": [...]}``; a pair holds both
    frequencies, ``df_percent`` (simulated vs measured), damping ratios, ``amplitude_db``
    (simulated / measured peak), ``phase_deg`` (mean phase of the simulated vector against the measured)
    and ``mac``.
    """
    # the simulation is predicted as measured (the measurement's window on it): one window to take off
    shift = window_pole_shift(measured.exp_window_tau_s)
    pm, ps = pick_peaks(measured, window_shift=shift), pick_peaks(simulated, window_shift=shift)
    cand = []
    for i, a in enumerate(pm):
        for j, b in enumerate(ps):
            rel = abs(b["freq_hz"] - a["freq_hz"]) / a["freq_hz"]
            if rel <= max_rel_df:
                mac = mac_of(a["vector"], b["vector"])
                if mac >= min_mac:
                    cand.append((mac * (1 - rel / max_rel_df), i, j, mac))
    cand.sort(reverse=True)
    used_m, used_s, pairs = set(), set(), []
    for _, i, j, mac in cand:
        if i in used_m or j in used_s:
            continue
        used_m.add(i)
        used_s.add(j)
        a, b = pm[i], ps[j]
        phase = float(np.degrees(np.angle(np.vdot(a["vector"], b["vector"]))))
        pairs.append({
            "measured_hz": a["freq_hz"], "simulated_hz": b["freq_hz"],
            "df_percent": 100 * (b["freq_hz"] - a["freq_hz"]) / a["freq_hz"],
            "measured_damping": a["damping"], "simulated_damping": b["damping"],
            "amplitude_db": float(20 * np.log10(b["magnitude"] / a["magnitude"])),
            "phase_deg": phase, "mac": mac,
        })
    pairs.sort(key=lambda p: p["measured_hz"])
    only_m = [{"freq_hz": pm[i]["freq_hz"], "damping": pm[i]["damping"]} for i in range(len(pm)) if i not in used_m]
    only_s = [{"freq_hz": ps[j]["freq_hz"], "damping": ps[j]["damping"]} for j in range(len(ps)) if j not in used_s]
    return {"pairs": pairs, "only_measured": only_m, "only_simulated": only_s}


def doubtful_coherence(measured: FRFSet, threshold: float = 0.9, min_lines: int = 1) -> list[dict]:
    """Frequency ranges where the median coherence over the FRFs is below ``threshold``."""
    if measured.coherence is None:
        return []
    c = np.median(measured.coherence.reshape(-1, measured.freq_hz.size), axis=0)
    bad = c < threshold
    out, k, f = [], 0, measured.freq_hz
    while k < bad.size:
        if bad[k]:
            j = k
            while j + 1 < bad.size and bad[j + 1]:
                j += 1
            if j - k + 1 >= min_lines:
                out.append({"lo_hz": float(f[k]), "hi_hz": float(f[j]), "min_coherence": float(c[k:j + 1].min())})
            k = j + 1
        else:
            k += 1
    return out


def compare(measured: FRFSet, simulated: FRFSet, weights: np.ndarray | None = None,
            n_bands: int = 8) -> dict:
    """All the comparisons as one JSON-able dict: ``bands``, ``channels``, ``modes``, ``coherence``."""
    w = line_weights(measured) if weights is None else weights
    return {
        "bands": band_errors(measured, simulated.H, w, n_bands),
        "channels": channel_errors(measured, simulated.H, w),
        "modes": pair_modes(measured, simulated),
        "doubtful_coherence": doubtful_coherence(measured),
        "error_db": error_db(measured, simulated.H, w),
        "noise_db": noise_level(measured, w),
    }


def common_points(measured: FRFSet, simulated: FRFSet) -> tuple[Sequence[str], Sequence[str]]:
    """Outputs and references present in both (in the measured order); error when none."""
    outs = [o for o in measured.outputs if o in simulated.outputs]
    refs = [r for r in measured.references if r in simulated.references]
    if not outs or not refs:
        raise ValueError(
            f"measured and simulated FRFs share no points: measured outputs {list(measured.outputs)}, "
            f"references {list(measured.references)}; simulated outputs {list(simulated.outputs)}, "
            f"references {list(simulated.references)}. Label the points alike (component:node:direction)."
        )
    return outs, refs


#: Lines per block of the cross-validation folds (:func:`line_folds`).
BLOCK_LINES = 4


def line_folds(n: int, block: int = BLOCK_LINES) -> list[tuple[np.ndarray, np.ndarray]]:
    """The two cross-validation folds of ``n`` lines, (train, test) masks each way: blocks of
    ``block`` contiguous lines, alternating between the folds. Blocks, not single interleaved lines:
    neighbouring lines of a smooth FRF are not independent (their noise is correlated by the windows
    and the leakage of the record), so an effect scored on the lines right beside the ones it was
    fitted on would be scored on what it has seen. Every line is scored once."""
    first = (np.arange(n) // max(int(block), 1)) % 2 == 0
    return [(first, ~first), (~first, first)]


def held_out_errors(measured_H: np.ndarray, before_H: np.ndarray, weights: np.ndarray,
                    fitted_on: Callable[[np.ndarray], np.ndarray],
                    measured_after_H: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The held-out fold loop of the diagnosis: per line and FRF, the weighted squared errors ``w |H_m -
    H|^2`` (raveled (..., n_freq) arrays, every line once) of the prediction ``before_H`` and of the
    prediction ``fitted_on(train)`` (an array like ``measured_H``: the model fitted on the boolean line
    mask ``train``) on the lines of the other fold (:func:`line_folds`), both ways.
    ``measured_after_H``: the measurement the second is scored against when it differs (an exclusion of
    hits changes the measured H1 itself); default ``measured_H``."""
    m_after = measured_H if measured_after_H is None else measured_after_H
    before = weights * np.abs(measured_H - before_H) ** 2
    after = np.empty_like(before)
    for train, test in line_folds(measured_H.shape[-1]):
        Hx = fitted_on(train)
        after[..., test] = weights[..., test] * np.abs(m_after[..., test] - Hx[..., test]) ** 2
    return before.ravel(), after.ravel()

