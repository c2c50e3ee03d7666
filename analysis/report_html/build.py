"""Assemble and write the report folder: ``index.html``, ``report-data.js``, ``report.js``,
``report.css`` and ``plotly.min.js`` (copied from the plotly package: no network needed)."""
from __future__ import annotations

import json
import logging
import os
import shutil
from collections.abc import Sequence
from importlib import resources
from pathlib import Path

from ..frf import FRFSet
from ..geometry import Geometry, points_on_a_line
from ..web_assets import plotly_js_path
from .collect import shape_vectors
from .page import written_stamp
from .sections import ReportInputs, collect_sections, render_page
from .sources import FitData, ReportInputError, TestRecord, load_diagnosis, load_fit_json, read_test_record, run_fit

__all__ = ["build_document", "make_report", "write_report", "report_files", "check_report_folder"]

log = logging.getLogger(__name__)
_OWN_ASSETS = ("report.js", "report.css")


def build_document(frf: FRFSet, fit: FitData, *, geometry: Geometry | None = None,
                   record: TestRecord | None = None, diagnosis: dict | None = None,
                   input_name: str = "", title: str = "", quality: dict | None = None) -> dict:
    """The report's content as one JSON-able dict: ``meta``, then one entry per section of
    :data:`analysis.report_html.sections.SECTIONS` (its collector's data) and ``drawers``."""
    notes = []
    labels, _ = shape_vectors(fit.model)
    geo = geometry
    if geo is not None and geo.covers(labels):
        missing = geo.covers(labels)
        notes.append(f"geometry {geo.name!r} lacks the nodes of {', '.join(missing[:5])}"
                     f"{'...' if len(missing) > 5 else ''}: the shapes are drawn on the points on a line")
        log.warning(notes[-1])
        geo = None
    if geo is None:
        geo = points_on_a_line(labels)
    doc = {
        "meta": {"title": title or Path(input_name).name or "FRFs", "input": input_name,
                 "frf_count": f"{frf.n_outputs} x {frf.n_references} FRFs, {frf.freq_hz.size} lines "
                              f"{frf.freq_hz[0]:.4g}-{frf.freq_hz[-1]:.4g} Hz",
                 "written": written_stamp(), "notes": notes},
        **collect_sections(ReportInputs(frf, fit, geo, record=record, diagnosis=diagnosis, quality=quality)),
    }
    return doc


def write_report(out_dir: str | Path, doc: dict) -> Path:
    """Write the report folder for ``doc`` (from :func:`build_document`); returns ``index.html``.

    The files are built in a temporary folder beside ``out_dir`` and moved into place at the end
    (``index.html`` last), so a report that fails while being built writes nothing."""
    import os

    from ..atomic import remove_stale_temporaries, temporary_beside
    from ..disk_space import disk_full_cause

    out = Path(out_dir)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(out)  # left by a report that was killed while being built
        tmp = temporary_beside(out)
        tmp.mkdir(mode=0o755)
    except OSError as exc:
        if disk_full_cause(exc) is not None:
            raise
        raise ReportInputError(f"cannot create the report folder {out}: {exc.strerror}") from None
    try:
        try:
            _write_files(tmp, doc)
        except OSError as exc:
            full = disk_full_cause(exc)
            if full is None:
                raise
            raise OSError(full.errno, full.strerror, str(out)) from None  # named by the folder asked for
        if not out.exists():
            os.replace(tmp, out)
        else:
            names = sorted((p.name for p in tmp.iterdir()), key=lambda n: n == "index.html")
            for name in names:
                os.replace(tmp / name, out / name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out / "index.html"


def _write_files(out: Path, doc: dict) -> None:
    """The report's files into the (new, empty) folder ``out``."""
    shutil.copyfile(plotly_js_path(), out / "plotly.min.js")
    pkg = resources.files(__package__)
    for name in _OWN_ASSETS:
        (out / name).write_text(pkg.joinpath(name).read_text(encoding="utf-8"), encoding="utf-8")
    payload = json.dumps(doc, separators=(",", ":"), allow_nan=False, default=_default)
    (out / "report-data.js").write_text("window.REPORT_DATA = " + payload + ";\n", encoding="utf-8")
    (out / "index.html").write_text(render_page(doc), encoding="utf-8")


def _default(x: object) -> bool | int | float | list:
    import numpy as np

    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"{type(x).__name__} is not JSON serialisable")


def report_files(out_dir: str | Path) -> list[Path]:
    """The files a report writes into ``out_dir`` (``index.html`` and its assets)."""
    out = Path(out_dir)
    return [out / name for name in ("index.html", "report-data.js", *_OWN_ASSETS, "plotly.min.js")]


def check_report_folder(out_dir: str | Path, inputs: Sequence[str | Path | None] = (), overwrite: bool = False) -> None:
    """Refuse, before any work, a report folder whose files are inputs or held by a live writer
    (:func:`analysis.outputs.check_outputs`), or that already holds a report file without ``overwrite``
    (the user's own ``index.html`` is never replaced unasked)."""
    from ..outputs import check_outputs

    files = report_files(out_dir)
    check_outputs(files, inputs)
    there = [f.name for f in files if os.path.lexists(f)]
    if there and not overwrite:
        raise ReportInputError(f"{out_dir} already holds {', '.join(there)}: add --overwrite to replace them, or give "
                               "another --out folder")


def make_report(input_path: str | Path, out_dir: str | Path, *, fit_json: str | Path | None = None,
                diagnosis: str | Path | None = None, geometry: Geometry | None = None,
                estimator: str | None = None, overwrite: bool = False, inputs: Sequence[str | Path | None] = ()) -> Path:
    """Write the report of a recording or UFF file into ``out_dir``; returns ``index.html``.

    Without ``fit_json`` the automatic fit runs here; ``geometry`` None puts the points on a line.
    Report files already in ``out_dir`` are replaced only with ``overwrite``, and never when they are
    an input (``input_path``, ``fit_json``, ``diagnosis`` or one of ``inputs``: :func:`check_report_folder`).
    """
    from ..inputs import detect_format, load_input

    check_report_folder(out_dir, [input_path, fit_json, diagnosis, *inputs], overwrite)

    frf = load_input(input_path, estimator=estimator)
    record = read_test_record(input_path) if detect_format(input_path) == "recording" else None
    diag = load_diagnosis(diagnosis)
    fit = load_fit_json(fit_json, frf) if fit_json else run_fit(frf)
    from .quality_section import quality_section

    quality = quality_section(frf, record, fit.band)
    doc = build_document(frf, fit, geometry=geometry, record=record, diagnosis=diag, input_name=str(input_path),
                         quality=quality)
    return write_report(out_dir, doc)
