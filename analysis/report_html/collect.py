"""The report's content as JSON-able dictionaries (numbers rounded for a compact page).

Units: frequencies Hz, magnitudes dB re 1 (FRF unit), phases deg, times ms, forces N, damping %.
"""
from __future__ import annotations

import numpy as np

from ..frf import QUANTITY_UNIT, FRFSet
from ..geometry import Geometry, node_label
from ..mac import mac_matrix
from ..modal import ModalModel, damping_ratio, natural_freq_hz, synthesize
from ..points import label_direction
from ..section_data import indicator_data, stabilization_rows, synthesis_traces
from ..section_data import magnitude_db as _db
from ..section_data import rounded as _r
from ..spectra import excitation_band as spectra_excitation_band
from ..spectra import hit_spectra
from .sources import FitData, TestRecord

__all__ = [
    "MAX_TIME_POINTS",
    "VISIBLE_FRFS",
    "excitation_band",
    "frf_section",
    "modal_section",
    "mpc",
    "points_section",
    "shape_vectors",
    "shapes_section",
    "stabilization_data",
    "test_section",
]

#: time histories are reduced to at most this many points (min/max envelope)
MAX_TIME_POINTS = 1600
#: FRFs drawn when the page opens (the strongest); the others are one legend click away
VISIBLE_FRFS = 4
#: FRFs shown in the synthesis plot
SYNTHESIS_FRFS = 3


def _fmt(x: float, digits: int = 4) -> str:
    return f"{x:.{digits}g}"


def _pairs(frf: FRFSet) -> list[tuple[int, int]]:
    """(output, reference) indices, strongest RMS first."""
    rms = np.sqrt(np.nanmean(np.abs(frf.H) ** 2, axis=2))
    rows, cols = np.unravel_index(np.argsort(-rms, axis=None), rms.shape)
    return [(int(o), int(r)) for o, r in zip(rows, cols)]


def frf_section(frf: FRFSet) -> dict:
    """Magnitude (dB), phase (deg) and coherence of every FRF, strongest first."""
    traces = []
    order = _pairs(frf)
    for k, (o, r) in enumerate(order):
        h = frf.H[o, r]
        t = {"name": f"{frf.outputs[o]} / {frf.references[r]}", "mag_db": _r(_db(h), 2),
             "phase_deg": _r(np.degrees(np.angle(h)), 1), "visible": k < VISIBLE_FRFS}
        if frf.coherence is not None:
            t["coh"] = _r(frf.coherence[o, r], 3)
        traces.append(t)
    return {"freq_hz": _r(frf.freq_hz, 4), "traces": traces, "quantity": frf.quantity,
            "unit": frf.unit or QUANTITY_UNIT.get(frf.quantity, ""), "has_coherence": frf.coherence is not None,
            "n_outputs": frf.n_outputs, "n_references": frf.n_references,
            "exp_window_tau_s": frf.exp_window_tau_s}


def mpc(phi: np.ndarray) -> float:
    """Modal phase collinearity (0..1, 1: a real mode) of a complex shape vector."""
    re, im = np.real(phi), np.imag(phi)
    S = np.array([[re @ re, re @ im], [re @ im, im @ im]])
    ev = np.linalg.eigvalsh(S)
    tot = float(ev.sum())
    return float(((ev[1] - ev[0]) / tot) ** 2) if tot > 0 else float("nan")


def shape_vectors(model: ModalModel) -> tuple[list[str], np.ndarray]:
    """Point labels and (n_dof, m) complex shapes: per mode, the residue row/column of the larger
    point set (references for a roving hammer, outputs for a roving sensor) with the largest norm;
    phase-rotated so the largest entry is real positive, scaled to a largest modulus of 1."""
    R = np.asarray(model.residues)
    n_out, n_ref, m = R.shape
    over_refs = n_ref > n_out
    labels = list(model.references if over_refs else model.outputs)
    shapes = np.zeros((len(labels), m), complex)
    for k in range(m):
        block = R[:, :, k] if over_refs else R[:, :, k].T  # rows: the other set
        row = block[int(np.argmax(np.linalg.norm(block, axis=1)))]
        big = row[int(np.argmax(np.abs(row)))]
        if abs(big) > 0:
            shapes[:, k] = row * np.exp(-1j * np.angle(big)) / abs(big)
    return labels, shapes


def modal_section(frf: FRFSet, fit: FitData) -> dict:
    """Mode table, synthesis vs measurement with relative error, AutoMAC, stabilization."""
    model = fit.model
    order = np.argsort(natural_freq_hz(model.poles))
    f = natural_freq_hz(model.poles)[order]
    z = damping_ratio(model.poles)[order]
    labels, shapes = shape_vectors(model)
    shapes = shapes[:, order]
    modes = []
    for k, i in enumerate(order):
        p = mpc(shapes[:, k])
        modes.append({"n": k + 1, "freq_hz": float(f[k]), "damping_pct": 100 * float(z[k]),
                      "freq_std_hz": _finite(fit.freq_hz_std[i]), "damping_std_pct": _finite(100 * fit.damping_std[i]),
                      "mpc": _finite(p), "complexity_pct": _finite(100 * (1 - p))})
    lo, hi = fit.band
    sel = (frf.freq_hz >= lo) & (frf.freq_hz <= hi)
    fb = frf.freq_hz[sel]
    H = frf.H[..., sel]
    G = synthesize(fit.model_raw, fb).H
    ok = np.isfinite(H)
    num = np.sqrt(np.nansum(np.where(ok, np.abs(H - G) ** 2, 0), axis=(0, 1)))
    den = np.sqrt(np.nansum(np.where(ok, np.abs(H) ** 2, 0), axis=(0, 1)))
    rel = num / np.where(den > 0, den, np.nan)
    total = float(np.sqrt(np.sum(num ** 2)) / np.sqrt(np.sum(den ** 2))) if np.sum(den) > 0 else float("nan")
    synth = synthesis_traces(frf, H, G, _pairs(frf)[:SYNTHESIS_FRFS])
    mac = mac_matrix(shapes, shapes) if shapes.size else np.zeros((0, 0))
    return {"band_hz": [float(lo), float(hi)], "modes": modes, "source": fit.source, "warnings": list(fit.warnings),
            "synthesis": {"freq_hz": _r(fb, 4), "frfs": synth, "rel_error_db": _r(20 * np.log10(
                np.maximum(rel, 1e-6)), 2), "rel_rms": _finite(total)},
            "automac": _r(mac, 3), "shape_points": len(labels), "stabilization": stabilization_data(frf, fit),
            "indicator": indicator_data(frf, (lo, hi) if fit.stab is None else fit.stab.band)}


def _finite(x: float) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def stabilization_data(frf: FRFSet, fit: FitData) -> dict:
    """The stabilization section of a fit: :func:`stabilization_rows` of its stabilization (when it has
    one), its band and its fitted poles."""
    return stabilization_rows(frf, fit.stab, fit.band, fit.model.poles)


def _axis_sign(label: str) -> tuple[int, int]:
    """Axis (0, 1, 2 for X, Y, Z) and sign of a point label; a label that is not
    ``component:node:direction`` (e.g. ``view0:acc:Z`` of another tool) keeps a direction written
    as its last part, else it moves along Z (:func:`analysis.points.label_direction`)."""
    d = label_direction(label)
    return abs(d) - 1, 1 if d > 0 else -1


def shapes_section(fit: FitData, geometry: Geometry) -> dict:
    """Geometry and, per mode, the complex displacement (re, im) of every measured DOF."""
    labels, shapes = shape_vectors(fit.model)
    order = np.argsort(natural_freq_hz(fit.model.poles))
    shapes = shapes[:, order]
    dofs = []
    for lab in labels:
        axis, sign = _axis_sign(lab)
        dofs.append({"label": lab, "node": geometry.index(node_label(lab)), "axis": axis, "sign": sign})
    f = natural_freq_hz(fit.model.poles)[order]
    return {"geometry": geometry.to_dict(), "dofs": dofs,
            "modes": [{"freq_hz": float(f[k]), "re": _r(shapes[:, k].real, 4), "im": _r(shapes[:, k].imag, 4)}
                      for k in range(shapes.shape[1])]}


def _envelope(t: np.ndarray, y: np.ndarray, n_max: int) -> tuple[np.ndarray, np.ndarray]:
    """At most ``n_max`` points keeping each bin's min and max (peaks survive the reduction)."""
    if y.size <= n_max:
        return t, y
    bins = n_max // 2
    edges = np.linspace(0, y.size, bins + 1).astype(int)
    tt, yy = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        seg = y[a:b]
        i, j = a + int(np.argmin(seg)), a + int(np.argmax(seg))
        for k in sorted((i, j)):
            tt.append(t[k])
            yy.append(y[k])
    return np.asarray(tt), np.asarray(yy)


def excitation_band(freq_hz: np.ndarray, gff_db: np.ndarray) -> dict:
    """The excitation band (:func:`analysis.spectra.excitation_band`) as the page draws it:
    ``f10_hz`` and ``f20_hz`` (Hz, None when the force spectrum never falls that far)."""
    edges = spectra_excitation_band(freq_hz, gff_db, (10.0, 20.0))
    return {"f10_hz": edges[10.0], "f20_hz": edges[20.0]}


def points_section(rec: TestRecord) -> list[dict]:
    """Per point: force and response time histories (ms, EU) and the force autospectrum (dB re 1 N^2/Hz)."""
    out = []
    units: dict[str, str] = {}
    for c in rec.channels:
        d = str(c.get("direction", ""))
        for key in (str(c.get("point", "")), f"{c.get('point', '')}:{d}", str(c.get("name", ""))):
            units.setdefault(key, str(c.get("unit", "")))
    for point, p in rec.points.items():
        fs, k0 = float(p["fs_hz"]), int(p["trigger_index"])
        force, resp = p["force"], p["responses"]
        n = force.shape[1]
        t_ms = (np.arange(n) - k0) / fs * 1e3
        windows = rec.windows
        gff = np.mean([hit_spectra(force[h], resp[h], fs, k0, windows).Gff for h in range(force.shape[0])], axis=0)
        freq = np.fft.rfftfreq(n, 1 / fs)
        gdb = 10 * np.log10(np.maximum(gff, max(float(gff.max()) * 1e-15, 1e-300)))
        fsel = np.linspace(0, freq.size - 1, min(freq.size, 1200)).astype(int)
        # the force pulse: from 5 ms before the trigger to 4x the force window (or 50 ms) after it
        width = (windows.force_width_s if windows is not None and windows.force_width_s else 0.0125) * 4e3
        fw = (t_ms >= -5) & (t_ms <= max(width, 50.0))
        last = force.shape[0] - 1
        tr, fr = _envelope(t_ms[fw], force[last][fw], MAX_TIME_POINTS)
        responses = []
        for c, label in enumerate(p["outputs"]):
            tx, yx = _envelope(t_ms, resp[last, c], MAX_TIME_POINTS)
            responses.append({"name": label, "unit": units.get(label, ""), "t_ms": _r(tx, 2), "y": _r(yx, 5)})
        out.append({"point": point, "n_hits": int(force.shape[0]), "force": {"t_ms": _r(tr, 3), "y": _r(fr, 3)},
                    "responses": responses,
                    "spectrum": {"freq_hz": _r(freq[fsel], 3), "gff_db": _r(gdb[fsel], 2),
                                 **excitation_band(freq, gdb)}})
    return out


def test_section(rec: TestRecord) -> dict:
    """The test description: device, date, channels, trigger, windows, plan, hits."""
    trig = rec.setup.get("trigger", {})
    win = rec.windows.to_dict() if rec.windows is not None else {}
    accepted = sum(1 for h in rec.hits if h["accepted"])
    return {"device": rec.device, "date": rec.date, "instrument": rec.instrument,
            "sample_rate_hz": rec.setup.get("sample_rate_hz"), "block_size": rec.setup.get("block_size"),
            "channels": rec.channels, "trigger": trig, "windows": win, "plan": rec.plan,
            "points": list(rec.plan.get("points", [])), "hits": rec.hits, "accepted": accepted,
            "rejected": len(rec.hits) - accepted}


