"""The mains grid of a test from its FRFs: 50 Hz, 60 Hz, or unknown.

Electrical pickup shows as narrow lines at the harmonics ``k m`` of the grid's frequency ``m``: a
spike of ``|H|`` one or two lines wide, or a dip of the coherence where ``|H|`` has none (the
pickup is not caused by the force; a dip *with* a dip of ``|H|`` is an anti-resonance). Only the
harmonics of one grid that are not also near a harmonic of the other are looked at (300 Hz is both
6 x 50 and 5 x 60 Hz, and says nothing). The rule (:func:`detect_mains_grid`):

- a harmonic ``k m`` (``k`` = 1..``MAX_HARMONIC``, within the data) *has a line* when at least
  ``LINE_FRF_FRACTION`` of the FRFs (at least one) show, within
  :func:`analysis.bands.harmonic_tolerance_hz` of it, a spike ``LINE_DB`` above every ``|H|`` of
  its sides (``SIDE_LINES`` lines on each side beyond a gap of ``SIDE_GAP_LINES``), or a coherence
  ``COHERENCE_DIP`` (and ``DIP_SPREADS`` times the sides' spread) below the sides' median with
  ``|H|`` there no more than ``DIP_LEVEL_DB`` below theirs;
- the grid is ``m`` when at least ``MIN_LINES`` of its harmonics have a line and at least
  ``DOMINANCE`` times as many as the other grid's; otherwise it is unknown (no lines, lines on both
  families, or a line spacing above ``MAX_LINE_SPACING_HZ``, too coarse to tell the families apart).

The fit's mains check (:mod:`analysis.missing_modes`) then takes a narrow misfit peak on a harmonic
of the detected grid for an electrical line, and on a harmonic of either grid when the grid is
unknown (:func:`mains_for_fit`; ``--mains 50|60|none`` on the command line overrides).
"""
from __future__ import annotations

import logging
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .bands import LOW_LINES, MAINS_HZ, harmonic_tolerance_hz
from .frf import FRFSet

__all__ = ["MainsGrid", "detect_mains_grid", "mains_for_fit", "parse_mains_option", "MAX_HARMONIC", "LINE_DB",
           "COHERENCE_DIP", "MIN_LINES", "DOMINANCE"]

log = logging.getLogger(__name__)

#: harmonics looked at: k = 1..MAX_HARMONIC of each grid (pickup above 1 kHz is rarely seen)
MAX_HARMONIC = 20
#: a spike of |H| this many dB above every line of its sides is a line
LINE_DB = 6.0
#: a coherence this much below the median of the lines on its sides, and ``DIP_SPREADS`` times
#: their spread (few averages scatter the coherence), is a dip
COHERENCE_DIP = 0.3
DIP_SPREADS = 4.0
MAD_TO_STD = 1.4826
#: ... when |H| at the dip is no more than this many dB below the sides (else an anti-resonance)
DIP_LEVEL_DB = 3.0
#: lines on each side of a harmonic's window that give its background, beyond a gap of lines
SIDE_LINES = 8
SIDE_GAP_LINES = 2
#: the fraction of the FRFs (at least one) that must show a line at a harmonic
LINE_FRF_FRACTION = 0.25
#: a grid needs lines at this many of its own harmonics ...
MIN_LINES = 2
#: ... and this many times as many as the other grid
DOMINANCE = 3.0
#: coarser line spacings (Hz) cannot tell a line on a harmonic from its neighbours
MAX_LINE_SPACING_HZ = 2.0


@dataclass(frozen=True)
class MainsGrid:
    """What :func:`detect_mains_grid` found.

    hz : the grid's frequency (50.0 or 60.0 Hz), None when unknown.
    lines_hz : per grid frequency (Hz), the harmonics (Hz) with a line.
    tested : per grid frequency (Hz), how many of its harmonics were looked at.
    reason : one line saying why.
    """

    hz: float | None
    lines_hz: dict[float, tuple[float, ...]] = field(default_factory=dict)
    tested: dict[float, int] = field(default_factory=dict)
    reason: str = ""

    @property
    def guard_hz(self) -> tuple[float, ...]:
        """The mains frequencies (Hz) the fit's mains check uses: the grid's, else both grids'."""
        return (float(self.hz),) if self.hz else tuple(MAINS_HZ)

    def fit_note(self) -> list[str]:
        """The fit's note on a grid found in the data (none when it is unknown: the check keeps both)."""
        if self.hz is None:
            return []
        return [f"{self.describe()}: the mains check uses it (--mains 50|60|none overrides)"]

    def describe(self) -> str:
        """One line: ``mains grid 60 Hz from the data (narrow lines at 180, 240, 420 Hz; ...)``."""
        if self.hz is None:
            return f"mains grid unknown from the data ({self.reason})"
        return f"mains grid {self.hz:g} Hz from the data ({self.reason})"


def _harmonic_lines(frf: FRFSet, c: float, tol: float) -> np.ndarray | None:
    """Per FRF (flattened), whether it shows a line at ``c`` Hz (module rule), or None when the data
    do not hold the harmonic's window and both its sides."""
    f = frf.freq_hz
    df = float(frf.line_spacing_hz)
    d = f - c
    window = np.flatnonzero(np.abs(d) <= tol)
    near, far = tol + SIDE_GAP_LINES * df, tol + (SIDE_GAP_LINES + SIDE_LINES) * df
    left = np.flatnonzero((d < -near) & (d >= -far))
    right = np.flatnonzero((d > near) & (d <= far))
    if window.size == 0 or left.size < SIDE_LINES // 2 or right.size < SIDE_LINES // 2 or window[0] < LOW_LINES:
        return None
    n_frf = frf.n_outputs * frf.n_references
    sides = np.concatenate([left, right])
    H = np.asarray(frf.H).reshape(n_frf, -1)
    a_win, a_side = np.abs(H[:, window]), np.abs(H[:, sides])   # only the lines the rule reads
    with np.errstate(divide="ignore", invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)   # an FRF never measured (all NaN) shows no line
        level = np.nanmedian(a_side, axis=1)
        spike = 20.0 * np.log10(np.nanmax(a_win, axis=1) / np.nanmax(a_side, axis=1)) >= LINE_DB
        if frf.coherence is None:
            return np.asarray(spike & np.isfinite(level))
        C = np.asarray(frf.coherence).reshape(n_frf, -1)
        g_win, g_sides = C[:, window], C[:, sides]
        g_side = np.nanmedian(g_sides, axis=1)
        spread = MAD_TO_STD * np.nanmedian(np.abs(g_sides - g_side[:, None]), axis=1)
        k = np.argmin(np.where(np.isfinite(g_win), g_win, np.inf), axis=1)
        g_min = g_win[np.arange(n_frf), k]
        at_dip = a_win[np.arange(n_frf), k]
        dip = ((g_side - g_min >= np.maximum(COHERENCE_DIP, DIP_SPREADS * spread))
               & (20.0 * np.log10(at_dip / level) >= -DIP_LEVEL_DB))
    return np.asarray((spike | dip) & np.isfinite(level))


def detect_mains_grid(frf: FRFSet, grids_hz: Sequence[float] = MAINS_HZ) -> MainsGrid:
    """The mains grid of ``frf`` from the narrow lines at its grids' harmonics (module docstring);
    ``grids_hz`` the candidate grid frequencies (Hz). Reads the FRFs and their coherence, never
    changes them."""
    grids = tuple(float(m) for m in grids_hz)
    df = float(frf.line_spacing_hz)
    if not np.isfinite(df) or df > MAX_LINE_SPACING_HZ:
        return MainsGrid(None, {m: () for m in grids}, {m: 0 for m in grids},
                         f"line spacing {df:.3g} Hz is too coarse to see mains lines (at most {MAX_LINE_SPACING_HZ:g} Hz)")
    top = float(frf.freq_hz[-1])
    harmonics = {m: [(k, k * m) for k in range(1, MAX_HARMONIC + 1) if k * m < top] for m in grids}
    lines: dict[float, tuple[float, ...]] = {}
    tested: dict[float, int] = {}
    n_frf = frf.n_outputs * frf.n_references
    need = max(1, int(np.ceil(LINE_FRF_FRACTION * n_frf - 1e-9)))
    for m in grids:
        found: list[float] = []
        n = 0
        for k, c in harmonics[m]:
            tol = harmonic_tolerance_hz(k, df)
            shared = any(abs(c - c2) <= tol + harmonic_tolerance_hz(k2, df) + (SIDE_GAP_LINES + SIDE_LINES) * df
                         for m2 in grids if m2 != m for k2, c2 in harmonics[m2])
            if shared:
                continue
            seen = _harmonic_lines(frf, c, tol)
            if seen is None:
                continue
            n += 1
            if int(np.count_nonzero(seen)) >= need:
                found.append(c)
        lines[m] = tuple(found)
        tested[m] = n
    counts = {m: len(lines[m]) for m in grids}
    best = max(grids, key=lambda m: counts[m]) if grids else None
    others = [counts[m] for m in grids if m != best]
    at = "; ".join(f"{m:g} Hz: lines at {', '.join(f'{c:g}' for c in lines[m]) or 'none'} of {tested[m]} harmonics"
                   for m in grids)
    if best is not None and counts[best] >= MIN_LINES and all(counts[best] >= DOMINANCE * o for o in others):
        rest = ", ".join(f"{counts[m]} of {tested[m]} at the {m:g} Hz harmonics" for m in grids if m != best)
        grid = MainsGrid(best, lines, tested, f"narrow lines at {', '.join(f'{c:g}' for c in lines[best])} Hz; {rest}")
    elif not any(counts.values()):
        grid = MainsGrid(None, lines, tested, f"no narrow lines at the harmonics of {' or '.join(f'{m:g}' for m in grids)} Hz")
    else:
        grid = MainsGrid(None, lines, tested, f"neither grid stands out: {at}")
    log.info(grid.describe())
    return grid


def parse_mains_option(text: str) -> tuple[float, ...] | str:
    """``--mains``: ``auto`` (from the data), ``none`` (no mains check: ``()``), or frequencies in Hz,
    comma separated (``50``, ``60``, ``50,60``). Raises ValueError naming the problem."""
    t = str(text).strip().lower()
    if t in ("auto", "none"):
        return "auto" if t == "auto" else ()
    try:
        values = tuple(float(v) for v in t.split(",") if v.strip())
    except ValueError:
        values = ()
    if not values or not all(np.isfinite(v) and v > 0 for v in values):
        raise ValueError(f"--mains {text!r}: give auto, none, or the grid frequency in Hz (50 or 60)")
    return values


def mains_for_fit(mains_hz: Sequence[float] | str | None, frf: FRFSet) -> tuple[tuple[float, ...], MainsGrid | None]:
    """The mains frequencies (Hz) of the fit's mains check and, when they come from the data, the
    detection behind them: ``"auto"`` detects the grid (:func:`detect_mains_grid`; both grids when
    it is unknown), None or ``()`` means no check, frequencies are taken as given."""
    if isinstance(mains_hz, str):
        if mains_hz.strip().lower() != "auto":
            raise ValueError(f"mains_hz must be 'auto', None or frequencies in Hz; got {mains_hz!r}")
        grid = detect_mains_grid(frf)
        return grid.guard_hz, grid
    mains = tuple(float(m) for m in (mains_hz or ()))
    if any(not np.isfinite(m) or m <= 0 for m in mains):
        raise ValueError(f"mains_hz must hold positive frequencies in Hz (or be None); got {mains_hz!r}")
    return mains, None
