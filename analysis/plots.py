"""Figures of the fit: measured vs synthesised FRFs (paper Fig. 7) and stabilization diagrams (Fig. 8).

The figures draw the same data as the HTML report's sections (:mod:`analysis.section_data`, which
:mod:`analysis.report_html.collect` puts in the report: the stabilization rows, the mode indicator, the
synthesis traces), so a PNG and the report
show one computation. Matplotlib is used through :class:`matplotlib.figure.Figure` and the Agg canvas directly, never
through pyplot's global state, so this module is safe in servers, tests and threads.
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from .frf import FRFSet
from .modal import ModalModel, synthesize

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from .lsfd import LSFDResult
    from .stabilization import StabilizationResult

__all__ = ["fit_figure", "indicator_panel", "label_levels", "plot_fit", "plot_stabilization"]

#: The stability classes as drawn, keyed by the class names of the stabilization rows
#: (:func:`analysis.section_data.stabilization_rows`): (marker, colour, size, label).
_STYLE = {
    "non-physical": ("x", "#bbbbbb", 10, "non-physical"),
    "new": ("o", "#999999", 10, "new"),
    "freq": ("v", "#1f77b4", 16, "stable f"),
    "freq+damp": ("d", "#2ca02c", 18, "stable f, zeta"),
    "freq+damp+mac": ("+", "#d62728", 40, "stable f, zeta, MAC"),
}


def _figure(width_in: float, height_in: float) -> Figure:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=100)
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: str | Path) -> Path:
    from .atomic import atomic_path

    p = Path(path)
    with atomic_path(p) as tmp:
        fig.savefig(str(tmp), format="png")
    return p


def _unwrapped_gaps(phase_deg: Sequence[float | None]) -> np.ndarray:
    """A phase (deg) with NaN at the +-180 deg wraps, so no vertical lines are drawn there."""
    p = np.asarray(phase_deg, float)
    jump = np.abs(np.diff(p)) > 180.0
    p[1:][jump] = np.nan
    return p


def _log_limits(lo: float, hi: float, freq_hz: np.ndarray) -> tuple[float, float]:
    """A frequency range a log axis can show: ``lo`` raised to the first positive line."""
    pos = freq_hz[freq_hz > 0]
    floor = float(pos[0]) if pos.size else 1.0
    return max(lo, floor), max(hi, floor * 10)


def label_levels(x: Sequence[float], width: float, levels: int = 4) -> list[int]:
    """Rows for labels centred at ``x`` (in any linear display unit, e.g. axes fraction), each
    ``width`` wide: every label takes the lowest row where it overlaps no label already placed,
    so close modes' numbers sit above one another instead of on top of one another. A label that
    finds no free row among ``levels`` takes the row whose last label is farthest away."""
    last = [-np.inf] * levels
    out = []
    for xi in np.asarray(x, float):
        free = [k for k in range(levels) if xi - last[k] >= width]
        k = free[0] if free else int(np.argmin(last))
        last[k] = xi
        out.append(k)
    return out


def _mark_modes(ax: Axes, modes_hz: np.ndarray, x_lo: float, x_hi: float, log_freq: bool, *, labels: bool = True,
                fontsize: float = 7) -> None:
    """The fitted modes as dotted green lines, numbered from 1 in order of frequency above the axes
    (rows chosen by :func:`label_levels`, so close numbers do not overlap)."""
    shown = [(k, f) for k, f in enumerate(np.sort(modes_hz), start=1) if x_lo <= f <= x_hi]
    for _, f in shown:
        ax.axvline(f, color="#2ca02c", lw=0.6, ls=":")
    if not labels or not shown:
        return
    scale = (lambda v: np.log10(v)) if log_freq else (lambda v: v)
    a, b = scale(x_lo), scale(x_hi)
    pos = [(scale(f) - a) / (b - a) for _, f in shown]
    # the axes of this module are made on a top-level Figure (see _figure), never on a SubFigure
    width_in = ax.get_position().width * cast("Figure", ax.figure).get_figwidth()
    label_in = (0.6 * len(str(len(shown))) + 0.5) * fontsize / 72  # digits and a little space, inches
    rows = label_levels(pos, width=label_in / max(width_in, 0.5))
    for (k, f), row in zip(shown, rows):
        ax.text(f, 1.005 + 0.05 * row, str(k), transform=ax.get_xaxis_transform(), ha="center", va="bottom",
                fontsize=fontsize, color="#2ca02c")


def indicator_panel(ax: Axes, indicator: dict, band: Sequence[float], modes_hz: np.ndarray | None = None,
                    log_freq: bool = False, unit: str = "") -> None:
    """Draw the mode indicator ``indicator`` (:func:`analysis.section_data.indicator_data`) over ``band``
    (Hz) on ``ax``: the CMIF (singular values of the FRF matrix per line, dB re 1 ``unit`` of H) when there are several
    references, else the real-normal MIF of the one reference (0..1, dips at modes; with one reference
    the CMIF is the summed FRF already drawn). ``modes_hz``: fitted modes as dotted lines."""
    f = np.asarray(indicator["freq_hz"], float)
    if indicator["mif"] is None:
        s_db = np.asarray(indicator["cmif_db"], float)
        for k in range(s_db.shape[0]):
            ax.plot(f, s_db[k], lw=0.8, color=_CMIF_COLOURS[k % len(_CMIF_COLOURS)], label=f"CMIF {k + 1}")
        ax.set_ylabel(f"CMIF [dB {unit or indicator['unit']}]", fontsize=8)
        ax.legend(loc="best", ncol=s_db.shape[0], fontsize=7, framealpha=0.8)
    else:
        ax.plot(f, np.asarray(indicator["mif"], float), lw=0.8, color="#9467bd")
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel("MIF [-]", fontsize=8)
    if log_freq:
        ax.set_xscale("log")
    if modes_hz is not None:
        _mark_modes(ax, np.asarray(modes_hz, float), float(band[0]), float(band[1]), log_freq, labels=False)
    ax.grid(True, color="#e5e5e5", lw=0.5)


_CMIF_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e")


def plot_stabilization(result: StabilizationResult, frf: FRFSet, path_png: str | Path, *, title: str | None = None,
                       show_nonphysical: bool = False, selected: np.ndarray | None = None,
                       log_freq: bool = False, indicator: bool = True) -> Path:
    """Stabilization diagram (paper Fig. 8): poles by model order, one symbol per stability class,
    over the summed FRF magnitude (right axis, dB), with the mode indicator beneath
    (:func:`indicator_panel`; ``indicator`` False leaves it out). Optional ``selected`` poles (rad/s)
    are drawn as vertical lines. ``log_freq``: a logarithmic frequency axis. The legend sits above
    the diagram, outside the pole columns. Returns the path written."""
    from .section_data import indicator_data, stabilization_rows

    rows = stabilization_rows(frf, result, result.band, selected, nonphysical=show_nonphysical)
    lo, hi = rows["band_hz"]
    if log_freq:
        lo, hi = _log_limits(lo, hi, frf.freq_hz)
    fig = _figure(10, 7.5 if indicator else 6)
    gs = fig.add_gridspec(2 if indicator else 1, 1, height_ratios=[4, 1.3] if indicator else [1], hspace=0.08)
    ax = fig.add_subplot(gs[0, 0])
    ax2 = ax.twinx()
    ax2.plot(np.asarray(rows["freq_hz"], float), np.asarray(rows["summed_db"], float), color="#444444", lw=0.8,
             alpha=0.6)
    ax2.set_ylabel("sum of |H| [dB]")
    classes = rows["classes"]
    for name, c in classes.items():
        m, col, size, label = _STYLE[name]
        ax.scatter(c["freq_hz"], c["order"], marker=m, c=col, s=size, label=f"{label} ({len(c['freq_hz'])})",
                   linewidths=1.0, zorder=3)
    sel_hz = np.asarray(rows["fitted_hz"], float) if selected is not None else None
    if sel_hz is not None:
        for f in sel_hz:
            ax.axvline(f, color="#d62728", lw=0.6, ls=":", zorder=1)
    if log_freq:
        ax.set_xscale("log")
    ax.set_xlim(lo, hi)
    ax.set_ylim(0, max(result.orders) + 1)
    ax.set_ylabel("model order (number of modes)")
    ax.set_zorder(ax2.get_zorder() + 1)
    ax.patch.set_visible(False)
    ax.legend(loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=len(classes), fontsize=8, frameon=False,
              borderaxespad=0.2)
    fig.suptitle(title or f"stabilization diagram ({result.method}), tolerances f {100 * result.tol_freq:g} %, "
                 f"zeta {100 * result.tol_damp:g} %, MAC {100 * result.tol_mac:g} %", fontsize=11)
    if indicator:
        ax.tick_params(labelbottom=False)
        axi = fig.add_subplot(gs[1, 0], sharex=ax)
        indicator_panel(axi, indicator_data(frf, (lo, hi)), (lo, hi), sel_hz, log_freq, frf.unit or frf.quantity)
        axi.set_xlim(lo, hi)
        axi.set_xlabel("frequency [Hz]")
    else:
        ax.set_xlabel("frequency [Hz]")
    fig.subplots_adjust(left=0.08, right=0.86, top=0.88, bottom=0.08)
    return _save(fig, path_png)


def plot_fit(frf: FRFSet, model: LSFDResult | ModalModel, path_png: str | Path, *,
             pairs: Sequence[tuple[int, int]] | None = None, max_panels: int = 4,
             band: Sequence[float] | None = None, log_freq: bool = False, indicator: bool = False) -> Path:
    """:func:`fit_figure` written to ``path_png`` (PNG); returns the path."""
    return _save(fit_figure(frf, model, pairs=pairs, max_panels=max_panels, band=band, log_freq=log_freq,
                            indicator=indicator), path_png)


def fit_figure(frf: FRFSet, model: LSFDResult | ModalModel, *, pairs: Sequence[tuple[int, int]] | None = None,
               max_panels: int = 4, band: Sequence[float] | None = None, log_freq: bool = False,
               indicator: bool = False) -> Any:
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
        says how many are. ``log_freq``: logarithmic frequency axes. ``indicator``: a last row across
        all columns with the mode indicator (:func:`indicator_panel`) and the fitted modes.
        Returns the matplotlib ``Figure``.
    """
    from .lsfd import LSFDResult, seen_through_window
    from .section_data import indicator_data, synthesis_traces

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
    traces = synthesis_traces(frf, frf.H, synthesize(seen, f).H, pairs, phase=True, floor=False)
    n = len(pairs)
    width_in = 4.2 * n + 1.2
    fig = _figure(width_in, 10 if indicator else 8)
    if band is not None:
        span = float(band[1]) - float(band[0])
        x_lo, x_hi = max(float(f[0]), band[0] - 0.1 * span), min(float(f[-1]), band[1] + 0.1 * span)
    else:
        x_lo, x_hi = float(f[0]), float(f[-1])
    if log_freq:
        x_lo, x_hi = _log_limits(x_lo, x_hi, f)
    modes_hz = np.sort(np.asarray(model.freq_hz, dtype=float))
    live = [(o, r) for o in range(frf.n_outputs) for r in range(frf.n_references)
            if np.any(np.isfinite(frf.H[o, r]) & (frf.H[o, r] != 0))]
    if len(pairs) < len(live):
        fig.suptitle(f"{len(pairs)} of {len(live)} FRFs shown (the strongest first); the fit used all of them",
                     fontsize=10)
    gs = fig.add_gridspec(4 if indicator else 3, n, height_ratios=[3, 1.5, 1.5, 2.2][:4 if indicator else 3],
                          hspace=0.08)
    for c, ((o, r), t) in enumerate(zip(pairs, traces)):
        axm = fig.add_subplot(gs[0, c])
        axp = fig.add_subplot(gs[1, c], sharex=axm)
        axe = fig.add_subplot(gs[2, c], sharex=axm)
        axm.plot(f, np.asarray(t["measured_db"], float), "--", color="#555555", lw=1.0, label="measured")
        axm.plot(f, np.asarray(t["synth_db"], float), "-", color="#1f77b4", lw=1.0,
                 label="LSFD model" + (" (as windowed)" if frf.exp_window_tau_s else ""))
        axp.plot(f, _unwrapped_gaps(t["measured_phase_deg"]), "--", color="#555555", lw=0.8)
        axp.plot(f, _unwrapped_gaps(t["synth_phase_deg"]), "-", color="#1f77b4", lw=0.8)
        axe.plot(f, np.asarray(t["rel_error_db"], float), color="#d62728", lw=0.8)
        if log_freq:
            axm.set_xscale("log")
        axm.set_xlim(x_lo, x_hi)
        _mark_modes(axm, modes_hz, x_lo, x_hi, log_freq)
        if band is not None:
            for ax in (axm, axp, axe):
                ax.axvspan(f[0], band[0], color="#eeeeee", zorder=0)
                ax.axvspan(band[1], f[-1], color="#eeeeee", zorder=0)
        axm.set_title(f"{frf.outputs[o]} / {frf.references[r]}", fontsize=9, pad=46)
        axm.tick_params(labelbottom=False)
        axp.tick_params(labelbottom=False)
        axp.set_ylim(-180, 180)
        axp.set_yticks([-180, -90, 0, 90, 180])
        if not indicator:
            axe.set_xlabel("frequency [Hz]")
        else:
            axe.tick_params(labelbottom=False)
        if c == 0:
            axm.set_ylabel(f"|H| [dB {frf.unit or frf.quantity}]")
            axp.set_ylabel("phase [deg]")
            axe.set_ylabel("rel. error [dB]")
            axm.legend(fontsize=8)
        axm.set_xlim(x_lo, x_hi)
    if indicator:
        axi = fig.add_subplot(gs[3, :])
        indicator_panel(axi, indicator_data(frf, (x_lo, x_hi)), (x_lo, x_hi), modes_hz, log_freq,
                        frf.unit or frf.quantity)
        axi.set_xlim(x_lo, x_hi)
        axi.set_xlabel("frequency [Hz]")
    # margins in inches, so that a single narrow column keeps its axis labels
    fig.subplots_adjust(left=0.95 / width_in, right=1 - 0.2 / width_in, top=0.88, bottom=0.07,
                        wspace=0.9 / 4.2)
    return fig
