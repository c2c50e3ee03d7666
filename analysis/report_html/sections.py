"""The report's sections, declared once: each :class:`Section` row names its key (in the report
document and the page's ``id``), its heading, its data collector, its HTML and the ``report.js``
drawers that draw its plots. The page's headings, their numbers and the navigation, the document's
keys and the list of drawers the browser runs are all generated from :data:`SECTIONS`.

A new section is one row here, its collector (:mod:`analysis.report_html.collect`), its HTML
(:mod:`analysis.report_html.page`) and its drawer in ``report.js`` (the table ``DRAWERS``).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from html import escape
from typing import Any

from ..frf import FRFSet
from ..geometry import Geometry
from .collect import frf_section, modal_section, points_section, shapes_section, test_section
from .page import diagnosis_html, frf_html, modes_html, points_html, shapes_html, test_html
from .quality_section import quality_html
from .sources import FitData, TestRecord

__all__ = ["ReportInputs", "Section", "SECTIONS", "shown_sections", "collect_sections", "render_page"]


@dataclass(frozen=True)
class ReportInputs:
    """What the sections are collected from: the FRFs, the fit, the geometry the shapes are drawn on,
    and, when given, the test record, a diagnosis (its JSON document) and the quality checks."""

    frf: FRFSet
    fit: FitData
    geometry: Geometry
    record: TestRecord | None = None
    diagnosis: dict | None = None
    quality: dict | None = None


@dataclass(frozen=True)
class Section:
    """One section of the report.

    ``key``: its entry in the report document; ``title`` and ``nav``: its heading (numbered in the
    order of :data:`SECTIONS`) and its link in the navigation; ``collect(inputs)``: its JSON-able data;
    ``html(data, doc)``: the body of its ``<section>``; ``drawers``: the names of the ``report.js``
    functions (table ``DRAWERS``) that draw its plots; ``optional``: shown only when its data is
    there (else a section says what is missing); ``anchor``: the page id when not ``key``."""

    key: str
    title: str
    nav: str
    collect: Callable[[ReportInputs], Any]
    html: Callable[[Any, dict], str]
    drawers: tuple[str, ...] = ()
    optional: bool = False
    anchor: str = ""

    @property
    def id(self) -> str:
        """The ``id`` of the section element (the navigation's target)."""
        return self.anchor or self.key


SECTIONS: tuple[Section, ...] = (
    Section("test", "The test", "test", lambda i: None if i.record is None else test_section(i.record), test_html),
    Section("points", "Excitation and responses", "excitation",
            lambda i: None if i.record is None else points_section(i.record), points_html, ("points",)),
    Section("frf", "FRFs", "FRFs", lambda i: frf_section(i.frf), frf_html, ("frf",)),
    Section("modal", "Modal parameters", "modes", lambda i: modal_section(i.frf, i.fit), modes_html,
            ("stabilization", "indicator", "log-frequency", "synthesis", "automac")),
    Section("shapes", "Mode shapes", "shapes", lambda i: shapes_section(i.fit, i.geometry), shapes_html,
            ("mode-shapes",)),
    Section("diagnosis", "Diagnosis: what the simulation gets wrong", "diagnosis", lambda i: i.diagnosis,
            diagnosis_html, ("diagnosis",), optional=True),
    Section("quality", "Quality: linear, reciprocal, driving point", "quality", lambda i: i.quality, quality_html,
            ("linearity", "reciprocity"), optional=True, anchor="quality-checks"),
)


def shown_sections(doc: dict) -> list[Section]:
    """The sections the page of ``doc`` shows, in order (an optional one only with its data)."""
    return [s for s in SECTIONS if not s.optional or doc.get(s.key)]


def collect_sections(inputs: ReportInputs) -> dict:
    """Every section's data by key, and ``drawers``: the drawers of the shown sections, in order."""
    doc = {s.key: s.collect(inputs) for s in SECTIONS}
    doc["drawers"] = [d for s in shown_sections(doc) for d in s.drawers]
    return doc


def render_page(data: dict, *, plotly_src: str = "plotly.min.js") -> str:
    """The whole ``index.html``; ``data`` is the report document (see :mod:`analysis.report_html.build`)."""
    meta = data["meta"]
    title = f"Impact test report: {escape(meta['title'])}"
    shown = shown_sections(data)
    nav = " ".join(f"<a href='#{s.id}'>{escape(s.nav)}</a>" for s in shown)
    body = "\n".join(f"<section id='{s.id}'><h2>{n}. {escape(s.title)}</h2>{s.html(data.get(s.key), data)}</section>"
                     for n, s in enumerate(shown, start=1))
    return "\n".join([
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        ("<meta http-equiv='Content-Security-Policy' content=\"default-src 'self' file: 'unsafe-inline' 'unsafe-eval' "
         "data: blob:; connect-src 'none'\">"),
        f"<title>{title}</title><link rel='stylesheet' href='report.css'></head><body>",
        (f"<header><h1>{title}</h1><p>input <code>{escape(meta['input'])}</code> &middot; {escape(meta['frf_count'])}"
         f" &middot; written {escape(meta['written'])} by impactlab</p>"),
        "".join(f"<p class='warn'>note: {escape(n)}</p>" for n in meta.get("notes", [])),
        f"<nav>{nav}</nav></header><main>",
        body,
        (f"</main><script src='{plotly_src}'></script><script src='report-data.js'></script>"
         "<script src='report.js'></script></body></html>"),
    ])
