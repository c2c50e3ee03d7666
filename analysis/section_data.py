"""The data the report's sections and the PNG figures both draw, computed once: the stabilization
diagram's rows, the mode indicator at the report's resolution, the measured and synthesised FRFs
(:mod:`analysis.report_html.collect` puts them in the report document, :mod:`analysis.plots` draws
them). JSON-able, numbers rounded for a compact page.

Units: frequencies Hz, magnitudes dB re 1 (FRF unit), phases deg, damping ratio.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .frf import FRFSet
from .mif import indicator_summary, summed_magnitude_db
from .modal import damping_ratio, natural_freq_hz
from .stabilization import CLASS_NAMES

if TYPE_CHECKING:
    from .stabilization import StabilizationResult

__all__ = ["INDICATOR_POINTS", "NONPHYSICAL", "indicator_data", "magnitude_db", "rounded", "stabilization_rows",
           "synthesis_traces"]

#: lines of the mode-indicator plot at most (bins keep their CMIF peak)
INDICATOR_POINTS = 1500


def rounded(a: Any, decimals: int) -> list:
    """Rounded nested list; non-finite values become None (JSON null)."""
    x = np.round(np.asarray(a, dtype=float), decimals)
    if np.all(np.isfinite(x)):
        return x.tolist()
    out = x.astype(object)
    out[~np.isfinite(x)] = None
    return out.tolist()


def magnitude_db(z: np.ndarray, floor: bool = True) -> np.ndarray:
    """20 log10 |z|; zeros floored 240 dB below the largest (``floor`` False: -inf, a gap once rounded)."""
    a = np.abs(z)
    if not floor:
        with np.errstate(divide="ignore"):
            return 20 * np.log10(a)
    low = max(float(np.nanmax(a)) * 1e-12, 1e-300) if a.size else 1e-300
    return 20 * np.log10(np.maximum(a, low))


def indicator_data(frf: FRFSet, band: Sequence[float]) -> dict:
    """The mode indicator over ``band`` (Hz) as the report and the figures draw it
    (:func:`analysis.mif.indicator_summary` with at most :data:`INDICATOR_POINTS` lines)."""
    return indicator_summary(frf, (float(band[0]), float(band[1])), max_points=INDICATOR_POINTS)


def synthesis_traces(frf: FRFSet, H: np.ndarray, G: np.ndarray, pairs: Sequence[tuple[int, int]], *,
                     phase: bool = False, floor: bool = True) -> list[dict]:
    """The measured FRFs ``H`` (``frf.H`` at some lines) and the synthesised ``G`` at the same lines, one
    dict per (output, reference) of ``pairs``: ``name``, ``measured_db`` and ``synth_db`` (dB re 1 FRF unit);
    with ``phase``: ``measured_phase_deg``, ``synth_phase_deg`` (deg) and ``rel_error_db``
    (``|H - G| / |H|`` in dB, None where undefined). ``G`` with a single output or reference serves
    every FRF of that axis. ``floor`` False: a zero magnitude is None (a gap), not floored."""
    out = []
    for o, r in pairs:
        h, g = H[o, r], G[min(o, G.shape[0] - 1), min(r, G.shape[1] - 1)]
        t = {"name": f"{frf.outputs[o]} / {frf.references[r]}", "measured_db": rounded(magnitude_db(h, floor), 2),
             "synth_db": rounded(magnitude_db(g, floor), 2)}
        if phase:
            with np.errstate(divide="ignore", invalid="ignore"):
                rel_db = 20 * np.log10(np.abs(h - g) / np.abs(h))
            t.update({"measured_phase_deg": rounded(np.degrees(np.angle(h)), 1),
                      "synth_phase_deg": rounded(np.degrees(np.angle(g)), 1), "rel_error_db": rounded(rel_db, 2)})
        out.append(t)
    return out


#: The class of the poles that are not physical (outside the band or damping out of range), only with
#: ``nonphysical`` in :func:`stabilization_rows`.
NONPHYSICAL = "non-physical"


def stabilization_rows(frf: FRFSet, stab: StabilizationResult | None, band: Sequence[float],
                       fitted_poles: np.ndarray | None = None, *, nonphysical: bool = False) -> dict:
    """Poles per order by class (``classes`` None without a stabilization ``stab``, e.g. a fit read
    from a file; per class ``freq_hz`` (Hz), ``order`` and ``damping`` (ratio) of every physical pole, for
    the page's pole picking; with ``nonphysical`` also the class :data:`NONPHYSICAL`: the other poles
    whose damped frequency lies in the band), the summed FRF (dB) over the band (the stabilization's,
    else ``band``, Hz), the natural frequencies (Hz) of ``fitted_poles`` (rad/s; None: none) and the band."""
    lo, hi = band if stab is None else stab.band
    sel = (frf.freq_hz >= lo) & (frf.freq_hz <= hi)
    fitted = np.zeros(0) if fitted_poles is None else natural_freq_hz(np.asarray(fitted_poles))
    doc = {"classes": None, "freq_hz": rounded(frf.freq_hz[sel], 4), "summed_db": rounded(summed_magnitude_db(frf)[sel], 2),
           "fitted_hz": rounded(np.sort(fitted), 4), "method": None, "max_order": None,
           "band_hz": [float(lo), float(hi)]}
    if stab is None:
        return doc
    names = (NONPHYSICAL, *CLASS_NAMES) if nonphysical else CLASS_NAMES
    classes: dict[str, dict] = {name: {"freq_hz": [], "order": [], "damping": []} for name in names}
    for n, p, ph, s in zip(stab.orders, stab.poles, stab.physical, stab.status):
        fd = p.imag / (2 * np.pi)
        shown = ph | ((fd >= lo) & (fd <= hi)) if nonphysical else ph
        for i in np.flatnonzero(shown):
            c = classes[CLASS_NAMES[int(s[i])] if ph[i] else NONPHYSICAL]
            c["freq_hz"].append(round(float(natural_freq_hz(p[i])), 4))
            c["order"].append(int(n))
            c["damping"].append(float(f"{float(damping_ratio(p[i])):.6g}"))
    return {**doc, "classes": classes, "method": stab.method, "max_order": int(max(stab.orders))}
