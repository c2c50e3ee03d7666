"""The report's sections, declared once (analysis/report_html/sections.py): every section has its
drawer in report.js, and the headings, numbers, navigation and drawer list come from the rows."""
from __future__ import annotations

import json
import re
from dataclasses import replace
from importlib import resources
from pathlib import Path

from analysis.report_html.sections import SECTIONS, render_page, shown_sections


def _drawer_table() -> dict[str, str]:
    """report.js's table DRAWERS: drawer name -> JavaScript function."""
    js = resources.files("analysis.report_html").joinpath("report.js").read_text(encoding="utf-8")
    body = re.search(r"var DRAWERS = \{(.*?)\};", js, re.S)
    assert body, "report.js lost its table DRAWERS"
    table = dict(re.findall(r'"([a-z-]+)":\s*([A-Za-z]+)', body.group(1)))
    for fn in table.values():
        assert re.search(rf"function {fn}\(", js), f"report.js names {fn} in DRAWERS but does not define it"
    return table


def test_every_section_has_its_drawer_and_every_drawer_its_section() -> None:
    table = _drawer_table()
    declared = [d for s in SECTIONS for d in s.drawers]
    assert len(declared) == len(set(declared)), "a drawer is declared by two sections"
    assert set(declared) == set(table), (set(declared) ^ set(table))
    assert len({s.key for s in SECTIONS}) == len(SECTIONS) and len({s.id for s in SECTIONS}) == len(SECTIONS)


def _report_doc(index: Path) -> dict:
    data = (index.parent / "report-data.js").read_text()
    return json.loads(data[len("window.REPORT_DATA = "):].rstrip().rstrip(";"))


def test_headings_navigation_and_drawers_come_from_the_rows(report_case) -> None:
    """The full report (with a diagnosis) and the demo's (without): each shown section once, numbered in
    order, linked from the navigation, and the page asks report.js for exactly their drawers; a section
    that draws a plot names a drawer."""
    for index in (report_case["report"], report_case["demo_report"]):
        doc = _report_doc(index)
        page = index.read_text()
        shown = shown_sections(doc)
        headings = re.findall(r"<section id='([a-z-]+)'><h2>(\d+)\. ([^<]+)</h2>", page)
        assert [(s.id, str(n), s.title) for n, s in enumerate(shown, 1)] == headings
        nav = re.search(r"<nav>(.*?)</nav>", page, re.S)
        assert nav and re.findall(r"href='#([a-z-]+)'", nav.group(1)) == [s.id for s in shown]
        assert doc["drawers"] == [d for s in shown for d in s.drawers]
        for s in shown:
            html = page[page.index(f"<section id='{s.id}'>"):]
            html = html[:html.index("</section>")]
            assert "data-plot" not in html or s.drawers, f"section {s.key} has plots and no drawer"
    assert "diagnosis" in _report_doc(report_case["report"])["drawers"]
    assert "diagnosis" not in _report_doc(report_case["demo_report"])["drawers"]
    assert render_page(_report_doc(report_case["report"])) == report_case["report"].read_text()


def test_band_figure_and_the_html_report_draw_the_same_band_rows() -> None:
    """The per-band error is computed once (Diagnosis.bands, written to the JSON the HTML report reads)
    and bands.png draws those rows: the simulation's bars are the comparison's band errors, the
    extension's are lower where the named cause acts."""
    import numpy as np

    from analysis.diagnosis import diagnose
    from analysis.diagnosis.report import band_figure
    from analysis.report_html.page import diagnosis_html
    from simulator.effects import add_frf_noise, base_model, simulate_with_effects

    outs, refs, f = ["left:9:Y", "top:4:X"], ["right:6:-X"], np.arange(2.0, 120.0, 0.5)
    base = base_model(None, outs, refs)
    measured = add_frf_noise(simulate_with_effects(base, outs, refs, f, "accelerance",
                                                   [{"effect": "time_delay", "delay_s": 3e-4}]), np.random.default_rng(3))
    diag = diagnose(measured, base, effects=["time_delay"])
    rows = diag.bands
    assert [(r["lo_hz"], r["hi_hz"], r["simulation_db"]) for r in rows] == [
        (b["lo_hz"], b["hi_hz"], b["error_db"]) for b in diag.comparison["bands"]]
    assert diag.verdict == "time_delay" and sum(r["extended_db"] for r in rows) < sum(r["simulation_db"] for r in rows)
    doc = json.loads(json.dumps(diag.to_json()))
    assert doc["bands"] == rows
    axes = band_figure(diag).axes[0]
    heights = [p.get_height() for p in axes.patches]
    assert heights == [r["simulation_db"] for r in rows] + [r["extended_db"] for r in rows]
    assert axes.lines[0].get_ydata()[0] == diag.noise_level_db == max(diag.noise_db.values())
    assert "data-plot=\"diagnosis-bands\"" in diagnosis_html(doc, {})


def _two_reference_fit():
    import numpy as np

    from analysis.modal import ModalModel, pole_from_fz, synthesize

    fz = np.array([30.0, 62.0, 95.0])
    poles = pole_from_fz(fz, np.full(fz.size, 0.01))
    model = ModalModel(poles, np.random.default_rng(1).normal(size=(2, 2, fz.size)) * poles.imag / 2j,
                       quantity="accelerance", residual_form="none", outputs=["n:1:Z", "n:2:Z"],
                       references=["n:3:Z", "n:4:Z"])
    return model, synthesize(model, np.linspace(0.0, 150.0, 601))


def test_stabilization_png_draws_the_report_sections_rows(tmp_path, monkeypatch) -> None:
    """stabilization.png and the report's modal section draw one computation: the scatter of each class is
    the class's rows of section_data.stabilization_rows, the background its summed FRF, the indicator the
    report's indicator data (two references: its CMIF curves)."""
    import numpy as np

    import analysis.plots as plots
    from analysis.section_data import indicator_data, stabilization_rows
    from analysis.stabilization import stabilization

    model, frf = _two_reference_fit()
    st = stabilization(frf, 8, band=(10.0, 140.0))
    figures = []
    monkeypatch.setattr(plots, "_save", lambda fig, path: figures.append(fig))
    plots.plot_stabilization(st, frf, tmp_path / "stab.png", selected=model.poles, show_nonphysical=True)
    ax, background, indicator = figures[0].axes[0], figures[0].axes[1], figures[0].axes[2]
    rows = stabilization_rows(frf, st, st.band, model.poles, nonphysical=True)
    assert set(rows["classes"]) == {"non-physical", "new", "freq", "freq+damp", "freq+damp+mac"}
    drawn = [c.get_offsets() for c in ax.collections]
    assert len(drawn) == len(rows["classes"])
    for xy, c in zip(drawn, rows["classes"].values()):
        assert np.array_equal(np.asarray(xy)[:, 0], c["freq_hz"]) and np.array_equal(np.asarray(xy)[:, 1], c["order"])
    assert sum(len(c["freq_hz"]) for c in rows["classes"].values()) > 0
    assert np.array_equal(background.lines[0].get_ydata(), rows["summed_db"])
    summary = indicator_data(frf, st.band)
    cmif = [line.get_ydata() for line in indicator.lines if line.get_label().startswith("CMIF")]
    assert len(cmif) == 2 and np.array_equal(cmif[0], np.asarray(summary["cmif_db"][0], float))


def test_fit_png_draws_the_report_sections_synthesis_traces() -> None:
    """fit.png's measured and synthesised curves, phases and relative error are the traces of the
    collector the report's modal section uses (section_data.synthesis_traces)."""
    import numpy as np

    from analysis.modal import synthesize
    from analysis.plots import fit_figure
    from analysis.section_data import synthesis_traces

    model, frf = _two_reference_fit()
    noisy = replace(frf, H=frf.H * (1 + 0.01 * np.random.default_rng(2).normal(size=frf.H.shape)))
    fig = fit_figure(noisy, model, pairs=[(1, 0)], band=(10.0, 140.0))
    (t,) = synthesis_traces(noisy, noisy.H, synthesize(model, noisy.freq_hz).H, [(1, 0)], phase=True, floor=False)
    mag, phase, err = fig.axes[0], fig.axes[1], fig.axes[2]
    assert np.array_equal(mag.lines[0].get_ydata(), np.asarray(t["measured_db"], float))
    assert np.array_equal(mag.lines[1].get_ydata(), np.asarray(t["synth_db"], float))
    shown = phase.lines[0].get_ydata()
    assert np.array_equal(shown[np.isfinite(shown)], np.asarray(t["measured_phase_deg"], float)[np.isfinite(shown)])
    assert np.array_equal(err.lines[0].get_ydata(), np.asarray(t["rel_error_db"], float), equal_nan=True)
    assert np.nanmax(err.lines[0].get_ydata()) < -20     # a 1 % error: about -40 dB
