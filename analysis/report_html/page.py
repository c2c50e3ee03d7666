"""The HTML of the report's sections (tables written here; plots drawn in the browser by
``report.js`` from ``report-data.js``). Each function writes the body of one section; the sections,
their headings, numbering and navigation come from :data:`analysis.report_html.sections.SECTIONS`."""
from __future__ import annotations

import datetime as _dt
from collections.abc import Sequence
from html import escape
from typing import Any

__all__ = ["test_html", "points_html", "frf_html", "modes_html", "shapes_html", "diagnosis_html", "written_stamp",
           "plot"]


def _num(x: Any, fmt: str = "{:.4g}") -> str:
    if x is None:
        return "&ndash;"
    try:
        return fmt.format(float(x))
    except (TypeError, ValueError):
        return escape(str(x))


def _table(head: Sequence[str], rows: Sequence[Sequence[str]], attrs: str = "") -> str:
    th = "".join(f"<th>{h}</th>" for h in head)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table{attrs}><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>"


def plot(name: str, caption: str, height: int = 380) -> str:
    return (f'<figure><div class="plot" data-plot="{name}" style="height:{height}px"></div>'
            f"<figcaption>{escape(caption)}</figcaption></figure>")


def _dl(items: Sequence[tuple[str, str]]) -> str:
    return "<dl>" + "".join(f"<dt>{escape(k)}</dt><dd>{v}</dd>" for k, v in items) + "</dl>"


def test_html(test: dict | None, doc: dict) -> str:
    """The test: device, date, sampling, trigger, windows, plan; the channel and hit tables."""
    if test is None:
        meta = doc["meta"]
        return ("<p class='note'>The input holds FRFs only (a UFF file): no "
                "record of the test (channels, windows, hits). Give the recording (.h5) for this section.</p>"
                + _dl([("input", escape(meta["input"])), ("FRFs", escape(meta["frf_count"]))]))
    win = test["windows"]
    tau, end = win.get("exp_window_tau_s"), win.get("exp_window_end_fraction")
    exp = (f"tau {_num(tau)} s" if tau else
           (f"to {_num(100 * end, '{:.3g}')} % at the block end" if end else "none"))
    force = (f"{_num(1e3 * win['force_width_s'], '{:.3g}')} ms + {_num(1e3 * win.get('force_taper_s', 0), '{:.3g}')}"
             " ms cosine taper" if win.get("force_width_s") else "none")
    fs, block = test["sample_rate_hz"], test["block_size"]
    record = (f" ({_num(float(block) / float(fs), '{:.3g}')} s)" if fs and block else "")
    points = test["points"] or list(dict.fromkeys(h["point"] for h in test["hits"]))
    items = [("device", escape(test["device"] or "unknown")), ("date (UTC)", escape(test["date"] or "unknown")),
             ("instrument", _described(test["instrument"], _INSTRUMENT_LABELS, skip=("url",))),
             ("sampling", f"{_num(fs)} Hz, blocks of {escape(str(block))} samples{record}"),
             ("trigger", _trigger(test["trigger"], test["channels"], fs)),
             ("force window", force), ("exponential window", exp),
             ("plan", _described({**test["plan"], "mode": str(test["plan"].get("mode", "")).replace("_", " ")},
                                 _PLAN_LABELS, skip=("points", "device"))),
             ("points", escape(", ".join(points)) if points else "none recorded"),
             ("hits", f"{test['accepted']} accepted, {test['rejected']} rejected")]
    ch_rows = [[escape(str(c.get("name", ""))), escape(str(c.get("point", ""))), escape(str(c.get("direction", ""))),
                escape(str(c.get("quantity", ""))),
                f"{_num(c.get('sensitivity'))} {escape(str(c.get('sensitivity_unit', '')))}",
                f"{_num(c.get('range_v'))} V", escape(str(c.get("coupling", ""))),
                "yes" if c.get("iepe") else "no"] for c in test["channels"]]
    # hits numbered from 1 as the terminal numbers them: in the recording and at their point
    at_point: dict[str, int] = {}
    hit_rows = []
    for h in test["hits"]:
        at_point[h["point"]] = at_point.get(h["point"], 0) + 1
        hit_rows.append([str(int(h["index"]) + 1), escape(h["point"]), str(at_point[h["point"]]),
                         "accepted" if h["accepted"] else "<b>rejected</b>", _num(h["peak_n"], "{:.1f}"),
                         escape("; ".join(h["reasons"])) or "&ndash;"])
    return (_dl(items) + "<h3>Channels</h3>"
            + _table(["channel", "point", "direction", "quantity", "sensitivity", "range", "coupling", "IEPE"],
                     ch_rows, " id='channels'")
            + "<h3>Hits</h3>" + _table(["hit", "point", "hit at the point", "decision", "peak force [N]", "reason"], hit_rows,
                                        " id='hits'"))


#: human labels of the instrument's and the plan's keys (other keys: underscores become spaces)
_INSTRUMENT_LABELS = {"vendor": "", "model": "", "firmware": "firmware", "serial": "serial number",
                      "protocol_version": "protocol version"}
_PLAN_LABELS = {"mode": "", "hits_per_point": "hits per point", "reference": "reference",
                "levels": "force levels", "auto": "hits accepted automatically"}


def _described(d: dict, labels: dict, skip: Sequence[str] = ()) -> str:
    """``d`` as "label value, ..." with human labels (an empty label: the value alone); keys in
    ``skip`` and values that are None or empty (not recorded) are left out."""
    parts = []
    for k, v in d.items():
        if k in skip or v is None or v == "" or v == []:
            continue
        label = labels.get(k, str(k).replace("_", " "))
        if isinstance(v, bool):
            v = "yes" if v else "no"
        elif isinstance(v, (list, tuple)):
            v = " then ".join(str(x) for x in v)   # e.g. the force levels, struck in this order
        parts.append(f"{label} {v}" if label else str(v))
    return escape(", ".join(parts)) or "&ndash;"


def _trigger(trig: dict, channels: list, fs: Any) -> str:
    """The trigger in words: channel (numbered from 1, with its name), level with the channel's
    unit, slope, and the pre-trigger samples with their duration."""
    if not trig:
        return "&ndash;"
    parts = []
    ch = trig.get("channel")
    unit = ""
    if isinstance(ch, int):
        info = channels[ch] if 0 <= ch < len(channels) else {}
        unit = str(info.get("unit", "") or "")
        name = str(info.get("name", "") or "")
        parts.append(f"channel {ch + 1}" + (f" ({name})" if name else ""))
    if trig.get("level") is not None:
        parts.append(f"level {_num(trig['level'])}" + (f" {unit}" if unit else " (engineering units)"))
    if trig.get("slope"):
        parts.append(f"{trig['slope']} slope")
    pre = trig.get("pretrigger_samples")
    if pre is not None:
        dur = f" ({_num(1e3 * float(pre) / float(fs), '{:.3g}')} ms)" if fs else ""
        parts.append(f"{pre} samples{dur} kept before the trigger")
    rest = {k: v for k, v in trig.items() if k not in ("channel", "level", "slope", "pretrigger_samples")}
    text = ", ".join(parts)
    return escape(text + (", " + ", ".join(f"{str(k).replace('_', ' ')} {v}" for k, v in rest.items()) if rest else ""))


def points_html(points: list | None, doc: dict) -> str:
    """Force spectra and time histories per point (a note without time data)."""
    if not points:
        return ("<p class='note'>No time data in the input "
                "(FRFs only): the force spectra and time histories need the recording.</p>")
    return ("<p>Force autospectrum of each point (mean of the accepted hits, force window applied) with the "
            "excitation band marked where it has fallen 10 dB (dashed) and 20 dB (dotted) below its low-frequency "
            "level; the force pulse and the response time histories of the last accepted hit (click the legend to "
            "show another point's).</p>"
            + plot("force-spectrum", "Force autospectrum per point, dB re 1 N\u00b2/Hz, with the -10/-20 dB marks")
            + plot("force-time", "Force pulse per point (last accepted hit)", 300)
            + plot("response-time", "Response time histories (last accepted hit of each point)", 320))


def modes_html(modal: dict, doc: dict) -> str:
    """The fit: stabilization (with pole picking), mode indicator, mode table, synthesis, AutoMAC."""
    rows = [[str(m["n"]), _num(m["freq_hz"], "{:.3f}"), _num(m["freq_std_hz"], "{:.2g}"),
             _num(m["damping_pct"], "{:.3f}"), _num(m["damping_std_pct"], "{:.2g}"), _num(m["mpc"], "{:.3f}"),
             _num(m["complexity_pct"], "{:.1f}")] for m in modal["modes"]]
    head = ["mode", "f [Hz]", "&sigma;<sub>f</sub> [Hz]", "&zeta; [%]", "&sigma;<sub>&zeta;</sub> [%]", "MPC",
            "complexity [%]"]
    warn = "".join(f"<li>{escape(w)}</li>" for w in modal["warnings"])
    rel = modal["synthesis"]["rel_rms"]
    stab = plot("stabilization", "Stabilization diagram: poles per model order by stability class over the summed "
                 "FRF; vertical lines: the fitted modes" if modal["stabilization"]["classes"] is not None else
                 "The fitted modes (vertical lines) over the summed FRF; no stabilization diagram: the fit was read "
                 "from a file (--fit)", 420)
    picking = modal["stabilization"]["classes"] is not None
    ind = modal["indicator"]
    ind_caption = ("Mode indicator: CMIF, the singular values of the FRF matrix per line (dB; a peak of the "
                   "first curve marks a mode, a peak of the second at the same line a second, close mode)"
                   + ("; MIF of the one reference on the right axis (0..1, dips at modes)" if ind["mif"] else "")
                   + "; vertical lines: the fitted modes")
    return (f"<p>Fit: {escape(modal['source'])}; band {modal['band_hz'][0]:.4g}&ndash;{modal['band_hz'][1]:.4g} Hz; "
            f"{len(modal['modes'])} modes; relative RMS misfit of the synthesis "
            f"{_num(None if rel is None else 100 * rel, '{:.2f}')} %.</p>"
            "<div class='controls'><label><input id='log-frequency' type='checkbox'> logarithmic frequency axis"
            "</label></div>"
            + stab + (_picks_html() if picking else "") + plot("cmif", ind_caption, 300)
            + "<h3>Mode table</h3>" + _table(head, rows, " id='modes'")
            + "<p class='note'>&sigma;: standard deviations of the fit (white-noise, perfect-model lower bounds). "
              "MPC: modal phase collinearity of the shape (1: real mode); complexity = 1 - MPC.</p>"
            + (f"<details><summary>fit warnings ({len(modal['warnings'])})</summary><ul>{warn}</ul></details>"
               if warn else "")
            + plot("synthesis", "Measured vs synthesised FRFs (top) and the relative error over all FRFs (bottom)",
                    480)
            + plot("automac", f"AutoMAC of the mode shapes over the {modal['shape_points']} points they are "
                    "measured at (few points cannot tell every pair of modes apart)", 420))


def _picks_html() -> str:
    return ("<div id='picks' class='controls'><p>Pick poles: click a pole marker of the diagram to pick it (a ring "
            "marks it), click it again to unpick it. Save the picks and fit from them with "
            "<code>python -m analysis fit INPUT --poles poles.json</code>.</p>"
            "<ol id='pick-list'></ol>"
            "<button id='save-picks' type='button' disabled>save picked poles (poles.json)</button> "
            "<button id='clear-picks' type='button' disabled>clear the picks</button></div>")


def shapes_html(shapes: dict, doc: dict) -> str:
    """The animated mode shapes on the test geometry (drawn on a canvas by ``report.js``)."""
    return ("<div class='controls'>"
            "<label>mode <select id='mode-select'></select></label>"
            "<button id='play' type='button'>pause</button>"
            "<label>amplitude <input id='amplitude' type='range' min='0' max='1' step='0.01' value='0.5'></label>"
            "<label>speed <input id='speed' type='range' min='0.1' max='3' step='0.1' value='1'></label>"
            "<label title='unmeasured nodes take the mean motion of their neighbours along the trace lines'>"
            "<input id='interpolate' type='checkbox'> interpolate unmeasured nodes</label>"
            "<span class='note'>drag to rotate</span></div>"
            "<figure><canvas class='plot' data-plot='mode-shapes' width='960' height='520'></canvas>"
            "<figcaption id='shape-caption'>Mode shape on the test geometry (grey: undeformed; red: measured points). "
            "As measured, a node moves only along its measured directions and unmeasured nodes stay still; the "
            "interpolation (an illustration, not data) gives every other direction the mean motion of the "
            "neighbours along the trace lines.</figcaption></figure>")


def _noise(x: Any) -> str:
    """The noise level(s) of a diagnosis, dB: one number or a dict of estimates."""
    if isinstance(x, dict):
        return ", ".join(f"{escape(str(k))} {_num(v, '{:.1f}')} dB" for k, v in x.items()) or "&ndash;"
    return f"{_num(x, '{:.1f}')} dB"


def _why_html(trace: Any) -> str:
    """"Why this verdict": the diagnosis' trace, the rules that decided in order ("" without one)."""
    from ..diagnosis.rule import why_lines

    if not trace:
        return ""
    items = "".join(f"<li>{escape(line)}</li>" for line in why_lines(trace))
    return f"<h3>Why this verdict</h3><ol id='diagnosis-why'>{items}</ol>"


def diagnosis_html(diag: dict, doc: dict) -> str:
    """A diagnosis read from its JSON: verdict, the rules that decided, causes with their gains, modes and bands."""
    rows = [[escape(str(c.get("effect", ""))), _num(c.get("gain_db"), "{:.1f}"), _num(c.get("error_before_db"), "{:.1f}"),
             _num(c.get("error_after_db"), "{:.1f}"), "yes" if c.get("significant") else "no",
             escape(str(c.get("evidence", "")))[:300]] for c in diag.get("causes", [])]
    comparison = diag.get("comparison") or {}
    pairs = (comparison.get("modes") or {}).get("pairs") or []
    mode_rows = [[_num(q.get("measured_hz"), "{:.3f}"), _num(q.get("simulated_hz"), "{:.3f}"),
                  _num(q.get("df_percent"), "{:+.2f}"), _num(q.get("amplitude_db"), "{:+.1f}"),
                  _num(q.get("mac"), "{:.2f}")] for q in pairs]
    bands = diag.get("bands") or comparison.get("bands") or []
    return (_dl([("verdict", f"<b>{escape(str(diag.get('verdict')))}</b>"),
                   ("error before", f"{_num(diag.get('error_before_db'), '{:.1f}')} dB"),
                   ("error after", f"{_num(diag.get('error_after_db'), '{:.1f}')} dB"),
                   ("noise floor", _noise(diag.get("noise_db")))]
                  + ([("time data", escape(str(diag["time_data_verdict"])))] if "time_data_verdict" in diag else []))
            + _why_html(diag.get("trace"))
            + "<h3>Causes</h3>"
            + _table(["cause", "gain [dB]", "error before [dB]", "error after [dB]", "significant", "evidence"], rows,
                     " id='causes'")
            + plot("diagnosis", "Gain of each cause: how much the held-out model error falls when the cause is "
                    "applied (dB; blue: significant)", 90 + 28 * max(len(rows), 4))
            + ("<h3>Modes: simulation vs measurement</h3>"
               + _table(["measured f [Hz]", "simulated f [Hz]", "&Delta;f [%]", "amplitude [dB]", "MAC"], mode_rows,
                        " id='diagnosis-modes'") if mode_rows else "")
            + (plot("diagnosis-bands", "Error per frequency band of the simulation and of its extension by the named "
                   "causes (dB re the measurement)", 300)
               if bands else ""))


def frf_html(frf: dict, doc: dict) -> str:
    """The FRFs (magnitude, phase) and their coherence, with the picker of FRFs to add."""
    return ("<p>The strongest FRFs are drawn first. Click a legend entry to show or "
            "hide an FRF (the coherence follows), or add any FRF with the list; drag to zoom, double-click to reset.</p>"
            "<div class='controls'><label>add an FRF <select id='frf-picker'><option value='' disabled selected>"
            f"{frf['n_outputs'] * frf['n_references']} FRFs (output / reference)</option></select></label></div>"
            + plot("frf", f"FRF magnitude and phase, {frf['quantity']} in {frf['unit']}", 560)
            + (plot("coherence", "Coherence", 260) if frf["has_coherence"] else
               '<div class="plot empty" data-plot="coherence"><p class="note">The input holds no coherence.</p></div>'))


def written_stamp() -> str:
    return _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
