"""Is the structure linear? FRFs at different excitation levels compared mode by mode.

A linear structure has the same FRF at every force. The check fits one modal model at each level
(the lowest level's automatic fit, then LSFD at every level from those poles, so modes pair by
index) and compares, per mode, the natural frequency and the damping ratio from the lowest to the
highest level against their standard deviations:

    df %      = 100 (f_hi - f_lo) / f_lo,           sd = 100 sqrt(sd_f,lo^2 + sd_f,hi^2) / f_lo
    dzeta %   = 100 (zeta_hi - zeta_lo) / zeta_lo,  sd likewise from sd_zeta

The standard deviations are the fits' own, widened per mode to the noise the data show on that mode's
lines (:func:`data_noise_factor`: the coherence's per-line noise, the exponential window's correlation of
neighbouring lines; :mod:`analysis.uncertainty`): near the top of the band a soft hit excites, a fit's
one noise level for the whole band understates them several times.

A mode is ``significant`` when either change exceeds ``z`` standard deviations (default 3) *and* a
floor of practical size (``min_df_percent``, ``min_dzeta_percent``); a mode the fits leave poorly
determined (standard deviation above ``MAX_DF_STD_PERCENT`` or ``MAX_DZETA_STD_PERCENT``, or a pole that
ran to the edge of its ``MAX_SHIFT`` window at a higher level) is not judged; a pole whose natural frequency
leaves the compared band at some level (a start pole the data do not hold, turned into a heavily damped
background term: its damped frequency stays in its window, its natural frequency does not) is no mode of
the band and is left out of the table with a note (:func:`modes_inside_band`). Without a given band the
comparison uses the band every level's data support (:func:`common_band`: the intersection of their
default bands, from the force spectrum, the coherence and the data's end). The verdict is "nonlinear" when
any mode is, else "linear" (within the noise). Changes are also given per decade of excitation level
(``df % / log10(level_hi / level_lo)``).

Before any verdict the two measurements must be of one structure: the resonance peaks of the lowest and
the highest level in the band pair by frequency (within ``MAX_SHIFT``) and MAC of the FRF vectors at the
peaks (>= ``PAIR_MIN_MAC``; :func:`analysis.diagnosis.compare.pair_modes`). When fewer than
``MIN_PAIRED_SHARE`` of the lowest level's peaks find a partner, :class:`LevelsDoNotPair` is raised
instead of a verdict: a difference between two structures (or between other points) is no evidence about
linearity.

Hits of one recording at different forces (the operator's soft and hard hits, or the natural spread)
are grouped by their peak force (:func:`group_by_force`) and averaged to one H1 per group
(:func:`level_frfsets`).
"""
from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import LevelsDoNotPair
from .frf import FRFSet

__all__ = ["ModeShift", "LinearityResult", "LevelHit", "LevelsDoNotPair", "compare_levels", "group_by_force",
           "level_frfsets", "recording_hits", "level_spread", "check_levels_pair", "common_band", "modes_inside_band",
           "Z_SIGNIFICANT", "MIN_DF_PERCENT", "MIN_DZETA_PERCENT", "MIN_LEVEL_RATIO", "PAIR_MIN_MAC",
           "MIN_PAIRED_SHARE"]

Z_SIGNIFICANT = 3.0
MIN_DF_PERCENT = 0.05
MIN_DZETA_PERCENT = 3.0
MIN_LEVEL_RATIO = 1.5  # hits whose peak forces span less than this ratio are one level
MAX_DF_STD_PERCENT = 0.5  # a mode whose frequency is less certain than this at a level is not judged
MAX_DZETA_STD_PERCENT = 50.0
MAX_SHIFT = 0.05  # relative frequency window of each level's pole around the lowest level's
#: the MAC (FRF vectors at the peaks) above which a peak of the highest level partners one of the lowest
#: (the same structure: 0.98 and above; another structure's peaks within MAX_SHIFT: 0.6 to 0.94)
PAIR_MIN_MAC = 0.9
#: the share of the lowest level's peaks that must find a partner for the levels to be one structure's
MIN_PAIRED_SHARE = 0.5


@dataclass(frozen=True)
class ModeShift:
    """One mode from the lowest to the highest level: ``freq_hz`` (Hz) and ``zeta`` (ratio) at the lowest
    level, changes in % with their standard deviations, per decade of level, and ``significant``."""

    freq_hz: float
    zeta: float
    df_percent: float
    df_std_percent: float
    dzeta_percent: float
    dzeta_std_percent: float
    df_percent_per_decade: float
    dzeta_percent_per_decade: float
    significant: bool
    determined: bool = True

    def to_dict(self) -> dict:
        from .reciprocity import finite_or_none

        return {k: (bool(v) if isinstance(v, (bool, np.bool_)) else finite_or_none(v)) for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class LinearityResult:
    """The comparison: ``levels`` (ascending, the data's units: N, V...), ``modes`` (:class:`ModeShift`,
    by frequency), ``verdict`` "linear" or "nonlinear", ``band`` (Hz), per-level frequencies and damping
    ``freq_hz`` / ``zeta`` (n_levels, n_modes) with their standard deviations, ``notes``, and ``poles``
    (rad/s, as fitted to the lowest level's data: the start of every level's fit)."""

    levels: tuple
    modes: tuple
    verdict: str
    band: tuple
    freq_hz: np.ndarray
    zeta: np.ndarray
    freq_hz_std: np.ndarray
    zeta_std: np.ndarray
    z: float = Z_SIGNIFICANT
    notes: tuple = field(default=())
    poles: np.ndarray = field(default_factory=lambda: np.zeros(0, complex), repr=False)

    @property
    def nonlinear_modes(self) -> list[int]:
        """Indices of the modes whose change is significant."""
        return [i for i, m in enumerate(self.modes) if m.significant]

    def summary(self) -> str:
        """One line for a terminal: the verdict, and which modes move how much."""
        if self.verdict == "linear":
            return (f"linear within the noise: {len(self.modes)} mode(s) compared over levels "
                    f"{self.levels[0]:.3g}..{self.levels[-1]:.3g}")
        parts = [f"{m.freq_hz:.4g} Hz {m.df_percent:+.2f} % (+-{m.df_std_percent:.2f}), zeta {m.dzeta_percent:+.0f} %"
                 for m in self.modes if m.significant]
        return "nonlinear: " + "; ".join(parts) + f" (levels {self.levels[0]:.3g} -> {self.levels[-1]:.3g})"

    def to_dict(self) -> dict:
        """The JSON contract: verdict, modes (freq_hz, df_percent, df_std_percent, dzeta_percent, significant...),
        levels, band, z, per-level frequencies and damping, notes."""
        return {"verdict": self.verdict, "modes": [m.to_dict() for m in self.modes],
                "levels": [float(v) for v in self.levels], "band_hz": [float(b) for b in self.band],
                "z": float(self.z), "freq_hz_by_level": np.nan_to_num(self.freq_hz).tolist(),
                "zeta_by_level": np.nan_to_num(self.zeta).tolist(), "notes": list(self.notes)}


@dataclass(frozen=True)
class LevelHit:
    """One hit for :func:`level_frfsets`: ``force`` (n,) N, ``responses`` (n_out, n) EU, ``fs_hz`` (Hz),
    ``trigger_index`` (sample), ``point`` (struck reference label), ``outputs`` (labels)."""

    force: np.ndarray
    responses: np.ndarray
    fs_hz: float
    trigger_index: int
    point: str
    outputs: tuple


def _pct(a: float, b: float) -> float:
    return 100.0 * (b - a) / a if a else float("nan")


def compare_levels(
    frfs: Sequence[FRFSet],
    levels: Sequence[float],
    *,
    band: Sequence[float] | None = None,
    z: float = Z_SIGNIFICANT,
    min_df_percent: float = MIN_DF_PERCENT,
    min_dzeta_percent: float = MIN_DZETA_PERCENT,
    fit_options: dict | None = None,
    poles: np.ndarray | None = None,
) -> LinearityResult:
    """Compare FRF sets measured at excitation ``levels`` (any positive unit; one level per set).

    The lowest level's set is fitted automatically (:func:`analysis.pipeline.fit_auto`, ``band`` or the
    default band, ``fit_options`` passed on; the next level's when no poles are found there); every level
    is then fitted by LSFD from those poles in the same band. ``poles`` (complex rad/s, with ``band``):
    start every level's fit from these instead (e.g. another comparison's ``poles``). Inputs are not
    modified. Raises ValueError on mismatched inputs.
    """
    from .bands import FitError
    from .lsfd import fit_lsfd
    from .pipeline import fit_auto

    if len(frfs) != len(levels) or len(frfs) < 2:
        raise ValueError(f"need at least two FRF sets and one level each; got {len(frfs)} sets, {len(levels)} levels")
    if not (np.isfinite(z) and z > 0):
        raise ValueError(f"z must be a finite number of standard deviations > 0; got {z}")
    lv = np.asarray(levels, float)
    if not np.all(np.isfinite(lv) & (lv > 0)):
        raise ValueError(f"levels must be positive numbers; got {list(levels)}")
    if len(set(lv.tolist())) < len(lv):
        raise ValueError(f"levels must differ; got {list(levels)}")
    order = np.argsort(lv)
    sets = [frfs[i] for i in order]
    lv = lv[order]
    # the band every level's data support, unless the user gives one
    supported: tuple[float, float] | None = None
    if band is None:
        supported = common_band(sets, lv.tolist())
    # one structure at two levels, or no verdict: before anything is fitted
    check_levels_pair(sets[0], sets[-1], supported or band or (), (float(lv[0]), float(lv[-1])))
    notes: list[str] = []
    if poles is None:
        base = None
        for k, s in enumerate(sets):  # the lowest level first; a higher one (better signal) when it finds no poles
            try:
                base = fit_auto(s, band=band, **(fit_options or {}))
                break
            except FitError:
                if k == len(sets) - 1:
                    raise
                notes.append(f"no poles found at level {lv[k]:.3g}; the modes were found at level {lv[k + 1]:.3g}")
        assert base is not None
        band_used: tuple[float, float] = (float(base.band[0]), float(base.band[1]))
        if supported is not None:  # the lowest level's band, within what every level's data support
            band_used = (max(band_used[0], supported[0]), min(band_used[1], supported[1]))
        poles = base.lsfd.poles_raw
    else:
        if band is None:
            raise ValueError("give the band with the poles")
        band_used = (float(band[0]), float(band[1]))
        poles = np.asarray(poles, complex)
    # every level's pole stays within MAX_SHIFT of the lowest level's: a pole that ends on that bound went
    # to fit something else (a neighbour, distortion) and its mode is not judged
    window = MAX_SHIFT * np.abs(poles)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # non-convergence is noted below
        fits = [fit_lsfd(s, poles, band=band_used, freq_window_hz=window / (2 * np.pi), max_iter=300) for s in sets]
    for lvl, r in zip(lv, fits):
        if not r.success:
            notes.append(f"the fit at level {lvl:.3g} stopped before converging ({r.message}); its modes are "
                         "compared as they are")
    f = np.array([r.freq_hz for r in fits])
    zt = np.array([r.damping for r in fits])
    # the fits' standard deviations, each mode's widened to the noise its own lines carry (honest at the
    # band's top, where a soft hit barely excites a mode)
    grow = np.array([np.sqrt(np.fmax(data_noise_factor(r, s, band_used), 1.0)) for r, s in zip(fits, sets)])
    fs = np.array([r.freq_hz_std for r in fits]) * grow
    zs = np.array([r.damping_std for r in fits]) * grow
    inside = modes_inside_band(f, band_used)
    for j in np.flatnonzero(~inside):
        outside = "; ".join(f"{fk:.5g} Hz, {100 * zk:.3g} % damping at level {v:.3g}"
                            for v, fk, zk in zip(lv, f[:, j], zt[:, j]) if not band_used[0] <= fk <= band_used[1])
        notes.append(f"the pole started at {abs(poles[j]) / (2 * np.pi):.5g} Hz left the band "
                     f"{band_used[0]:.5g}-{band_used[1]:.5g} Hz ({outside}): not a mode of the band, left out")
    idx = np.flatnonzero(inside)
    idx = idx[np.argsort(f[0, idx])]
    f, zt, fs, zs = f[:, idx], zt[:, idx], fs[:, idx], zs[:, idx]
    decades = float(np.log10(lv[-1] / lv[0]))
    modes = []
    for k in range(f.shape[1]):
        df = _pct(float(f[0, k]), float(f[-1, k]))
        df_sd = 100.0 * float(np.hypot(fs[0, k], fs[-1, k]) / f[0, k])
        dz = _pct(float(zt[0, k]), float(zt[-1, k]))
        dz_sd = 100.0 * float(np.hypot(zs[0, k], zs[-1, k]) / zt[0, k]) if zt[0, k] else float("nan")
        sig_f = abs(df) > max(z * df_sd, min_df_percent)
        sig_z = abs(dz) > max(z * dz_sd, min_dzeta_percent) if np.isfinite(dz_sd) else False
        determined = bool(df_sd <= MAX_DF_STD_PERCENT and np.isfinite(dz_sd) and dz_sd <= MAX_DZETA_STD_PERCENT
                          and abs(df) < 95.0 * MAX_SHIFT)
        if not determined:
            notes.append(f"the mode at {f[0, k]:.5g} Hz is poorly determined at some level (sd {df_sd:.2g} % in "
                         f"frequency, {dz_sd:.2g} % in damping): not judged")
        ok = bool(np.isfinite(df)) and determined
        modes.append(ModeShift(freq_hz=float(f[0, k]), zeta=float(zt[0, k]), df_percent=df, df_std_percent=df_sd,
                               dzeta_percent=dz, dzeta_std_percent=dz_sd, df_percent_per_decade=df / decades,
                               dzeta_percent_per_decade=dz / decades, significant=bool(ok and (sig_f or sig_z)),
                               determined=determined))
    verdict = "nonlinear" if any(m.significant for m in modes) else "linear"
    return LinearityResult(levels=tuple(float(v) for v in lv), modes=tuple(modes), verdict=verdict, band=band_used,
                           freq_hz=f, zeta=zt, freq_hz_std=fs, zeta_std=zs, z=float(z), notes=tuple(notes),
                           poles=fits[0].poles_raw[idx])


def common_band(sets: Sequence[FRFSet], levels: Sequence[float]) -> tuple[float, float]:
    """The band (Hz) every level's data support: the intersection of the default bands
    (:func:`analysis.bands.default_band`) of ``sets``, measured at ``levels`` (which only name them in
    the message). Raises ValueError when the bands do not overlap."""
    from .bands import default_band

    bands = [default_band(s) for s in sets]
    lo, hi = max(b[0] for b in bands), min(b[1] for b in bands)
    if not lo < hi:
        raise ValueError("the levels' data support no common band (" + ", ".join(
            f"{b[0]:.5g}-{b[1]:.5g} Hz at level {v:.3g}" for b, v in zip(bands, levels))
            + "): give the band to compare (--band LO:HI)")
    return float(lo), float(hi)


def modes_inside_band(freq_hz: np.ndarray, band: Sequence[float]) -> np.ndarray:
    """Per mode (column of ``freq_hz``, natural frequencies in Hz, one row per level), True when it lies inside
    ``band`` (Hz) at every level: only those are modes the levels' fits in that band compare."""
    f = np.asarray(freq_hz, float)
    return np.all((f >= float(band[0])) & (f <= float(band[1])), axis=0)


def check_levels_pair(low: FRFSet, high: FRFSet, band: Sequence[float], levels: Sequence[float] = (0.0, 0.0)) -> int:
    """Raise :class:`LevelsDoNotPair` unless the lowest level's FRFs ``low`` and the highest's ``high`` are
    measurements of one structure: at least :data:`MIN_PAIRED_SHARE` of the resonance peaks of ``low`` in
    ``band`` (Hz) pair with peaks of ``high`` within :data:`MAX_SHIFT` in frequency and with MAC >=
    :data:`PAIR_MIN_MAC` (module docstring). ``levels`` (their excitation levels) only name them in the
    message. Returns the number of pairs (0 when ``low`` shows no peak in the band: nothing to pair)."""
    from .diagnosis.compare import pair_modes

    if set(low.outputs) != set(high.outputs) or set(low.references) != set(high.references):
        raise LevelsDoNotPair(f"the levels hold different FRFs (outputs {', '.join(low.outputs)} / references "
                              f"{', '.join(low.references)} against {', '.join(high.outputs)} / "
                              f"{', '.join(high.references)}): compare measurements of the same points")
    lo, hi = float(band[0]), float(band[1])
    paired = pair_modes(low.band(lo, hi), high.select(low.outputs, low.references).band(lo, hi),
                        max_rel_df=MAX_SHIFT, min_mac=PAIR_MIN_MAC)
    n_pairs, n_low = len(paired["pairs"]), len(paired["pairs"]) + len(paired["only_measured"])
    if n_low and n_pairs < MIN_PAIRED_SHARE * n_low:
        raise LevelsDoNotPair(
            f"the modes of the two measurements do not pair: {n_pairs} of the {n_low} resonance peaks in "
            f"{lo:.5g}..{hi:.5g} Hz at level {levels[0]:.3g} have a partner at level {levels[-1]:.3g} (within "
            f"{100 * MAX_SHIFT:g} % in frequency, MAC >= {PAIR_MIN_MAC:g}); they look like different structures "
            "or points, not one structure at two levels: compare measurements of one structure")
    return n_pairs


def data_noise_factor(fit: Any, frf: FRFSet, band: Sequence[float]) -> np.ndarray:
    """Per mode of ``fit`` (an :class:`analysis.lsfd.LSFDResult` of ``frf`` on ``band`` Hz), the factor by which
    its pole's variance exceeds the fit's own (:func:`analysis.uncertainty.mode_noise_factor`): the per-line
    noise from the coherence and the averages (:func:`analysis.reciprocity.frf_error_variance`; without
    coherence the fit's noise on every line) and the lines' correlation from the recorded exponential window."""
    from .reciprocity import frf_error_variance
    from .uncertainty import mode_noise_factor

    sub = frf.band(float(band[0]), float(band[1]))
    line_var = frf_error_variance(sub)
    if line_var is not None and not np.all(np.isfinite(line_var)):
        line_var = None
    return mode_noise_factor(fit.poles_raw, fit.model.residues, sub.freq_hz, float(fit.noise_var), line_var,
                             sub.exp_window_tau_s)


def group_by_force(peaks_n: Sequence[float] | np.ndarray, min_ratio: float = MIN_LEVEL_RATIO) -> np.ndarray:
    """Level group (0 = soft, 1 = hard) of each hit from its peak force (N): the hits are split at the
    widest gap of their log peak forces when the groups' median forces differ by at least ``min_ratio``;
    otherwise every hit is group 0 (one level: the natural spread is too narrow to compare)."""
    p = np.asarray(peaks_n, float)
    labels = np.zeros(p.size, int)
    if p.size < 2 or not np.all(p > 0):
        return labels
    lp = np.log(p)
    srt = np.sort(lp)
    gaps = np.diff(srt)
    cut = srt[int(np.argmax(gaps))] + 0.5 * float(np.max(gaps))
    hi = lp > cut
    if hi.all() or not hi.any():
        return labels
    if np.exp(np.median(lp[hi]) - np.median(lp[~hi])) < min_ratio:
        return labels
    labels[hi] = 1
    return labels


def level_frfsets(hits: Sequence[Any], windows: Any = None, quantity: str = "accelerance",
                  unit: str = "") -> tuple[list[float], list[FRFSet]]:
    """H1 per force level from hits of one or more points.

    ``hits``: objects with ``force`` (n,) N, ``responses`` (n_out, n), ``fs_hz``, ``trigger_index``,
    ``point`` (the struck reference) and ``outputs`` (e.g. adapters over
    :class:`analysis.recording.RecordedHit`). Each point's hits are grouped by :func:`group_by_force`;
    the groups' H1 are merged over the points struck at two levels (:func:`analysis.recording.merge_frfsets`;
    a point struck at one level only is left out). Returns the levels (median peak force per group, N) and
    one FRF set per level; one level when no point's forces spread.
    """
    from .recording import merge_frfsets
    from .spectra import FRFAccumulator, WindowSettings, hit_spectra

    win = windows if windows is not None else WindowSettings()
    by_point: dict[str, list[Any]] = {}
    for h in hits:
        by_point.setdefault(str(h.point), []).append(h)
    per_level: dict[int, list[FRFSet]] = {}
    peaks: dict[int, list[float]] = {}
    grouped = {point: group_by_force([float(np.max(np.abs(h.force))) for h in hs]) for point, hs in by_point.items()}
    two = {point for point, lab in grouped.items() if lab.max() == 1}
    for point, hs in by_point.items():
        if two and point not in two:
            continue  # a point struck at one level only joins no comparison (the sets must hold the same FRFs)
        pk = [float(np.max(np.abs(h.force))) for h in hs]
        labels = grouped[point]
        for g in sorted(set(labels.tolist())):
            acc = FRFAccumulator(hs[0].outputs, point, quantity, unit)
            for h, lab in zip(hs, labels):
                if lab == g:
                    acc.add(hit_spectra(h.force, h.responses, h.fs_hz, h.trigger_index, win))
            per_level.setdefault(g, []).append(acc.frfset("H1", sample_rate_hz=hs[0].fs_hz))
            peaks.setdefault(g, []).extend(p for p, lab in zip(pk, labels) if lab == g)
    keys = sorted(per_level)
    return [float(np.median(peaks[k])) for k in keys], [merge_frfsets(per_level[k]) for k in keys]


def recording_hits(path: Any) -> tuple[list[LevelHit], list[float], list[FRFSet]] | None:
    """A recording's accepted hits (:class:`LevelHit`), their levels (median peak force per group, N) and
    H1 per level (:func:`level_frfsets`, the recording's windows, quantity and unit); None when the file
    is not a recording or holds no hits."""
    from .inputs import detect_format
    from .recording import Recording

    if detect_format(path) != "recording":
        return None
    with Recording(path) as rec:
        hits = [LevelHit(force=h.data[h.force_channel], responses=h.data[h.response_channels], fs_hz=h.sample_rate_hz,
                         trigger_index=h.trigger_index, point=h.reference, outputs=tuple(h.outputs))
                for h in rec.hits(accepted_only=True, skip_damaged=True)]
        sets = rec.frfsets()
        windows = rec.windows
    if not hits:
        return None
    quantity, unit = (sets[0].quantity, sets[0].unit) if sets else ("accelerance", "")
    levels, level_sets = level_frfsets(hits, windows, quantity, unit)
    return hits, levels, level_sets


def level_spread(hits: Sequence[Any], band: Sequence[float] | None = None, n_peaks: int = 4) -> dict | None:
    """A quick look for the operator while testing: the hits of one point (:class:`analysis.spectra.HitSpectra`)
    grouped by force (the RMS of each force spectrum in ``band`` Hz, relative to the softest group), H1
    per group and, at the ``n_peaks`` strongest resonances of the first output, the peak frequency of the
    hard hits' H1 relative to the soft hits' (parabola through the top three lines of ``|H1|``, in %).
    None until the hits span two levels. No modal fit: :func:`compare_levels` gives the changes with
    their uncertainty."""
    from .peaks import PEAK_RULES

    if len(hits) < 2:
        return None
    f = hits[0].freq_hz
    lo, hi = (float(band[0]), float(band[1])) if band is not None else (float(f[1]), float(f[-1]))
    sel = (f >= lo) & (f <= hi)
    rms = np.array([np.sqrt(np.sum(h.Gff[sel])) for h in hits])
    labels = group_by_force(rms)
    if labels.max() == 0:
        return None
    h1 = []
    for g in (0, 1):
        gff = sum(h.Gff for h, lab in zip(hits, labels) if lab == g)
        gfx = sum(h.Gfx[0] for h, lab in zip(hits, labels) if lab == g)
        h1.append(np.abs(gfx / np.where(gff > 0, gff, np.inf)))
    mag = np.where(sel, h1[0], 0.0)
    pk, prom = PEAK_RULES["level_peaks"].find(mag)
    top = np.sort(pk[np.argsort(prom)[::-1][:n_peaks]])

    def vertex(y: np.ndarray, k: int) -> float:
        a, b, c = np.log(np.maximum(y[k - 1:k + 2], 1e-300))
        den = a - 2 * b + c
        return float(f[k] + (0.5 * (a - c) / den if den != 0 else 0.0) * (f[1] - f[0]))

    peaks = []
    for k in top:
        if 0 < k < f.size - 1:
            f0, f1 = vertex(h1[0], k), vertex(h1[1], k)
            peaks.append({"freq_hz": f0, "df_percent": 100.0 * (f1 - f0) / f0,
                          "db": float(20 * np.log10(max(h1[1][k], 1e-300) / max(h1[0][k], 1e-300)))})
    ratio = float(np.median(rms[labels == 1]) / np.median(rms[labels == 0]))
    line = (f"soft ({int(np.sum(labels == 0))}) and hard ({int(np.sum(labels == 1))}) hits, force x {ratio:.3g}: "
            + ", ".join(f"{p['freq_hz']:.4g} Hz {p['df_percent']:+.2f} %" for p in peaks))
    return {"force_ratio": ratio, "n_hits": [int(np.sum(labels == 0)), int(np.sum(labels == 1))], "peaks": peaks,
            "line": line}
