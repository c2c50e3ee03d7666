"""What the station page plots, as plain JSON-able dicts: one hit's traces and force spectrum, one
point's FRFs and coherence, the set-up, and a verdict with its advice.

Units: time ms, frequency Hz, force N, acceleration m/s^2, spectra and FRF magnitudes dB
(force autospectrum dB re its own maximum; FRF dB re 1 of the FRF's unit). Numbers are rounded to
5 significant digits: the page draws them, nothing is computed from them.
"""
from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np

from analysis.frf import analyser_band_hz
from analysis.geometry import Geometry
from analysis.spectra import excitation_band

__all__ = ["band_edges", "frf_payload", "geometry_payload", "hit_payload", "quality_payload", "range_advice",
           "setup_payload", "verdict_payload"]

#: most samples of a time trace sent to the page (min/max pairs keep the peaks when decimating)
MAX_TRACE_POINTS = 2400
#: most frequency lines of a spectrum or FRF sent to the page
MAX_LINES = 1600


def _round(a: np.ndarray) -> list:
    a = np.asarray(a, dtype=float)
    out = np.where(np.isfinite(a), a, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        mag = np.where(out != 0, np.floor(np.log10(np.abs(np.where(out != 0, out, 1.0)))), 0.0)
    scale = 10.0 ** (4 - np.nan_to_num(mag))
    r = np.round(out * scale) / scale
    return [None if not np.isfinite(v) else float(v) for v in r]


def _envelope(t: np.ndarray, y: np.ndarray, n_max: int) -> tuple[np.ndarray, np.ndarray]:
    """(t, y) decimated to at most ``n_max`` points as min/max pairs per bucket (keeps peaks)."""
    n = y.size
    if n <= n_max:
        return t, y
    buckets = n_max // 2
    edges = np.linspace(0, n, buckets + 1).astype(int)
    tt, yy = [], []
    for a, b in itertools.pairwise(edges):
        seg = y[a:b]
        i, j = int(np.argmin(seg)), int(np.argmax(seg))
        for k in sorted((i, j)):
            tt.append(t[a + k])
            yy.append(seg[k])
    return np.asarray(tt), np.asarray(yy)


def band_edges(freq_hz: np.ndarray, gff_db: np.ndarray) -> dict:
    """The hit's excitation band (:func:`analysis.spectra.excitation_band`) as the page shows it:
    ``minus10_hz`` and ``minus20_hz`` (Hz, None when the spectrum never falls that far)."""
    edges = excitation_band(freq_hz, gff_db, (10.0, 20.0))
    return {"minus10_hz": edges[10.0], "minus20_hz": edges[20.0]}


def _lines(freq_hz: np.ndarray, bandwidth_hz: float) -> np.ndarray:
    idx = np.nonzero(freq_hz <= bandwidth_hz)[0]
    if idx.size > MAX_LINES:
        idx = idx[np.linspace(0, idx.size - 1, MAX_LINES).astype(int)]
    return idx


def hit_payload(data: np.ndarray, fs_hz: float, trigger_index: int, pretrigger: int, force_channel: int,
                response_channels: Sequence[int], names: Sequence[str], units: Sequence[str],
                force_window_s: float | None = None) -> dict:
    """Traces of one hit (``data[n_ch, n]`` EU) and its force autospectrum.

    The force trace shows the first 0.25 s after the pre-trigger at full resolution (the pulse is
    a few ms); responses are the whole block as a min/max envelope."""
    n = data.shape[1]
    t_ms = (np.arange(n) - trigger_index) / fs_hz * 1e3
    nf = min(n, trigger_index + int(0.25 * fs_hz) + 1, MAX_TRACE_POINTS)
    f = data[force_channel]
    force = {"t_ms": _round(t_ms[:nf]), "y": _round(f[:nf]), "name": names[force_channel],
             "unit": units[force_channel]}
    responses = []
    for i in response_channels:
        tt, yy = _envelope(t_ms, data[i], MAX_TRACE_POINTS)
        responses.append({"t_ms": _round(tt), "y": _round(yy), "name": names[i], "unit": units[i]})
    spec = np.abs(np.fft.rfft(f)) ** 2
    freq = np.fft.rfftfreq(n, 1.0 / fs_hz)
    peak = float(np.max(spec)) if spec.size else 0.0
    with np.errstate(divide="ignore"):
        gff_db = 10 * np.log10(np.where(spec > 0, spec, np.nan) / peak) if peak > 0 else np.full(spec.shape, np.nan)
    idx = _lines(freq, analyser_band_hz(fs_hz))
    return {
        "force": force,
        "responses": responses,
        "trigger_ms": 0.0,
        "pretrigger_ms": -pretrigger / fs_hz * 1e3,
        "force_window_ms": None if force_window_s is None else force_window_s * 1e3,
        "spectrum": {"f_hz": _round(freq[idx]), "db": _round(gff_db[idx]),
                     **band_edges(freq, np.nan_to_num(gff_db, nan=-999.0))},
    }


def frf_payload(average: Any, bandwidth_hz: float, measured: Sequence[Any] = ()) -> dict:
    """H1, H2 (dB) and coherence per output of a point's running average
    (``acquisition.session.MeasurementAverage``), ``levels``: soft against hard hits when their forces
    spread (:func:`analysis.linearity.level_spread`, else None), and ``quality``: the point's quality
    lines (:func:`quality_payload` against the other points ``measured`` so far); empty when it has no hit yet."""
    base = {"point": average.point, "reference": average.reference, "n_averages": average.n_averages,
            "unit": average.unit, "outputs": []}
    if average.n_averages == 0:
        return base
    acc = average.acc
    freq = acc.freq_hz
    idx = _lines(freq, bandwidth_hz)
    h1, h2, coh = acc.h1(), acc.h2(), acc.coherence()
    with np.errstate(divide="ignore", invalid="ignore"):
        def db(h: np.ndarray) -> np.ndarray:
            return 20 * np.log10(np.abs(h))
        for i, o in enumerate(average.outputs):
            base["outputs"].append({"name": o, "h1_db": _round(db(h1[i, idx])), "h2_db": _round(db(h2[i, idx])),
                                    "coherence": _round(coh[i, idx])})
    base["f_hz"] = _round(freq[idx])
    from analysis.linearity import level_spread

    base["levels"] = level_spread(acc.hits, (float(freq[1]), float(bandwidth_hz)))
    base["quality"] = quality_payload(average, measured)
    return base


def quality_payload(average: Any, measured: Sequence[Any] = ()) -> list[str]:
    """Short lines of the quality checks for the point on screen (:func:`analysis.quality.quality_lines`):
    its driving point when its reference is among its outputs (:func:`analysis.driving_point.check_driving_point`
    in the band the analyser, the hammer and the coherence support),
    and reciprocity (:func:`analysis.reciprocity.reciprocity`) over the point and its partners among the
    points ``measured`` so far (running averages with at least one hit that form a pair H_ij / H_ji with
    it). Only those partners are merged, so the cost per hit stays that of a few FRFs. Empty when no
    check applies or the data cannot carry one yet (a band with no usable line)."""
    from analysis.driving_point import check_driving_point, driving_points
    from analysis.errors import FitError, RecordingError
    from analysis.quality import quality_lines
    from analysis.reciprocity import reciprocity, same_dof
    from analysis.recording import merge_frfsets

    here = average.frfset()
    partners = [a for a in measured if a is not average and a.n_averages > 0 and a.point != average.point
                and any(same_dof(a.reference, o) for o in average.outputs)
                and any(same_dof(average.reference, o) for o in a.outputs)]
    checks: dict = {"linearity": None, "reciprocity": None, "driving_points": []}
    try:
        checks["driving_points"] = [check_driving_point(here, o, r, s).to_dict()
                                    for o, r, s in driving_points(here)]
        if partners:
            checks["reciprocity"] = reciprocity(merge_frfsets([here, *(a.frfset() for a in partners)])).to_dict()
    except (FitError, RecordingError, ValueError):
        return []
    return quality_lines(checks)


def range_advice(check: Any, setup: Any, ranges_v: Sequence[float], data: np.ndarray | None) -> list[str]:
    """For each overloaded channel, the next input range up that holds the hit's peak with 20 %
    headroom (or the largest range), as a sentence for the operator."""
    out = []
    for i, over in enumerate(check.overload):
        if not over or i >= len(setup.channels):
            continue
        ch = setup.channels[i]
        peak_v = float(np.max(np.abs(data[i]))) * ch.volts_per_unit if data is not None else ch.range_v
        bigger = sorted(r for r in ranges_v if r > ch.range_v and r >= 1.2 * peak_v)
        if bigger:
            out.append(f"channel {ch.name} ({ch.point}) overloaded at {ch.range_v:g} V: set its range to {bigger[0]:g} V")
        else:
            out.append(f"channel {ch.name} ({ch.point}) overloaded at {ch.range_v:g} V, the largest range: hit softer "
                       "or use a less sensitive sensor")
    return out


def verdict_payload(summary: Any, pending: bool, advice: Sequence[str] = (), number: int | None = None) -> dict:
    """The verdict line of a hit (``acquisition.session.HitSummary``): state accepted / rejected /
    decide, reasons, and the measured properties. ``number``: the hit's number in the recording,
    counted from 1 as the session's log and the report count (None for a test hit, never recorded)."""
    c = summary.check
    if pending:
        state = "decide"
        reasons: list = []
    elif summary.reasons and str(summary.reasons[0]).startswith("test hit"):
        state = "test"
        reasons = list(summary.check.verdict.reasons) + list(summary.reasons)
    else:
        state = "accepted" if summary.decision else "rejected"
        reasons = list(summary.reasons)
    auto_rejected = c.verdict.accept is False
    return {
        "state": "rejected" if auto_rejected and state != "test" else state,
        "reasons": list(c.verdict.reasons) if auto_rejected and state != "test" else reasons,
        "double_hit": bool(c.double_hit),
        "overload": [bool(o) for o in c.overload],
        "force_peak_n": round(float(c.force_peak_n), 2),
        "pulse_width_ms": round(float(c.pulse_width_ms), 3),
        "second_peak_pct": round(100 * float(c.second_peak_ratio), 1),
        "coherence": None if summary.coherence_so_far is None else round(float(summary.coherence_so_far), 4),
        "attempt": summary.attempt,
        "hit_index": summary.hit_index,
        "number": None if state == "test" else number,
        "point": summary.point,
        "advice": list(advice),
    }


def setup_payload(setup: Any, caps: Any, windows: Any, editable: bool) -> dict:
    """The set-up panel's content: channels, trigger, windows and what the analyser offers."""
    return {
        "editable": bool(editable),
        "setup": setup.to_dict(),
        "windows": windows.to_dict(),
        "windows_text": windows.describe(),
        "capabilities": {"ranges_v": list(caps.ranges_v), "sample_rates_hz": list(caps.sample_rates_hz),
                         "block_sizes": list(caps.block_sizes), "couplings": list(caps.couplings),
                         "max_pretrigger": int(caps.max_pretrigger), "n_inputs": int(caps.n_inputs)},
    }


def geometry_payload(geometry: Geometry | None) -> dict:
    """The test-plan view's wireframe: ``{"nodes": {"left:0": [x, y, z], ...}, "lines": [["left:0",
    "left:1"], ...]}`` (m, to 10 um); empty without a geometry."""
    if geometry is None:
        return {"nodes": {}, "lines": []}
    return {"nodes": {label: [round(float(v), 5) for v in xyz] for label, xyz in zip(geometry.labels, geometry.xyz)},
            "lines": [[a, b] for a, b in geometry.lines]}
