"""Self-contained HTML test report: ``python -m analysis report``.

:func:`build_document` collects the content, :func:`write_report` writes the folder
(``index.html`` and its assets; opens from ``file://`` with no network).
"""
from __future__ import annotations

from .build import build_document, make_report, write_report
from .sources import (
                      FitData,
                      ReportInputError,
                      TestRecord,
                      load_diagnosis,
                      load_fit_json,
                      read_test_record,
                      recording_device,
                      run_fit,
)

__all__ = [
                      "FitData",
                      "ReportInputError",
                      "TestRecord",
                      "build_document",
                      "load_diagnosis",
                      "load_fit_json",
                      "make_report",
                      "read_test_record",
                      "recording_device",
                      "run_fit",
                      "write_report",
]
