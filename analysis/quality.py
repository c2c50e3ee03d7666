"""The quality checks a modal test needs, together: linearity (when hits span force levels),
reciprocity and driving points, as one JSON-ready dictionary for the report, the station and the
capture summary.

``quality_checks(frf)`` runs the reciprocity check (:mod:`analysis.reciprocity`) and every driving
point's check (:mod:`analysis.driving_point`) on one FRF set; a :class:`analysis.linearity.LinearityResult`
computed from the hits' force levels may be passed in and is added as it is.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from .driving_point import check_driving_point, driving_points
from .frf import FRFSet
from .reciprocity import reciprocity

__all__ = ["quality_checks", "quality_lines", "recording_quality"]


def quality_checks(frf: FRFSet, *, band: Sequence[float] | None = None, linearity: Any = None) -> dict:
    """``{"reciprocity": ..., "driving_points": [...], "linearity": ... or None}`` (see the modules'
    ``to_dict``); ``band`` (Hz) limits the driving-point check. Inputs are not modified."""
    rec = reciprocity(frf)
    dps = [check_driving_point(frf, o, r, s, band=band).to_dict() for o, r, s in driving_points(frf)]
    return {"reciprocity": rec.to_dict(), "driving_points": dps,
            "linearity": None if linearity is None else linearity.to_dict()}


def quality_lines(checks: dict) -> list[str]:
    """Short lines for a terminal summary of :func:`quality_checks`."""
    out = []
    lin = checks.get("linearity")
    if lin:
        bad = [m for m in lin["modes"] if m["significant"]]
        out.append("linearity: " + ("linear within the noise" if lin["verdict"] == "linear" else
                                    "nonlinear at " + ", ".join(f"{m['freq_hz']:.4g} Hz ({m['df_percent']:+.2f} %)"
                                                                for m in bad)))
    rec = checks.get("reciprocity") or {}
    if rec.get("verdict") and rec["verdict"] != "no pairs":
        line = f"reciprocity: {rec['verdict']} ({len(rec['pairs'])} pair(s))"
        if rec.get("suspects"):
            cal = rec.get("calibration") or {}
            line += "; sensor calibration off at " + ", ".join(f"{s} (x{cal.get(s, float('nan')):.3f})"
                                                              for s in rec["suspects"])
        out.append(line)
    for dp in checks.get("driving_points", []):
        if dp["ok"]:
            out.append(f"driving point {dp['point']}: phase within +-90 deg, an antiresonance between every two "
                       "resonances")
        else:
            why = []
            if not dp["phase_ok"]:
                why.append(f"mobility phase outside +-90 deg on {100 * dp['phase_outside']:.0f} % of the lines")
            if dp["missing"]:
                why.append("no antiresonance between " + ", ".join(f"{a:.4g}-{b:.4g} Hz" for a, b in dp["missing"]))
            out.append(f"driving point {dp['point']}: " + "; ".join(why) + " (sign, place or label wrong?)")
    return out


def recording_quality(path: Any, estimator: str | None = None) -> dict:
    """:func:`quality_checks` of a recording's FRFs, with the linearity of its hits when their peak forces
    span levels (:func:`analysis.linearity.recording_hits`)."""
    from .bands import FitError
    from .linearity import compare_levels, recording_hits
    from .recording import load_frfset

    frf = load_frfset(path, estimator)
    got = recording_hits(path)
    lin = None
    if got is not None and len(got[2]) >= 2:
        try:
            lin = compare_levels(got[2], got[1])
        except (FitError, ValueError):
            lin = None
    return quality_checks(frf, linearity=lin)
