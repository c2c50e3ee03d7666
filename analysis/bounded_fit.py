"""Steps 5-6 of :mod:`analysis.pipeline`: the LSFD with a frequency trust region per pole, and the
check that drops out-of-range, migrated and duplicate poles and refits."""
from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import numpy as np

from .fit_checks import MIGRATE_BANDWIDTHS, bandwidth_hz, duplicate_poles, migrated_poles
from .fit_result import MAX_DAMPING
from .frf import FRFSet
from .modal import natural_freq_hz

if TYPE_CHECKING:
    from .lsfd import LSFDResult

__all__ = ["fit_bounded", "bad_poles", "drop_bad_poles", "trust_window_hz", "MAX_DAMPING"]

log = logging.getLogger(__name__)


MAX_CHECK_ROUNDS = 4
#: a pole's decay rate stays within this factor of its start in the pipeline's LSFD: on a wide band a
#: weak mode is otherwise turned into a very damped pole that absorbs broadband misfit
DAMPING_WINDOW = 4.0
#: a pole on its upper decay-rate bound is restarted from where it ended (once) when its damping ratio is at
#: most this factor times the median of the fit's poles (damped like the structure's modes)
RESTART_DAMPING_FACTOR = 2.0


def trust_window_hz(start: np.ndarray, df: float) -> np.ndarray:
    """Half-width (Hz) of each pole's frequency trust region: MIGRATE_BANDWIDTHS bandwidths."""
    return MIGRATE_BANDWIDTHS * bandwidth_hz(start, df)


def fit_bounded(frf: FRFSet, start: np.ndarray, fit_kw: dict,
                damping_window: float = DAMPING_WINDOW) -> LSFDResult:
    """LSFD with each pole's damped frequency held within ``MIGRATE_BANDWIDTHS`` half-power
    bandwidths of its start and its decay rate within a factor ``damping_window`` of its start
    (the trust region, steps 5-7)."""
    from .lsfd import fit_lsfd

    return fit_lsfd(frf, start, freq_window_hz=trust_window_hz(start, frf.line_spacing_hz),
                    damping_window=damping_window, **fit_kw)


def bad_poles(result: LSFDResult, start: np.ndarray, df: float, duplicates: bool = True) -> tuple[np.ndarray, list[str]]:
    """Mask of fitted poles to drop (step 6) and the reasons (``duplicates=False``: without the
    duplicate check; step 7 judges its new pole's neighbours itself)."""
    lo, hi = result.band
    fd = result.poles_raw.imag / (2 * np.pi)
    z = result.damping
    out_of_range = ~((fd >= lo) & (fd <= hi) & (z > 0) & (z < MAX_DAMPING))
    on_bound = np.abs(result.poles_raw.imag - start.imag) / (2 * np.pi) >= 0.99 * trust_window_hz(start, df)
    # a decay rate on its bound (DAMPING_WINDOW) wanted to go elsewhere as well
    on_bound |= _on_damping_bound(result, start)
    migrated = (migrated_poles(start, result.poles_raw, df) | on_bound) & ~out_of_range
    moved = np.abs(natural_freq_hz(result.poles_raw) - natural_freq_hz(start)) / bandwidth_hz(start, df)
    dup = duplicate_poles(result.poles_raw, result.model.residues, df, moved=moved) & ~out_of_range & ~migrated
    if not duplicates:
        dup = np.zeros_like(dup)
    why: list[tuple[int, str]] = []
    edge = (f"pulled to its trust-region edge ({MIGRATE_BANDWIDTHS:g} half-power bandwidths from its start, or "
            f"{DAMPING_WINDOW:g} times its start's damping)")
    for mask, text in ((out_of_range, "moved out of the band or to unphysical damping"),
                       (migrated, edge),
                       (dup, "duplicates a neighbour (same resonance, same shape)")):
        for k in np.flatnonzero(mask):
            why.append((int(k), f"{natural_freq_hz(start[k]):.4g} Hz -> {result.freq_hz[k]:.4g} Hz/{100 * z[k]:.3g} %: "
                                f"{text}"))
    return out_of_range | migrated | dup, [w for _, w in sorted(why, key=lambda kw: kw[0])]


def _on_damping_bound(result: LSFDResult, start: np.ndarray) -> np.ndarray:
    """Mask of the poles whose decay rate ended on its bound (``DAMPING_WINDOW`` times its start's, or
    its start's over it)."""
    ratio = result.poles_raw.real / np.where(start.real == 0, -1e-300, start.real)
    return np.asarray((ratio >= 0.99 * DAMPING_WINDOW) | (ratio <= 1.01 / DAMPING_WINDOW))


def _damping_bound_only(result: LSFDResult, start: np.ndarray, df: float) -> np.ndarray:
    """Mask of the poles that ended on the upper decay-rate bound only (a start far too lightly damped):
    in the band, within their frequency trust region, not migrated, and damped like the fit's modes
    (at most ``RESTART_DAMPING_FACTOR`` times their median damping ratio: a mode, not a pole soaking up
    broadband misfit)."""
    lo, hi = result.band
    fd = result.poles_raw.imag / (2 * np.pi)
    z = result.damping
    in_range = (fd >= lo) & (fd <= hi) & (z > 0) & (z < MAX_DAMPING)
    freq_edge = np.abs(result.poles_raw.imag - start.imag) / (2 * np.pi) >= 0.99 * trust_window_hz(start, df)
    ratio = result.poles_raw.real / np.where(start.real == 0, -1e-300, start.real)
    like_modes = z <= RESTART_DAMPING_FACTOR * float(np.median(z[in_range])) if np.any(in_range) else np.zeros_like(z, bool)
    return np.asarray(in_range & ~freq_edge & ~migrated_poles(start, result.poles_raw, df)
                      & (ratio >= 0.99 * DAMPING_WINDOW) & like_modes)


def drop_bad_poles(frf: FRFSet, result: LSFDResult, fit_kw: dict, warnings_out: list[str]) -> LSFDResult:
    """Step 6: drop out-of-range, migrated and duplicate poles and refit (see module docstring)."""
    df = frf.line_spacing_hz
    anchor = np.asarray(result.initial_poles if result.initial_poles is not None else result.poles_raw)
    regrown = np.zeros(anchor.size, dtype=bool)
    for _ in range(MAX_CHECK_ROUNDS):
        bad, why = bad_poles(result, anchor, df)
        if not np.any(bad) or np.all(bad):
            break
        # the kept poles restart from their own starts, with the same trust regions; a pole that only hit
        # its decay-rate bound inside its frequency window (a start far too lightly damped for the data)
        # restarts once where it ended, with a trust region of its own width, instead of being dropped
        damp_only = bad & _damping_bound_only(result, anchor, df) & ~regrown
        if np.any(damp_only):
            log.info("restarted %d pole(s) from where they ended on their damping bound: %s", int(damp_only.sum()),
                     ", ".join(f"{x:.5g} Hz" for x in natural_freq_hz(result.poles_raw[damp_only])))
            anchor = np.where(damp_only, result.poles_raw, anchor)
            regrown |= damp_only
            bad &= ~damp_only
            why = [w for w, d in zip(why, np.flatnonzero(bad | damp_only)) if not damp_only[d]]
        if np.any(bad):
            msg = f"dropped {int(bad.sum())} pole(s) and refitted: " + "; ".join(why)
            log.info(msg)
            warnings_out.append(msg)
        anchor = anchor[~bad]
        regrown = regrown[~bad]
        result = fit_bounded(frf, anchor, fit_kw)
    return result
