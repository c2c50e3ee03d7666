"""The HTML test report, checked from Python: the page's DOM contract, its assets, the
content against the fit, the geometry files and the command's errors. The browser checks are in
tests/test_report_browser.py."""
from __future__ import annotations

import json
from html.parser import HTMLParser

import numpy as np
import pytest

from analysis import cli_report
from analysis.geometry import Geometry, GeometryError, points_on_a_line, read_uff_geometry, write_uff_geometry
from analysis.modal import ModalModel, pole_from_fz
from analysis.report_html.collect import excitation_band, mpc, shape_vectors

PLOTS = ("frf", "coherence", "force-spectrum", "stabilization", "cmif", "synthesis", "automac", "mode-shapes")


class Page(HTMLParser):
    """The parts of the page the tests look at: elements by id, data-plot names, mode-table rows, assets."""

    def __init__(self, text: str) -> None:
        super().__init__()
        self.ids: dict[str, str] = {}
        self.plots: list[str] = []
        self.assets: list[str] = []
        self.mode_rows: list[list[str]] = []
        self._stack: list[str] = []
        self._in_modes_body = False
        self._cell: list[str] | None = None
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "id" in a:
            self.ids[a["id"]] = tag
        if "data-plot" in a:
            self.plots.append(a["data-plot"])
        if tag == "script" and a.get("src"):
            self.assets.append(a["src"])
        if tag == "link" and a.get("href"):
            self.assets.append(a["href"])
        if tag == "table":
            self._stack.append(a.get("id", ""))
        if tag == "tbody" and self._stack and self._stack[-1] == "modes":
            self._in_modes_body = True
        if tag == "tr" and self._in_modes_body:
            self.mode_rows.append([])
        if tag == "td" and self._in_modes_body:
            self._cell = []

    def handle_endtag(self, tag):
        if tag == "table" and self._stack:
            self._stack.pop()
        if tag == "tbody":
            self._in_modes_body = False
        if tag == "td" and self._cell is not None:
            self.mode_rows[-1].append("".join(self._cell).strip())
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def test_page_holds_the_dom_contract(report_case):
    page = Page(report_case["report"].read_text())
    assert set(PLOTS) <= set(page.plots), f"missing data-plot elements: {set(PLOTS) - set(page.plots)}"
    assert page.ids.get("modes") == "table"
    assert page.ids.get("diagnosis") == "section"
    assert page.ids.get("diagnosis-modes") == "table" and "diagnosis-bands" in page.plots
    assert "difference -42.5 dB, coherence -40.9 dB" in report_case["report"].read_text()
    assert len(page.mode_rows) == report_case["n_modes"] > 0
    # the table shows the fitted frequencies (sorted, as in the fit JSON)
    fitted = [p["freq_hz"] for p in report_case["fit_doc"]["poles"]]
    shown = [float(r[1]) for r in page.mode_rows]
    assert np.allclose(shown, fitted, atol=6e-4)


def test_page_without_diagnosis_has_no_diagnosis_section(report_case):
    page = Page(report_case["demo_report"].read_text())
    assert "diagnosis" not in page.ids
    assert set(PLOTS) <= set(page.plots)


def test_every_asset_ships_in_the_folder(report_case):
    index = report_case["report"]
    text = index.read_text()
    page = Page(text)
    assert "plotly.min.js" in page.assets
    for src in page.assets:
        assert "://" not in src and not src.startswith("//"), f"asset {src} is not a local file"
        assert (index.parent / src).is_file(), f"asset {src} missing from the report folder"
    for name in ("index.html", "report.js", "report.css"):
        own = (index.parent / name).read_text()
        assert "http://" not in own and "https://" not in own, f"{name} names a network address"
    data = (index.parent / "report-data.js").read_text()
    assert data.startswith("window.REPORT_DATA = ")
    doc = json.loads(data[len("window.REPORT_DATA = "):].rstrip().rstrip(";"))
    assert len(doc["modal"]["modes"]) == report_case["n_modes"]
    assert doc["test"]["rejected"] == 2  # the demo spoils two strikes on purpose, each with a reason
    assert all(h["reasons"] for h in doc["test"]["hits"] if not h["accepted"])
    assert {p["point"] for p in doc["points"]} == set(doc["test"]["points"])


def test_shapes_are_drawn_on_the_frame_geometry(report_case):
    data = (report_case["report"].parent / "report-data.js").read_text()
    doc = json.loads(data[len("window.REPORT_DATA = "):].rstrip().rstrip(";"))
    geo = doc["shapes"]["geometry"]
    assert geo["name"].startswith("simulated frame")
    for d in doc["shapes"]["dofs"]:
        assert geo["labels"][d["node"]] == ":".join(d["label"].split(":")[:2])
    assert all(max(np.hypot(m["re"], m["im"])) == pytest.approx(1.0, abs=1e-3) for m in doc["shapes"]["modes"])


def test_report_of_a_uff_file_runs_the_fit_itself(report_case, tmp_path):
    out = tmp_path / "uffreport"
    assert cli_report.main([str(report_case["uff"]), "--out", str(out)]) == 0
    page = Page((out / "index.html").read_text())
    assert set(PLOTS) - {"force-spectrum"} <= set(page.plots)  # a UFF file of FRFs holds no force spectra
    assert len(page.mode_rows) >= 3


def test_bad_inputs_exit_2_with_a_message(report_case, tmp_path, capsys):
    assert cli_report.main([str(tmp_path / "nope.h5"), "--out", str(tmp_path / "r")]) == 2
    assert "not found" in capsys.readouterr().err
    bad_fit = tmp_path / "fit.json"
    bad_fit.write_text('{"poles": [{"pole": [-1, 80]}], "residues": [{"output": "x:1:Z", "reference": "y:1:Z", '
                       '"values": [[1, 0]]}], "band": [1, 2]}')
    assert cli_report.main([str(report_case["recording"]), "--out", str(tmp_path / "r"), "--fit", str(bad_fit)]) == 2
    assert "is not a fit of this input" in capsys.readouterr().err
    assert cli_report.main([str(report_case["recording"]), "--out", str(tmp_path / "r"), "--fit",
                            str(report_case["fit"]), "--geometry", str(bad_fit)]) == 2
    assert "holds no node coordinates (UFF data set 15)" in capsys.readouterr().err
    assert cli_report.main([str(report_case["recording"]), "--out", str(tmp_path / "r"), "--fit",
                            str(report_case["fit"]), "--diagnosis", str(bad_fit)]) == 2
    assert "not a diagnosis" in capsys.readouterr().err


def test_missing_plotly_names_the_extra(monkeypatch):
    import importlib.util

    from analysis import web_assets

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "plotly" else real(name, *a))
    with pytest.raises(web_assets.MissingAssetError, match=r"impactlab\[report\]"):
        web_assets.plotly_js_path()


def test_plotly_js_ships_with_the_package():
    from analysis.web_assets import plotly_js_path

    path = plotly_js_path()
    assert path.name == "plotly.min.js" and path.stat().st_size > 1_000_000


def test_uff_geometry_round_trip(tmp_path):
    from simulator.geometry import frame_geometry

    g = frame_geometry()
    assert {"left:9", "top:4", "right:6"} <= set(g.labels)
    assert len(g.lines) == 10 + 10 + 8 + 2  # elements of the three members and the two joints
    assert g.supports == ("left:0", "right:0")
    path = write_uff_geometry(tmp_path / "frame.uff", g)
    h = read_uff_geometry(path)
    assert h.labels == g.labels
    assert np.allclose(h.xyz, g.xyz, atol=1e-9)
    assert set(h.lines) == set(g.lines)


def test_a_geometry_without_the_measured_nodes_falls_back_to_a_line(report_case, tmp_path):
    other = write_uff_geometry(tmp_path / "other.uff", points_on_a_line(["n:1:Z", "n:2:Z"]))
    out = tmp_path / "r"
    assert cli_report.main([str(report_case["recording"]), "--out", str(out), "--fit", str(report_case["fit"]),
                            "--geometry", str(other)]) == 0
    text = (out / "index.html").read_text()
    assert "lacks the nodes of" in text and "the shapes are drawn on the points on a line" in text


def test_geometry_errors(tmp_path):
    with pytest.raises(GeometryError, match="not found"):
        read_uff_geometry(tmp_path / "none.uff")
    with pytest.raises(GeometryError, match="unknown nodes"):
        Geometry(("a:1",), np.zeros((1, 3)), (("a:1", "a:2"),))
    line = points_on_a_line(["b:1:Z", "b:2:X", "b:1:Y"])
    assert line.labels == ("b:1", "b:2") and line.lines == (("b:1", "b:2"),)
    assert line.covers(["b:3:Z", "b:1:X"]) == ["b:3:Z"]


def test_mpc_of_real_and_complex_shapes():
    rng = np.random.default_rng(3)
    v = rng.standard_normal(6)
    assert mpc(v * np.exp(0.7j)) == pytest.approx(1.0)  # a real mode turned by any phase
    assert mpc(np.array([1.0, 1j, -1.0, -1j])) == pytest.approx(0.0, abs=1e-12)  # a travelling wave


def test_shape_vectors_take_the_larger_point_set():
    # roving hammer: one output, four references; the shape lives over the references
    phi = np.array([[0.2, 1.0, -0.5, 0.1], [1.0, 0.3, 0.3, -0.8]]).T  # (4 points, 2 modes)
    R = 2.0j * phi.T[None, :, :].transpose(0, 2, 1)  # (1, 4, 2): residues = psi_out * phi_ref, psi_out = 2j
    model = ModalModel(poles=pole_from_fz([10.0, 20.0], [0.01, 0.01]), residues=R, outputs=("o:1:Z",),
                       references=tuple(f"r:{k}:Z" for k in range(4)))
    labels, shapes = shape_vectors(model)
    assert labels == [f"r:{k}:Z" for k in range(4)]
    assert np.allclose(shapes, phi / np.abs(phi).max(axis=0))


def test_excitation_band_marks_the_10_and_20_db_drops():
    f = np.linspace(0, 1000, 2001)
    # a first-order roll-off of the force spectrum: -10 log10(1 + (f/fc)^2) dB, fc = 200 Hz
    g = 30 - 10 * np.log10(1 + (f / 200.0) ** 2)
    band = excitation_band(f, g)
    assert band["f10_hz"] == pytest.approx(200 * 3.0, abs=1.0)   # 10^(10/10) - 1 = 9 -> f = 3 fc
    assert band["f20_hz"] is None or band["f20_hz"] > 990  # 20 dB needs f = 9.95 fc: out of the span
    assert excitation_band(f, np.full(f.size, 5.0))["f10_hz"] is None


@pytest.mark.realdata
def test_report_of_the_uliege_plane(shared_data, tmp_path):
    """The ULiege plane (222 FRFs, 74 hammer points on node_shock.csv): every mode in the table, the shapes
    on the measured geometry (timings: benchmarks/speed/bench_report.py)."""
    from analysis.report_html import build_document, run_fit, write_report
    from benchmarks.accuracy.validation import uliege_plane
    from benchmarks.speed.bench_report import uliege_geometry

    frf = uliege_plane.load(shared_data)
    fit = run_fit(frf, band=uliege_plane.BAND)
    doc = build_document(frf, fit, geometry=uliege_geometry(), input_name="uliege")
    index = write_report(tmp_path / "uliege", doc)
    page = Page(index.read_text())
    assert len(page.mode_rows) == fit.model.poles.size >= 10
    assert doc["shapes"]["geometry"]["name"].startswith("ULiege") and not doc["meta"]["notes"]
    assert len(doc["frf"]["traces"]) == 222
    assert doc["test"] is None and doc["points"] is None  # FRFs only: no test record, no time data
