"""The quality checks in the HTML report: the #quality table and the linearity and reciprocity plots."""
from __future__ import annotations

import json

import numpy as np
from quality_support import FRICTION_JOINT, level_hits, roving_test

from analysis.report_html import sources
from analysis.report_html.quality_section import quality_html, quality_section
from simulator.config import FrameConfig
from simulator.stand import TestStand


def _record(hits) -> sources.TestRecord:
    rec = sources.TestRecord()
    for h in hits:
        p = rec.points.setdefault(h.point, {"fs_hz": h.fs_hz, "trigger_index": h.trigger_index,
                                            "outputs": list(h.outputs), "force": [], "responses": []})
        p["force"].append(h.force)
        p["responses"].append(h.responses)
    for p in rec.points.values():
        p["force"], p["responses"] = np.asarray(p["force"]), np.asarray(p["responses"])
    return rec


def test_report_section_of_hits_at_two_levels_with_a_friction_joint():
    from analysis.linearity import level_frfsets

    hits = level_hits(FrameConfig.from_dict({"nonlinear": FRICTION_JOINT}), 7, n_hits=6)
    frf = level_frfsets(hits)[1][0]
    q = quality_section(frf, _record(hits), (5.0, 220.0))
    json.dumps(q, allow_nan=False)  # the report's data are strict JSON
    assert q["checks"]["linearity"]["verdict"] == "nonlinear"
    assert len(q["linearity_curves"]) == 2 and q["linearity_curves"][0]["level"] < q["linearity_curves"][1]["level"]
    page = quality_html(q)
    assert "<table id='quality'>" in page and "data-plot='linearity'" in page and ">nonlinear<" in page
    assert any(line.startswith("linearity: nonlinear at") for line in q["lines"])


def test_report_section_of_a_roving_test_with_struck_sensor_points():
    frf = roving_test(TestStand(seed=9), n_hits=3)
    q = quality_section(frf, None, (5.0, 400.0))
    json.dumps(q, allow_nan=False)
    assert len(q["reciprocity_curves"]) == 3
    page = quality_html(q)
    assert "data-plot='reciprocity'" in page and ">reciprocal<" in page and "not checked" in page
    assert page.count("driving point ") == 3
