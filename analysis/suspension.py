"""Suspension (rigid-body) modes: the resonances of a structure on its supports, below its first elastic mode.

A free-free test piece hangs on soft cords or lies on foam; it then moves as a rigid body on that
suspension at a few low frequencies (up to six: three translations, three rotations), far below its
first elastic mode (a test is set up so; the usual aim is a tenth of it). These resonances are real,
but they belong to the test set-up, not to the structure's elastic modes, and an analyst names them
instead of calling a fit that leaves them out incomplete.

The rule (:func:`suspension_modes`): the resonances of a fit, its poles and the visible peaks
(:mod:`analysis.visibility`) together, sorted by frequency and one per ``SAME_FRACTION`` of
frequency, are split at the highest gap among the lowest ``RIGID_BODY_MODES + 1`` where the next
resonance lies at least ``SUSPENSION_GAP`` times higher. The resonances below the gap are
suspension modes, the one above it is the first elastic mode. A structure without such a gap has
no suspension modes. Neither shape nor damping enters (one FRF has no shape, and a suspension
mode's damping, often high, varies with the cords): the gap alone is the rule.

On the LADISK free-free beam: 18.0 and 36.0 Hz below the first bending mode at 695.7 Hz (a gap of 19).
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .visibility import VisiblePeak

__all__ = ["suspension_modes", "split_suspension", "SUSPENSION_GAP", "RIGID_BODY_MODES"]

#: a resonance at most 1 / SUSPENSION_GAP of the next one up (the first elastic mode) is a suspension mode
SUSPENSION_GAP = 5.0
#: a rigid body has at most this many suspension modes
RIGID_BODY_MODES = 6
#: resonances closer than this fraction of their frequency are one
SAME_FRACTION = 0.02


def suspension_modes(freqs_hz: Sequence[float] | np.ndarray) -> tuple[np.ndarray, float | None]:
    """The suspension modes among the resonances ``freqs_hz`` (Hz; module docstring): their
    frequencies (Hz, sorted, one per resonance) and the first elastic mode's (Hz), or an empty array
    and None when the resonances show no such gap."""
    f = np.sort(np.asarray(freqs_hz, dtype=float).ravel())
    f = f[np.isfinite(f) & (f > 0)]
    distinct: list[float] = []
    for x in f:
        if not distinct or x > distinct[-1] * (1.0 + SAME_FRACTION):
            distinct.append(float(x))
    gaps = [i for i in range(min(RIGID_BODY_MODES, len(distinct) - 1))
            if distinct[i + 1] >= SUSPENSION_GAP * distinct[i]]
    if not gaps:
        return np.zeros(0), None
    i = gaps[-1]
    return np.asarray(distinct[:i + 1]), distinct[i + 1]


def split_suspension(visible: Sequence[VisiblePeak], fitted_hz: np.ndarray
                     ) -> tuple[list[VisiblePeak], tuple[float, ...], list[str]]:
    """The fit's suspension modes (:func:`suspension_modes` over its poles ``fitted_hz`` (Hz) and the
    visible peaks ``visible``): ``(peaks left for the verdict, suspension frequencies in Hz, notes)``.
    A visible peak at a suspension mode is not a resonance the fit misses; a pole there is kept and
    named."""
    fitted = np.asarray(fitted_hz, dtype=float).ravel()
    sus, elastic = suspension_modes(np.concatenate([fitted, [v.freq_hz for v in visible]]))
    if elastic is None:
        return list(visible), (), []

    def at_suspension(x: float) -> bool:
        return bool(np.any(np.abs(sus - x) <= SAME_FRACTION * sus))

    near = fitted[np.abs(fitted - elastic) <= SAME_FRACTION * elastic]
    if near.size:   # the first elastic mode as fitted, not its peak's line
        elastic = float(near[np.argmin(np.abs(near - elastic))])
    kept = [v for v in visible if not at_suspension(v.freq_hz)]
    poles = [float(x) for x in fitted if at_suspension(float(x))]
    named = ", ".join(f"{x:.5g}" for x in sus)
    note = (f"suspension mode(s) at {named} Hz: the structure moving as a rigid body on its supports, "
            f"at most 1/{SUSPENSION_GAP:g} of the first elastic mode ({elastic:.5g} Hz); not elastic modes of the "
            "structure")
    note += (f"; the pole(s) at {', '.join(f'{x:.5g}' for x in poles)} Hz stand for them" if poles
             else "; not fitted (the residual terms take them)")
    return kept, tuple(float(x) for x in sus), [note]
