"""Figures of the fit: measured vs synthesised FRFs (paper Fig. 7) and stabilization diagrams (Fig. 8).

Matplotlib is used through :class:`matplotlib.figure.Figure` and the Agg canvas directly, never
through pyplot's global state, so this module is safe in servers, tests and threads.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np

from .frf import FRFSet
from .modal import ModalModel, natural_freq_hz, synthesize

__all__ = ["plot_fit", "fit_figure", "plot_stabilization", "summed_magnitude_db"]

_STYLE = {
    # class: (marker, colour, size, label)
    -1: ("x", "#bbbbbb", 10, "non-physical"),
    0: ("o", "#999999", 10, "new"),
    1: ("v", "#1f77b4", 16, "stable f"),
    2: ("d", "#2ca02c", 18, "stable f, zeta"),
    3: ("+", "#d62728", 40, "stable f, zeta, MAC"),
}


def _figure(width_in: float, height_in: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=100)
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path: "str | Path") -> Path:
    p = Path(path)
    fig.savefig(str(p), format="png")
    return p


def _phase_deg(z: np.ndarray) -> np.ndarray:
    """Phase in degrees with NaN at the +-180 deg wraps, so no vertical lines are drawn there."""
    p = np.degrees(np.angle(z))
    jump = np.abs(np.diff(p)) > 180.0
    p[1:][jump] = np.nan
    return p


def summed_magnitude_db(frf: FRFSet) -> np.ndarray:
    """20 log10 of the root-sum-square magnitude of all FRFs per line (a CMIF-like background)."""
    s = np.sqrt(np.nansum(np.abs(frf.H.reshape(-1, frf.freq_hz.size)) ** 2, axis=0))
    floor = max(float(np.max(s)) * 1e-12, 1e-300)
    return 20 * np.log10(np.maximum(s, floor))


def plot_stabilization(result, frf: FRFSet, path_png: "str | Path", *, title: Optional[str] = None,
                       show_nonphysical: bool = False, selected: Optional[np.ndarray] = None) -> Path:
    """Stabilization diagram (paper Fig. 8): poles by model order, one symbol per stability class,
    over the summed FRF magnitude (right axis, dB). Optional ``selected`` poles (rad/s) are
    drawn as vertical lines. Returns the path written."""
    lo, hi = result.band
    fig = _figure(10, 6)
    ax = fig.add_subplot(1, 1, 1)
    ax2 = ax.twinx()
    sel = (frf.freq_hz >= lo) & (frf.freq_hz <= hi)
    ax2.plot(frf.freq_hz[sel], summed_magnitude_db(frf)[sel], color="#444444", lw=0.8, alpha=0.6)
    ax2.set_ylabel("sum of |H| [dB]")
    classes = [-1, 0, 1, 2, 3] if show_nonphysical else [0, 1, 2, 3]
    for c in classes:
        xs, ys = [], []
        for n, p, st in zip(result.orders, result.poles, result.status):
            k = st == c
            if c == -1:
                fd = p.imag / (2 * np.pi)
                k = k & (fd >= lo) & (fd <= hi)
            xs.append(natural_freq_hz(p[k]))
            ys.append(np.full(int(k.sum()), n))
        x = np.concatenate(xs) if xs else np.zeros(0)
        y = np.concatenate(ys) if ys else np.zeros(0)
        m, col, size, label = _STYLE[c]
        ax.scatter(x, y, marker=m, c=col, s=size, label=f"{label} ({len(x)})", linewidths=1.0, zorder=3)
    if selected is not None:
        for f in natural_freq_hz(np.asarray(selected)):
            ax.axvline(f, color="#d62728", lw=0.6, ls=":", zorder=1)
    ax.set_xlim(lo, hi)
    ax.set_ylim(0, max(result.orders) + 1)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("model order (number of modes)")
    ax.set_zorder(ax2.get_zorder() + 1)
    ax.patch.set_visible(False)
    ax.legend(loc="upper left", fontsize=8, framealpha=0.9)
    ax.set_title(title or f"stabilization diagram ({result.method}), tolerances f {100 * result.tol_freq:g} %, "
                 f"zeta {100 * result.tol_damp:g} %, MAC {100 * result.tol_mac:g} %")
    fig.tight_layout()
    return _save(fig, path_png)


def plot_fit(frf: FRFSet, model, path_png: "str | Path", *,
             pairs: Optional[Sequence[tuple[int, int]]] = None, max_panels: int = 4,
             band: Optional[Sequence[float]] = None) -> Path:
    """:func:`fit_figure` written to ``path_png`` (PNG); returns the path."""
    return _save(fit_figure(frf, model, pairs=pairs, max_panels=max_panels, band=band), path_png)


def fit_figure(frf: FRFSet, model, *, pairs: Optional[Sequence[tuple[int, int]]] = None, max_panels: int = 4,
               band: Optional[Sequence[float]] = None) -> Any:
    """Measured vs synthesised FRFs in the manner of the paper's Fig. 7: magnitude (dB), phase
    (deg) and the relative error ``|H - G| / |H|`` (dB) beneath, one column per FRF.

    model : an :class:`analysis.lsfd.LSFDResult` (its raw poles are drawn: the model as
        measured) or a :class:`ModalModel` of the structure (window-corrected poles, like
        ``LSFDResult.model``). When the FRFs were exponentially windowed
        (``frf.exp_window_tau_s``) the overlay is the model *as measured through the window*
        (poles shifted by ``-1/tau``), so that it is compared like with like; the green lines
        mark the structure's natural frequencies.
    pairs : (output index, reference index) of the FRFs to draw; default: the first
        ``max_panels`` FRFs. ``band`` (Hz): the fitted band; the frequency axis spans it with a
        10 % margin each side (the lines outside are shaded). The fitted modes are marked and
        numbered in order of frequency (as in the tables); when not every FRF is drawn the title
        says how many are. Returns the matplotlib ``Figure``.
    """
    from .lsfd import LSFDResult, seen_through_window

    if isinstance(model, LSFDResult):
        seen = model.model_raw
        model = model.model
    elif isinstance(model, ModalModel):
        seen = seen_through_window(model, frf.exp_window_tau_s)
    else:
        raise TypeError(f"model must be an LSFDResult or a ModalModel; got {type(model).__name__}")
    if pairs is None:
        pairs = [(o, r) for o in range(frf.n_outputs) for r in range(frf.n_references)][:max_panels]
    pairs = list(pairs)
    if not pairs:
        raise ValueError("no FRF to plot: give at least one (output, reference) pair")
    f = frf.freq_hz
    G = synthesize(seen, f).H
    n = len(pairs)
    width_in = 4.2 * n + 1.2
    fig = _figure(width_in, 8)
    if band is not None:
        span = float(band[1]) - float(band[0])
        x_lo, x_hi = max(float(f[0]), band[0] - 0.1 * span), min(float(f[-1]), band[1] + 0.1 * span)
    else:
        x_lo, x_hi = float(f[0]), float(f[-1])
    modes_hz = np.sort(np.asarray(model.freq_hz, dtype=float))
    live = [(o, r) for o in range(frf.n_outputs) for r in range(frf.n_references)
            if np.any(np.isfinite(frf.H[o, r]) & (frf.H[o, r] != 0))]
    if len(pairs) < len(live):
        fig.suptitle(f"{len(pairs)} of {len(live)} FRFs shown (the strongest first); the fit used all of them",
                     fontsize=10)
    gs = fig.add_gridspec(3, n, height_ratios=[3, 1.5, 1.5], hspace=0.08)
    for c, (o, r) in enumerate(pairs):
        H = frf.H[o, r]
        g = G[min(o, G.shape[0] - 1), min(r, G.shape[1] - 1)]
        axm = fig.add_subplot(gs[0, c])
        axp = fig.add_subplot(gs[1, c], sharex=axm)
        axe = fig.add_subplot(gs[2, c], sharex=axm)
        with np.errstate(divide="ignore", invalid="ignore"):
            axm.plot(f, 20 * np.log10(np.abs(H)), "--", color="#555555", lw=1.0, label="measured")
            axm.plot(f, 20 * np.log10(np.abs(g)), "-", color="#1f77b4", lw=1.0,
                     label="LSFD model" + (" (as windowed)" if frf.exp_window_tau_s else ""))
            axp.plot(f, _phase_deg(H), "--", color="#555555", lw=0.8)
            axp.plot(f, _phase_deg(g), "-", color="#1f77b4", lw=0.8)
            rel = np.abs(H - g) / np.abs(H)
            axe.plot(f, 20 * np.log10(rel), color="#d62728", lw=0.8)
        last, level = -np.inf, 0
        for k, fr in enumerate(modes_hz, start=1):
            if x_lo <= fr <= x_hi:
                axm.axvline(fr, color="#2ca02c", lw=0.6, ls=":")
                # close modes: stagger their numbers upwards so that they stay legible
                level = (level + 1) % 3 if fr - last < 0.03 * (x_hi - x_lo) else 0
                last = fr
                axm.text(fr, 1.005 + 0.045 * level, str(k), transform=axm.get_xaxis_transform(), ha="center",
                         va="bottom", fontsize=7, color="#2ca02c")
        if band is not None:
            for ax in (axm, axp, axe):
                ax.axvspan(f[0], band[0], color="#eeeeee", zorder=0)
                ax.axvspan(band[1], f[-1], color="#eeeeee", zorder=0)
        axm.set_title(f"{frf.outputs[o]} / {frf.references[r]}", fontsize=9, pad=34)
        axm.tick_params(labelbottom=False)
        axp.tick_params(labelbottom=False)
        axp.set_ylim(-180, 180)
        axp.set_yticks([-180, -90, 0, 90, 180])
        axe.set_xlabel("frequency [Hz]")
        if c == 0:
            axm.set_ylabel(f"|H| [dB {frf.unit or frf.quantity}]")
            axp.set_ylabel("phase [deg]")
            axe.set_ylabel("rel. error [dB]")
            axm.legend(fontsize=8)
        axm.set_xlim(x_lo, x_hi)
    # margins in inches, so that a single narrow column keeps its axis labels
    fig.subplots_adjust(left=0.95 / width_in, right=1 - 0.2 / width_in, top=0.88, bottom=0.07,
                        wspace=0.9 / 4.2)
    return fig
