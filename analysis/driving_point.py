"""Is the driving-point FRF physical? Its mobility's phase and its antiresonances.

At a driving point (response measured where and along which the force acts) a passive structure's
mobility ``Y = v / F`` has a non-negative real part: its phase stays within -90..+90 degrees. Between
every two resonances of a driving-point FRF lies an antiresonance (the mobility's phase rises again
between them). A phase outside the range (beyond the noise) or a missing antiresonance
points at a wrong sign, a sensor not at the struck point, or a mislabelled channel.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .frf import FRFSet
from .peaks import PEAK_RULES, find_peaks
from .reciprocity import finite_or_none, frf_error_variance, same_dof

__all__ = ["DrivingPointCheck", "driving_points", "check_driving_point"]

PHASE_TOLERANCE_DEG = 10.0
PEAK_PROMINENCE_DB = PEAK_RULES["modal_peaks"].prominence_db
ANTIRESONANCE_DEPTH_DB = 3.0
MIN_PHASE_RISE_DEG = 20.0
MIN_COHERENCE = 0.5


@dataclass(frozen=True)
class DrivingPointCheck:
    """One driving point: ``point`` label; ``phase_ok`` and the share of lines whose mobility phase is outside
    +-(90 + tolerance) degrees beyond the noise (``phase_outside``); ``resonances_hz`` (the peaks),
    ``antiresonances_hz`` (one per gap, NaN where missing) and ``missing`` (the gaps (f1, f2) Hz without one)."""

    point: str
    phase_ok: bool
    phase_outside: float
    resonances_hz: tuple
    antiresonances_hz: tuple
    missing: tuple

    @property
    def ok(self) -> bool:
        return self.phase_ok and not self.missing

    def to_dict(self) -> dict:
        return {"point": self.point, "ok": self.ok, "phase_ok": self.phase_ok, "phase_outside": self.phase_outside,
                "resonances_hz": list(self.resonances_hz),
                "antiresonances_hz": [finite_or_none(a) for a in self.antiresonances_hz],
                "missing": [list(m) for m in self.missing]}


def driving_points(frf: FRFSet) -> list[tuple[int, int, int]]:
    """(output, reference, sign) of every driving-point FRF of the set."""
    out = []
    for o, lab in enumerate(frf.outputs):
        for r, rl in enumerate(frf.references):
            s = same_dof(lab, rl)
            if s and np.all(np.isfinite(frf.H[o, r])):
                out.append((o, r, s))
    return out


def check_driving_point(frf: FRFSet, output: int, reference: int, sign: int = 1,
                        band: Sequence[float] | None = None,
                        tolerance_deg: float = PHASE_TOLERANCE_DEG,
                        prominence_db: float = PEAK_PROMINENCE_DB) -> DrivingPointCheck:
    """Check one driving-point FRF ``H[output, reference]`` (times ``sign``) in ``band`` (Hz; default
    :func:`analysis.bands.default_band`: what the analyser, the hammer and the coherence support). Lines
    whose coherence is below ``MIN_COHERENCE`` are left out. Inputs are not modified."""
    from .bands import default_band

    f = frf.freq_hz
    lo, hi = (float(band[0]), float(band[1])) if band is not None else default_band(frf)
    sel = (f >= lo) & (f <= hi) & (f > 0)
    if frf.coherence is not None:
        sel &= ~(frf.coherence[output, reference] < MIN_COHERENCE)
    mob = frf.as_quantity("mobility").H[output, reference, sel] * sign
    fb = f[sel]
    var = frf_error_variance(frf)
    ph = np.degrees(np.angle(mob))
    lim = 90.0 + tolerance_deg
    if var is not None:
        # noise of the phase (rad): sqrt(var / 2) / |H|, per line
        sd = np.degrees(np.sqrt(var[output, reference, sel] / 2.0) / np.maximum(np.abs(frf.H[output, reference, sel]),
                                                                                  1e-300))
    else:
        sd = np.zeros(fb.size)
    outside = np.abs(ph) > lim + 3.0 * sd
    share = float(np.mean(outside)) if fb.size else 0.0
    mag = 20.0 * np.log10(np.maximum(np.abs(mob), 1e-300))
    peaks, _ = find_peaks(mag, **PEAK_RULES["modal_peaks"].options(prominence_db))
    anti, missing = [], []
    for p1, p2 in zip(peaks[:-1], peaks[1:]):
        # the mobility's phase falls by up to 180 degrees through each resonance and rises again at the
        # antiresonance between them (damping may keep it below zero when the two are close); without an
        # antiresonance it keeps falling
        # antiresonance: the imaginary part turns from negative (mass-like) back to positive, or (close
        # pairs) the phase rises by at least MIN_PHASE_RISE_DEG
        seg = np.degrees(np.unwrap(np.angle(mob[p1:p2 + 1])))
        rise = float(np.max(seg - np.minimum.accumulate(seg)))
        im = mob[p1:p2 + 1].imag
        turns = bool(np.any((im[:-1] < 0) & (im[1:] >= 0)))
        dips = mag[p1:p2 + 1]
        k = int(np.argmin(dips))
        deep = dips[k] < min(mag[p1], mag[p2]) - ANTIRESONANCE_DEPTH_DB
        if (turns or rise >= MIN_PHASE_RISE_DEG) and deep:
            anti.append(float(fb[p1 + k]))
        else:
            anti.append(float("nan"))
            missing.append((float(fb[p1]), float(fb[p2])))
    return DrivingPointCheck(point=frf.outputs[output], phase_ok=share <= 0.01, phase_outside=share,
                             resonances_hz=tuple(float(x) for x in fb[peaks]), antiresonances_hz=tuple(anti),
                             missing=tuple(missing))
