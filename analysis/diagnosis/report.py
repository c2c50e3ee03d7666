"""The diagnosis report: plots (measured, simulated, extended) and a short text an engineer can act on.

Figures are :class:`matplotlib.figure.Figure` objects drawn with the Agg canvas (no pyplot state).
"""
from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..atomic import atomic_path, write_text_atomic
from .param_range import parameters_text
from .rule import why_lines
from .verdict import Diagnosis

__all__ = ["frf_figure", "band_figure", "report_text", "write_report", "ACTIONS"]

log = logging.getLogger(__name__)

# What to do about each verdict (first sentence of the report).
def _actions() -> dict[str, str]:
    """What to do about each verdict: the advice of every catalogue row, and of the verdicts that name
    no single row (a physical or time-data cause carries its own ``advice``)."""
    from .effects import EFFECTS

    out = {name: e.advice for name, e in EFFECTS.items()}
    out.update({
        "none": "The simulation explains the measurement within its noise: nothing to fix.",
        "combined": "Two causes together explain the measurement: act on each (below).",
        "unexplained": "No cause of the catalogue, alone or with one other, explains the difference: look at "
                       "the bands and modes named below.",
    })
    return out


# What to do about each verdict (first sentence of the report).
ACTIONS = _actions()


def _save(fig: Figure, path: Path) -> None:
    FigureCanvasAgg(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")


def _extension_name(diag: Diagnosis) -> str:
    return " + ".join(c["effect"] for c in diag.combined) or "none"


def frf_figure(diag: Diagnosis, output: int = 0, reference: int = 0) -> Figure:
    """Magnitude (dB) and phase (deg) of one FRF: measured, simulated and extended."""
    fig = Figure(figsize=(8, 6))
    ax1, ax2 = fig.add_subplot(2, 1, 1), fig.add_subplot(2, 1, 2)
    f = diag.measured.freq_hz
    for frf, label, style in ((diag.measured, "measured", "k-"), (diag.simulated, "simulated", "b--"),
                              (diag.extended, f"extended ({_extension_name(diag)})", "r:")):
        if frf is None:       # a diagnosis assembled without its extension
            continue
        h = frf.H[output, reference]
        ax1.plot(f, 20 * np.log10(np.abs(h) + 1e-300), style, lw=1, label=label)
        ax2.plot(f, np.degrees(np.angle(h)), style, lw=1)
    ax1.set_ylabel(f"|H| dB re 1 {diag.measured.unit or diag.measured.quantity}")
    ax1.set_title(f"{diag.measured.outputs[output]} / {diag.measured.references[reference]}")
    ax1.legend(fontsize=8)
    ax2.set_ylabel("phase (deg)")
    ax2.set_xlabel("frequency (Hz)")
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


def band_figure(diag: Diagnosis) -> Figure:
    """Error per band (dB) of the simulation and of the extension, with the noise level: the rows of
    :attr:`Diagnosis.bands`, which the HTML report draws too."""
    bands = diag.bands
    fig = Figure(figsize=(8, 4))
    ax = fig.add_subplot(1, 1, 1)
    x = np.arange(len(bands))
    ax.bar(x - 0.2, [b["simulation_db"] for b in bands], 0.4, label="simulation")
    ax.bar(x + 0.2, [b["extended_db"] for b in bands], 0.4, label=f"extended ({_extension_name(diag)})")
    ax.axhline(diag.noise_level_db, color="k", ls="--", lw=1, label="noise level")
    ax.set_xticks(x)
    ax.set_xticklabels([f"{b['lo_hz']:.3g}-{b['hi_hz']:.3g}" for b in bands], rotation=30, fontsize=7)
    ax.set_ylabel("error (dB)")
    ax.set_xlabel("band (Hz)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def report_text(diag: Diagnosis) -> str:
    """The ``report.md`` text: verdict, action, why this verdict (the trace), evidence, mode table, bands,
    coherence."""
    L = ["# Model discrepancy diagnosis", "", f"**Verdict: `{diag.verdict}`.** {_action(diag)}", ""]
    advice = {c["effect"]: c.get("advice") for c in diag.causes}
    for c in diag.named:
        act = advice.get(c["effect"]) or ACTIONS.get(c["effect"], "")
        L.append(f"- **{c['effect']}** ({parameters_text(c['parameters'])}): {act}")
    if diag.named:
        L.append("")
    L += ["## Why this verdict", "", "The rules that decided, in the order they were applied (docs/diagnosis.md):", ""]
    L += [f"{i}. {line}" for i, line in enumerate(why_lines(diag.trace), start=1)] or ["(no rule applied)"]
    L.append("")
    if diag.next_measurement:
        nm = diag.next_measurement
        L += [f"**Next measurement:** {nm['point']}: {nm['why']} (the candidates' FRFs there differ by "
              f"{nm['separation_db']:.1f} dB above the noise).", ""]
    L.append(f"FRF error of the simulation {diag.error_before_db:.1f} dB, after the extension "
             f"{diag.error_after_db:.1f} dB; noise level {diag.noise_level_db:.1f} dB (dB of the mean "
             "squared error relative to the measured |H|, lines weighted as in docs/diagnosis.md; -40 dB is a 1 % "
             "error). The error is a typical value over all lines: bands listed below can stay above the noise.")
    if len(diag.combined) > 1:
        L += ["", "Accepted effects, stage by stage (each on top of the previous): "
              + "; ".join(f"{c['effect']} (+{c['gain_db']:.2f} dB -> {c['error_after_db']:.1f} dB)" for c in diag.combined)]
    L += ["", "## Causes (cross-validated gain)", "", "| effect | gain dB | z | significant | evidence |",
          "|---|---|---|---|---|"]
    for c in diag.causes:
        L.append(f"| {c['effect']} | {c['gain_db']:.2f} | {c['z']:.1f} | {'yes' if c['significant'] else 'no'} "
                 f"| {c['evidence']} |")
    if diag.skipped:
        L += ["", "Not tried: " + "; ".join(f"{k} ({v})" for k, v in diag.skipped.items())]
    modes = diag.comparison["modes"]
    L += ["", "## Modes (simulation vs measurement)", "",
          "| measured Hz | simulated Hz | df % | damping measured % (half-power) | damping simulated % | amplitude dB | "
          "phase deg | MAC |", "|---|---|---|---|---|---|---|---|"]
    for p in modes["pairs"]:
        L.append(f"| {p['measured_hz']:.3f} | {p['simulated_hz']:.3f} | {p['df_percent']:+.2f} | "
                 f"{_percent(p['measured_damping'])} | {_percent(p['simulated_damping'])} | {p['amplitude_db']:+.1f} | "
                 f"{p['phase_deg']:+.0f} | {p['mac']:.2f} |")
    if modes["only_measured"]:
        L.append("\nPeaks only in the measurement: " + ", ".join(f"{m['freq_hz']:.2f} Hz" for m in modes["only_measured"]))
    if modes["only_simulated"]:
        L.append("\nPeaks only in the simulation: " + ", ".join(f"{m['freq_hz']:.2f} Hz" for m in modes["only_simulated"]))
    L += ["", "## Error per band and channel (simulation)", ""]
    L += [f"- {b['lo_hz']:.3g}-{b['hi_hz']:.3g} Hz: {b['error_db']:.1f} dB" for b in diag.comparison["bands"]]
    L += [f"- {c['output']} / {c['reference']}: {c['error_db']:.1f} dB" for c in diag.comparison["channels"]]
    if diag.unexplained:
        L += ["", "Bands still above the noise after the extension: "
              + ", ".join(f"{b['lo_hz']:.3g}-{b['hi_hz']:.3g} Hz ({b['error_db']:.1f} dB)" for b in diag.unexplained)]
    if diag.comparison["doubtful_coherence"]:
        L += ["", "Coherence below 0.9 (the measurement itself is doubtful there): "
              + ", ".join(f"{r['lo_hz']:.2f}-{r['hi_hz']:.2f} Hz (min {r['min_coherence']:.2f})"
                          for r in diag.comparison["doubtful_coherence"][:20])]
    return "\n".join(L) + "\n"


def _action(diag: Diagnosis) -> str:
    """The first sentence of the report: what to do about the verdict."""
    if len(diag.named) == 1:
        c: dict = next((c for c in diag.causes if c["effect"] == diag.named[0]["effect"]), {})
        return str(c.get("advice") or ACTIONS.get(diag.verdict, ""))
    return ACTIONS.get(diag.verdict, "")


def write_report(diag: Diagnosis, outdir: str | Path, max_frf_plots: int = 6) -> Path:
    """Write ``report.md``, ``diagnosis.json``, ``bands.png`` and ``frf_<o>_<r>.png`` into ``outdir``."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    n = 0
    images = []
    for o in range(diag.measured.n_outputs):
        for r in range(diag.measured.n_references):
            if n >= max_frf_plots:
                break
            name = f"frf_{o}_{r}.png"
            _save(frf_figure(diag, o, r), out / name)
            images.append(name)
            n += 1
    _save(band_figure(diag), out / "bands.png")
    text = report_text(diag) + "\n## Plots\n\n![bands](bands.png)\n\n" + "\n\n".join(f"![{i}]({i})" for i in images) + "\n"
    write_text_atomic(out / "report.md", text)
    write_text_atomic(out / "diagnosis.json", json.dumps(diag.to_json(), indent=1))
    log.info("report written to %s", out)
    return out / "report.md"


def _percent(ratio: float | None) -> str:
    """A damping ratio in %, or "-" when the peak is too narrow for the line spacing to measure it."""
    return "-" if ratio is None else f"{100 * ratio:.2f}"
