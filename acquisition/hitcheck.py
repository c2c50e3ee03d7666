"""Per-hit quality checks of an impact: force peak, pulse width, overloads, double hits.

Definitions (force ``f[n]`` in N at ``fs`` Hz):

* force peak ``F_pk = f[n_pk]`` with ``n_pk = argmax |f|`` (N, signed like the hit);
* pulse: the contiguous run of samples around ``n_pk`` with ``s*f >= level * |F_pk|``
  (``s`` the sign of the peak, ``level`` = 10 % by default); pulse width = run length / fs (ms);
* double hit: after the pulse ends plus a guard of one pulse width, the largest same-sign force
  ``s*f`` exceeds ``double_hit_fraction * |F_pk|`` (default 0.1): the hammer struck again;
* overload: any channel whose ADC clipped (the analyser's per-channel flag).

Overloads and double hits reject the hit automatically (``accept=False``, with the reasons);
otherwise the verdict is ``accept=None``: the operator (or ``--auto``) decides.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["HitVerdict", "HitCheck", "HitCheckSettings", "check_hit", "pulse_extent"]


@dataclass
class HitVerdict:
    """accept: False = rejected automatically, None = operator decides, True = accepted."""

    accept: bool | None
    reasons: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class HitCheckSettings:
    """Thresholds: pulse level (fraction of peak), double-hit fraction, minimum force peak (N)."""

    pulse_level: float = 0.1
    double_hit_fraction: float = 0.1
    min_force_n: float = 0.0

    def __post_init__(self) -> None:
        if not 0 < self.pulse_level < 1:
            raise ValueError(f"pulse level {self.pulse_level} must lie strictly between 0 and 1")
        if not 0 < self.double_hit_fraction < 1:
            raise ValueError(f"double-hit fraction {self.double_hit_fraction} must lie strictly between 0 and 1")
        if self.min_force_n < 0:
            raise ValueError(f"minimum force {self.min_force_n} N must be >= 0")


@dataclass(frozen=True)
class HitCheck:
    """Measured hit properties and the verdict."""

    force_peak_n: float
    pulse_width_ms: float
    pulse_start: int
    pulse_end: int
    second_peak_ratio: float
    double_hit: bool
    overload: tuple
    verdict: HitVerdict

    def to_dict(self) -> dict:
        return {
            "force_peak_n": self.force_peak_n,
            "pulse_width_ms": self.pulse_width_ms,
            "second_peak_ratio": self.second_peak_ratio,
            "double_hit": self.double_hit,
            "overload": list(self.overload),
            "accept": self.verdict.accept,
            "reasons": list(self.verdict.reasons),
        }


def pulse_extent(force: np.ndarray, level: float = 0.1) -> tuple[int, int, int]:
    """(peak index, first index, one past the last index) of the pulse around the largest |force|."""
    f = np.asarray(force, dtype=float)
    k = int(np.argmax(np.abs(f)))
    s = 1.0 if f[k] >= 0 else -1.0
    thr = level * abs(f[k])
    above = s * f >= thr
    below_before = np.flatnonzero(~above[:k])
    start = int(below_before[-1]) + 1 if below_before.size else 0
    below_after = np.flatnonzero(~above[k:])
    end = k + int(below_after[0]) if below_after.size else f.size
    return k, start, end


def check_hit(
    force: np.ndarray,
    fs_hz: float,
    overload: Sequence[bool] = (),
    channel_names: Sequence[str] = (),
    settings: HitCheckSettings = HitCheckSettings(),
) -> HitCheck:
    """Check one hit; ``force`` in N (1-D), ``overload`` one flag per channel."""
    f = np.asarray(force, dtype=float)
    if f.ndim != 1 or f.size < 3:
        raise ValueError(f"force must be a 1-D record of at least 3 samples; got shape {f.shape}")
    if not fs_hz > 0:
        raise ValueError(f"sample rate {fs_hz} Hz must be positive")
    k, start, end = pulse_extent(f, settings.pulse_level)
    peak = float(f[k])
    width_ms = (end - start) / fs_hz * 1e3
    reasons: list[str] = []
    ovl = tuple(bool(o) for o in overload)
    for i, o in enumerate(ovl):
        if o:
            name = channel_names[i] if i < len(channel_names) else f"channel {i + 1}"
            reasons.append(f"overload on channel {i + 1} ({name}): raise its input range or hit softer")
    ratio = 0.0
    guard_end = end + (end - start)
    if abs(peak) > 0 and guard_end < f.size:
        s = 1.0 if peak >= 0 else -1.0
        ratio = float(np.max(s * f[guard_end:]) / abs(peak))
        ratio = max(ratio, 0.0)
    double = ratio > settings.double_hit_fraction
    if double:
        reasons.append(
            f"double hit: a second force peak of {100 * ratio:.0f} % of the first after the pulse; "
            "hit again with a quick rebound"
        )
    if abs(peak) < settings.min_force_n:
        reasons.append(f"force peak {abs(peak):.3g} N below the minimum {settings.min_force_n:.3g} N: hit harder")
    verdict = HitVerdict(accept=False if reasons else None, reasons=reasons)
    return HitCheck(peak, width_ms, start, end, ratio, double, ovl, verdict)
