"""Shared pieces of the validation cases: our fit with timing, figures, tables, report container.

Synthesis error
---------------
For measured FRFs ``H`` and a model ``G`` on the lines of the fitted band,

    e = 100 * ||H - G||_F / ||H||_F   (percent, Frobenius norm over all FRFs and lines)

which is the square root of the normalised sum of squared errors the LSFD minimises.

Pole matching
-------------
Two pole lists are paired greedily by relative natural-frequency distance (closest pairs first);
a pair further apart than ``tol`` (relative) is left unpaired.
"""
from __future__ import annotations

import logging
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analysis.frf import FRFSet
from analysis.modal import ModalModel, natural_freq_hz, synthesize

log = logging.getLogger(__name__)

__all__ = [
    "OurFit",
    "CaseReport",
    "fit_ours",
    "fit_ours_from_poles",
    "synthesis_error",
    "data_model",
    "match_poles",
    "pole_table",
    "consistency_table",
    "plot_case",
    "md_table",
    "fmt",
]

DPI = 80


@dataclass
class OurFit:
    """impactlab's fit of one FRF set: the LSFD result, the stabilization (or None), wall time (s)."""

    result: object
    stab: object
    time_s: float
    band: tuple
    synth_err_pct: float
    warnings: list = field(default_factory=list)


@dataclass
class CaseReport:
    """What one dataset contributes to ``docs/validation.md``."""

    name: str
    title: str
    source: str
    markdown: str
    summary: dict
    plots: list = field(default_factory=list)


def synthesis_error(H: np.ndarray, G: np.ndarray) -> float:
    """``100 ||H - G||_F / ||H||_F`` (percent) over every FRF and line given; NaN lines are skipped."""
    H = np.asarray(H)
    G = np.asarray(G)
    ok = np.isfinite(H) & np.isfinite(G)
    num = np.sqrt(np.sum(np.abs(H[ok] - G[ok]) ** 2))
    den = np.sqrt(np.sum(np.abs(H[ok]) ** 2))
    return float(100.0 * num / den) if den > 0 else float("nan")


def data_model(result) -> ModalModel:
    """The model as seen in the data: with an exponential window, the LSFD's ``poles_raw`` (window decay
    included); the reported ``result.model`` has the window removed and describes the structure."""
    from dataclasses import replace

    return replace(result.model, poles=np.asarray(result.poles_raw))


def _model_error(frf: FRFSet, result, band: Sequence[float]) -> float:
    sub = frf.band(band[0], band[1])
    G = synthesize(data_model(result), sub.freq_hz).H
    return synthesis_error(sub.H, G)


def fit_ours(frf: FRFSet, *, band: Sequence[float] | None = None, max_modes: int | None = None,
             n_modes: int | None = None, method: str = "lm", initial="lscf",
             selection_options: dict | None = None, max_iter: int = 100, frf_weighting: str = "rms") -> OurFit:
    """Run :func:`analysis.pipeline.fit_auto` (LSCF stabilization, automatic selection, LSFD), timed.

    ``frf_weighting`` is passed on: "rms" (the pipeline's default, each FRF weighted by 1 / its
    noise level) or "none" (unweighted least squares)."""
    from analysis.lsfd import LSFDConvergenceWarning
    from analysis.pipeline import fit_auto

    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LSFDConvergenceWarning)
        fit_stab = fit_auto(frf, band=band, max_modes=max_modes, n_modes=n_modes, method=method,
                             initial=initial, selection_options=selection_options, max_iter=max_iter,
                             frf_weighting=frf_weighting)
        res, stab = fit_stab
    dt = time.perf_counter() - t0
    used = tuple(fit_stab.band) if stab is not None else tuple(res.band)
    notes = list(fit_stab.warnings) if stab is not None else []
    notes += [str(w.message) for w in caught]
    return OurFit(res, stab, dt, used, _model_error(frf, res, res.band), notes)


def fit_ours_from_poles(frf: FRFSet, poles: np.ndarray, band: Sequence[float], *, method: str = "lm",
                        max_iter: int = 100) -> OurFit:
    """LSFD from given initial poles (rad/s) on ``band`` (Hz), timed (no stabilization)."""
    from analysis.lsfd import LSFDConvergenceWarning, fit_lsfd

    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", LSFDConvergenceWarning)
        res = fit_lsfd(frf, poles, method=method, band=tuple(band), max_iter=max_iter)
    dt = time.perf_counter() - t0
    return OurFit(res, None, dt, tuple(res.band), _model_error(frf, res, res.band),
                  [str(w.message) for w in caught])


def match_poles(f_a: np.ndarray, f_b: np.ndarray, tol: float = 0.03) -> list[tuple[int | None, int | None]]:
    """Pair two lists of natural frequencies (Hz) greedily by relative distance; unpaired get None.

    Returns (index in a or None, index in b or None), sorted by frequency.
    """
    f_a = np.asarray(f_a, float)
    f_b = np.asarray(f_b, float)
    pairs = []
    if f_a.size and f_b.size:
        d = np.abs(f_a[:, None] - f_b[None, :]) / np.maximum(f_a[:, None], 1e-300)
        order = np.dstack(np.unravel_index(np.argsort(d, axis=None), d.shape))[0]
        used_a, used_b = set(), set()
        for i, j in order:
            if d[i, j] > tol:
                break
            if i in used_a or j in used_b:
                continue
            used_a.add(int(i))
            used_b.add(int(j))
            pairs.append((int(i), int(j)))
    else:
        used_a, used_b = set(), set()
    pairs += [(i, None) for i in range(f_a.size) if i not in used_a]
    pairs += [(None, j) for j in range(f_b.size) if j not in used_b]

    def key(p):
        return f_a[p[0]] if p[0] is not None else f_b[p[1]]

    return sorted(pairs, key=key)


def fmt(x: float, digits: int = 4) -> str:
    """A number for a table; blank for None, 'n/a' for NaN."""
    if x is None:
        return ""
    x = float(x)
    if not np.isfinite(x):
        return "n/a"
    return f"{x:.{digits}g}"


def md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A GitHub markdown table."""
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def pole_table(ours, peer=None, crlb=None) -> str:
    """Our poles (f, std, zeta %, std) next to the peer's (f, zeta %), paired by frequency.

    ours : an LSFDResult; peer : a :class:`benchmarks.accuracy.validation.peer.PeerFit` or None;
    crlb : optional :class:`analysis.uncertainty.CRLB` of our model (bounds shown next to the std).
    """
    fo = np.asarray(ours.freq_hz)
    fp = np.asarray(peer.freq_hz) if peer is not None and peer.ok else np.zeros(0)
    head = ["#", "f ours [Hz]", "std f", "zeta ours [%]", "std zeta [%]"]
    if crlb is not None:
        head += ["CRLB f", "CRLB zeta [%]"]
    head += ["f sdypy [Hz]", "zeta sdypy [%]", "df [%]"]
    rows = []
    for k, (i, j) in enumerate(match_poles(fo, fp), start=1):
        r = [str(k)]
        if i is not None:
            r += [fmt(fo[i], 6), fmt(ours.freq_hz_std[i], 2), fmt(100 * ours.damping[i], 3),
                  fmt(100 * ours.damping_std[i], 2)]
            if crlb is not None:
                r += [fmt(crlb.freq_hz_std[i], 2), fmt(100 * crlb.damping_std[i], 2)]
        else:
            r += [""] * (4 + (2 if crlb is not None else 0))
        if j is not None:
            r += [fmt(fp[j], 6), fmt(100 * peer.damping[j], 3)]
        else:
            r += ["", ""]
        r.append(fmt(100 * (fp[j] - fo[i]) / fo[i], 2) if i is not None and j is not None else "")
        rows.append(r)
    return md_table(head, rows)


def consistency_table(labels: Sequence[str], results: Sequence, ref_freqs: np.ndarray, tol: float = 0.03) -> tuple[str, dict]:
    """Poles of repeated measurements side by side, paired to ``ref_freqs`` (Hz).

    Returns the markdown table (f and zeta per repetition, then the scatter: standard deviation
    over repetitions, and the median of the fit's own standard deviations) and a dict with, per
    reference mode, the arrays of f and zeta (NaN where a repetition lacks the mode).
    """
    ref = np.sort(np.asarray(ref_freqs, float))
    F = np.full((len(results), ref.size), np.nan)
    Z = np.full_like(F, np.nan)
    SF = np.full_like(F, np.nan)
    SZ = np.full_like(F, np.nan)
    for a, res in enumerate(results):
        if res is None:
            continue
        for i, j in match_poles(ref, np.asarray(res.freq_hz), tol):
            if i is not None and j is not None:
                F[a, i], Z[a, i] = res.freq_hz[j], res.damping[j]
                SF[a, i], SZ[a, i] = res.freq_hz_std[j], res.damping_std[j]
    head = ["mode"] + [f"{lab}: f [Hz] / zeta [%]" for lab in labels] + [
        "scatter f [Hz]", "median fit std f", "scatter zeta [%]", "median fit std zeta [%]"]
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for i in range(ref.size):
            r = [str(i + 1)]
            r += [f"{fmt(F[a, i], 6)} / {fmt(100 * Z[a, i], 3)}" if np.isfinite(F[a, i]) else "-"
                  for a in range(len(results))]
            n_ok = int(np.sum(np.isfinite(F[:, i])))
            sf = np.nanstd(F[:, i], ddof=1) if n_ok > 1 else np.nan
            sz = np.nanstd(Z[:, i], ddof=1) if n_ok > 1 else np.nan
            r += [fmt(sf, 2), fmt(np.nanmedian(SF[:, i]) if n_ok else np.nan, 2), fmt(100 * sz, 2),
                  fmt(100 * np.nanmedian(SZ[:, i]) if n_ok else np.nan, 2)]
            rows.append(r)
    return md_table(head, rows), {"f": F, "zeta": Z, "f_std": SF, "zeta_std": SZ}


def _summed_db(H: np.ndarray) -> np.ndarray:
    a = np.abs(H.reshape(-1, H.shape[-1])) ** 2
    s = np.sqrt(np.nansum(a, axis=0))
    out = 20 * np.log10(np.maximum(s, np.max(s) * 1e-12 + 1e-300))
    return np.where(np.all(np.isnan(a), axis=0), np.nan, out)


def plot_case(path: Path, frf: FRFSet, fit: OurFit, peer=None, *, title: str = "", pair: tuple | None = None) -> Path:
    """One figure per case (PNG, dpi 80): stabilization diagram over the summed FRF magnitude (top,
    when a stabilization exists), and measured vs synthesised FRF (ours, and the peer's) with our
    natural frequencies (bottom; ``pair`` = (output, reference) or the root-sum-square of all FRFs)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    lo, hi = fit.band
    sub = frf.band(lo, hi)
    f = sub.freq_hz
    G = synthesize(data_model(fit.result), f).H
    has_stab = fit.stab is not None
    fig = Figure(figsize=(9, 6.5 if has_stab else 3.8), dpi=DPI)
    FigureCanvasAgg(fig)
    axes = fig.subplots(2 if has_stab else 1, 1, sharex=True, squeeze=False)[:, 0]
    if has_stab:
        ax = axes[0]
        st = fit.stab
        ax2 = ax.twinx()
        ax2.plot(f, _summed_db(sub.H), color="#777777", lw=0.7)
        ax2.set_ylabel("sum |H| [dB]")
        styles = {0: ("o", "#aaaaaa", 6, "new"), 1: ("v", "#1f77b4", 8, "f"), 2: ("d", "#2ca02c", 9, "f, zeta"),
                  3: ("+", "#d62728", 20, "f, zeta, MAC")}
        for c, (m, col, s, lab) in styles.items():
            xs = [natural_freq_hz(p[k]) for p, k in ((p, stt == c) for p, stt in zip(st.poles, st.status))]
            ys = [np.full(int((stt == c).sum()), n) for n, stt in zip(st.orders, st.status)]
            x = np.concatenate(xs) if xs else np.zeros(0)
            y = np.concatenate(ys) if ys else np.zeros(0)
            ax.scatter(x, y, marker=m, c=col, s=s, linewidths=0.8, label=lab, zorder=3)
        for fr in fit.result.freq_hz:
            ax.axvline(fr, color="#d62728", lw=0.5, ls=":")
        ax.set_ylabel("model order")
        ax.set_zorder(ax2.get_zorder() + 1)
        ax.patch.set_visible(False)
        ax.legend(loc="upper left", fontsize=7, ncol=4)
        ax.set_title(f"{title}: stabilization (LSCF) and selected poles", fontsize=9)
    ax = axes[-1]
    if pair is None:
        meas, ours = _summed_db(sub.H), _summed_db(G)
        lab = "root-sum-square of all FRFs"
    else:
        o, r = pair
        meas = 20 * np.log10(np.abs(sub.H[o, r]) + 1e-300)
        ours = 20 * np.log10(np.abs(G[o, r]) + 1e-300)
        lab = f"{sub.outputs[o]} / {sub.references[r]}"
    ax.plot(f, meas, color="#444444", lw=1.0, label="measured")
    ax.plot(f, ours, color="#1f77b4", lw=0.9, label=f"impactlab LSFD ({fit.synth_err_pct:.3g} %)")
    if peer is not None and peer.ok and peer.H_band is not None:
        Hp = peer.H_band.reshape(sub.H.shape) if peer.H_band.size == sub.H.size else None
        if Hp is not None:
            pv = _summed_db(Hp) if pair is None else 20 * np.log10(np.abs(Hp[pair[0], pair[1]]) + 1e-300)
            ax.plot(f, pv, color="#ff7f0e", lw=0.9, ls="--", label=f"sdypy-EMA ({peer.synth_err_pct:.3g} %)")
    for fr in fit.result.freq_hz:
        ax.axvline(fr, color="#2ca02c", lw=0.4, ls=":")
    ax.set_xlim(lo, hi)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("|H| [dB]")
    ax.legend(loc="lower right", fontsize=7)
    ax.set_title(f"measured vs synthesised: {lab}", fontsize=9)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(str(path), format="png", dpi=DPI)
    return path
