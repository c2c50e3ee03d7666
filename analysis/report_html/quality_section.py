"""The report's quality checks: linearity (the hits grouped by force, H1 per group overlaid), reciprocity
(H_ij against H_ji) and driving points, as data (``quality_section``) and HTML (``quality_html``: the
table ``#quality`` and the plots ``data-plot="linearity"`` and ``data-plot="reciprocity"``)."""
from __future__ import annotations

from collections.abc import Sequence
from html import escape
from typing import Any

import numpy as np

from ..frf import FRFSet
from ..quality import quality_checks, quality_lines

__all__ = ["quality_section", "quality_html", "record_hits"]

_MAX_LINES = 1500


def record_hits(record: Any) -> list:
    """The accepted hits of a :class:`analysis.report_html.sources.TestRecord` as
    :class:`analysis.linearity.LevelHit`."""
    from ..linearity import LevelHit

    out = []
    for point, p in (getattr(record, "points", None) or {}).items():
        for f, x in zip(p["force"], p["responses"]):
            out.append(LevelHit(f, x, float(p["fs_hz"]), int(p["trigger_index"]), point, tuple(p["outputs"])))
    return out


def _curve(freq: np.ndarray, h: np.ndarray, sel: np.ndarray) -> dict:
    step = max(1, int(np.ceil(sel.sum() / _MAX_LINES)))
    idx = np.flatnonzero(sel)[::step]
    return {"freq_hz": np.round(freq[idx], 5).tolist(),
            "db": np.round(20 * np.log10(np.maximum(np.abs(h[idx]), 1e-300)), 3).tolist()}


def quality_section(frf: FRFSet, record: Any = None, band: Sequence[float] | None = None) -> dict:
    """The checks (:func:`analysis.quality.quality_checks`) with the linearity of the record's hits when
    they span force levels, the terminal lines, and the curves the plots draw (``band`` Hz)."""
    from ..linearity import compare_levels, level_frfsets

    lo, hi = (float(band[0]), float(band[1])) if band is not None else (float(frf.freq_hz[1]), float(frf.freq_hz[-1]))
    lin, lin_curves = None, []
    hits = record_hits(record) if record is not None else []
    if hits:
        windows = getattr(record, "windows", None)
        levels, sets = level_frfsets(hits, windows, frf.quantity, frf.unit)
        if len(sets) >= 2:
            try:
                lin = compare_levels(sets, levels, band=(lo, hi))
            except ValueError:
                lin = None
            for lv, s in zip(levels, sets):
                sel = (s.freq_hz >= lo) & (s.freq_hz <= hi)
                k = int(np.argmax(np.nanmax(np.abs(s.H[..., sel]), axis=-1).reshape(-1)))
                o, r = divmod(k, s.n_references)
                lin_curves.append({"level": float(lv), "frf": f"{s.outputs[o]} / {s.references[r]}",
                                   **_curve(s.freq_hz, s.H[o, r], sel)})
    checks = quality_checks(frf, band=(lo, hi), linearity=lin)
    sel = (frf.freq_hz >= lo) & (frf.freq_hz <= hi)
    rec_curves = []
    for p in checks["reciprocity"]["pairs"]:
        i, j = frf.outputs.index(p["i"]), frf.outputs.index(p["j"])
        ri = next((r for r, lab in enumerate(frf.references) if lab == p["i"]), None)
        rj = next((r for r, lab in enumerate(frf.references) if lab == p["j"]), None)
        if ri is None or rj is None:
            continue
        rec_curves.append({"pair": f"{p['i']} / {p['j']}", "ij": _curve(frf.freq_hz, frf.H[i, rj], sel),
                           "ji": _curve(frf.freq_hz, frf.H[j, ri], sel)})
    return {"checks": checks, "lines": quality_lines(checks), "linearity_curves": lin_curves,
            "reciprocity_curves": rec_curves}


def _row(check: str, verdict: str, detail: str) -> str:
    return f"<tr><td>{escape(check)}</td><td><b>{escape(verdict)}</b></td><td>{escape(detail)}</td></tr>"


def quality_html(q: dict, doc: dict | None = None) -> str:
    """The body of the report's quality section: the table ``#quality`` and the plots."""
    c = q["checks"]
    rows = []
    lin = c.get("linearity")
    if lin:
        moved = [m for m in lin["modes"] if m["significant"]]
        detail = ("; ".join(f"{m['freq_hz']:.4g} Hz {m['df_percent']:+.2f} % (+-{m['df_std_percent']:.2f}), damping "
                            f"{m['dzeta_percent']:+.0f} %" for m in moved) or "no mode moves beyond the noise")
        rows.append(_row(f"linearity (levels {lin['levels'][0]:.3g}-{lin['levels'][-1]:.3g})", lin["verdict"], detail))
    else:
        rows.append(_row("linearity", "not checked", "the hits do not span force levels (strike soft and hard hits)"))
    rec = c["reciprocity"]
    detail = (f"{len(rec['pairs'])} pair(s)" + (f"; calibration off at {', '.join(rec['suspects'])}"
                                                 if rec.get("suspects") else ""))
    rows.append(_row("reciprocity", rec["verdict"], detail if rec["pairs"] else
                     "no point is both struck and measured in the same direction"))
    for dp in c["driving_points"]:
        rows.append(_row(f"driving point {dp['point']}", "ok" if dp["ok"] else "suspect",
                         f"{len(dp['resonances_hz'])} resonances, antiresonances at "
                         + ", ".join(f"{a:.4g}" for a in dp["antiresonances_hz"] if a is not None) + " Hz"
                         + ("" if dp["phase_ok"] else f"; phase outside +-90 deg on {100 * dp['phase_outside']:.0f} %")))
    if not c["driving_points"]:
        rows.append(_row("driving point", "not measured", "no response taken where and along which a hit struck"))
    parts = ["<table id='quality'><thead><tr><th>check</th><th>result</th><th>detail</th></tr></thead><tbody>",
             "".join(rows), "</tbody></table>"]
    if q.get("linearity_curves"):
        parts.append("<figure><div class='plot' data-plot='linearity' style='height:360px'></div><figcaption>H1 of "
                     "each force level (the strongest FRF): a linear structure gives the same curve</figcaption></figure>")
    if q.get("reciprocity_curves"):
        parts.append("<figure><div class='plot' data-plot='reciprocity' style='height:360px'></div><figcaption>"
                     "H<sub>ij</sub> and H<sub>ji</sub> of each reciprocal pair</figcaption></figure>")
    return "".join(parts)
