"""Step 7 of :mod:`analysis.pipeline`: resonances the fitted model misses (see the pipeline's module
docstring): misfit peaks are tried as new poles, kept only on clear evidence, with a guard
against mains lines."""
from __future__ import annotations

import logging
import warnings
from typing import Optional, Sequence

import numpy as np
from .peaks import find_peaks

from .fit_checks import (DUPLICATE_BANDWIDTHS, DUPLICATE_MAC, bandwidth_hz)
from .frf import FRFSet
from .mac import mac
from .modal import damping_ratio, natural_freq_hz, pole_from_fz, transfer

from .bands import MAINS_DEVIATION_HZ, MAINS_HZ, MAINS_LINES, mains_harmonic_index
from .bounded_fit import bad_poles, fit_bounded

__all__ = ["add_missing_modes", "MAINS_HZ"]

log = logging.getLogger(__name__)


MISSING_MEDIAN_FACTOR = 4.0
MISSING_DATA_FRACTION = 0.25
MISSING_MIN_GAIN = 0.01
MAX_ADDED = 8
MISSING_BANDWIDTH_RATIO = 4.0
MAX_FAILED_TRIES = 2
MISSING_MIN_LINES = 3
MISSING_TRIAL_ITER = 40
MISSING_LOCAL_GAIN = 0.3
MISSING_MIN_RESIDUE_RATIO = 0.05
MISSING_CANCEL_RATIO = 0.2
MAINS_WIDTH_FRACTION = 0.5


def _synthesize_flat(model, f: np.ndarray) -> np.ndarray:
    """``synthesize(model, f).H`` flattened to (n_frf, n_f), by matrix products (BLAS): the same
    sum (eq. 11), several times faster than the general einsum on big sets."""
    return transfer(model, 2j * np.pi * f).reshape(-1, f.size)


def _scaled_misfit(frf: FRFSet, result) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(freq_hz, e, d) of step 7: RMS-scaled misfit and data over the FRFs, per line of the band."""
    lo, hi = result.band
    sel = (frf.freq_hz >= lo) & (frf.freq_hz <= hi)
    f = frf.freq_hz[sel]
    H = frf.H[..., sel].reshape(-1, f.size)
    G = _synthesize_flat(result.model_raw, f)
    rms = np.sqrt(np.mean(H.real ** 2 + H.imag ** 2, axis=1))
    live = np.isfinite(rms) & (rms > 0)
    if not np.all(live):
        H, G, rms = H[live], G[live], rms[live]
    w = (1.0 / rms ** 2)[:, None]
    E = H - G
    e = np.sqrt(np.mean((E.real ** 2 + E.imag ** 2) * w, axis=0))
    d = np.sqrt(np.mean((H.real ** 2 + H.imag ** 2) * w, axis=0))
    return f, e, d


def _missing_candidates(f: np.ndarray, e: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Frequencies (Hz) of the misfit peaks of step 7, strongest first."""
    level = MISSING_MEDIAN_FACTOR * float(np.median(e))
    pk, _ = find_peaks(e)
    pk = pk[(e[pk] > level) & (e[pk] > MISSING_DATA_FRACTION * d[pk])]
    return f[pk[np.argsort(-e[pk])]]


def _new_pole_relation(poles_raw: np.ndarray, residues: np.ndarray, df: float) -> tuple[bool, np.ndarray]:
    """How the last (added) pole relates to the others: ``(broad, close)``.

    broad : a broad pole under a much sharper neighbour (within the larger half-bandwidth,
        bandwidths more than ``MISSING_BANDWIDTH_RATIO`` apart): it absorbs the misfit of the
        sharp peak (leakage, a slightly non-modal peak shape), not a mode.
    close : indices of the neighbours it is hard to tell from: closer than ``MISSING_MIN_LINES``
        lines or a quarter of the smaller bandwidth, or a duplicate in the sense of
        :func:`analysis.fit_checks.duplicate_poles` (within half the larger bandwidth, residue
        MAC > ``DUPLICATE_MAC``). Such a pole is kept only on clear evidence
        (:func:`_pair_is_resolved`).
    """
    b = bandwidth_hz(poles_raw, df)
    f = natural_freq_hz(poles_raw)
    gap = np.abs(f[:-1] - f[-1])
    near = gap < 0.5 * np.maximum(b[:-1], b[-1])
    ratio = np.maximum(b[:-1], b[-1]) / np.minimum(b[:-1], b[-1])
    broad = bool(np.any(near & (ratio > MISSING_BANDWIDTH_RATIO)))
    unresolved = gap < np.maximum(MISSING_MIN_LINES * df, 0.25 * np.minimum(b[:-1], b[-1]))
    R = np.asarray(residues, dtype=complex).reshape(-1, f.size)
    same_shape = np.array([mac(R[:, k], R[:, -1]) > DUPLICATE_MAC for k in range(f.size - 1)], dtype=bool)
    dup = (gap < DUPLICATE_BANDWIDTHS * 0.5 * np.maximum(b[:-1], b[-1])) & same_shape
    return broad, np.flatnonzero(unresolved | dup)


def _pair_is_resolved(trial, k: int, f: np.ndarray, e_old: np.ndarray, e_new: np.ndarray, df: float) -> tuple[bool, str]:
    """Whether the added (last) pole and its close neighbour ``k`` are two modes (step 7).

    The data must say so: the pair is at least a line apart; over the pair's lines (the two
    frequencies +- the larger half-power bandwidth, at least ``MISSING_MIN_LINES`` lines) the
    scaled misfit ``sum e^2`` fell by at least ``MISSING_LOCAL_GAIN`` (the total gain of
    ``MISSING_MIN_GAIN`` is checked by the caller); and both poles keep distinct residues:
    neither is negligible (the smaller residue norm >= ``MISSING_MIN_RESIDUE_RATIO`` of the
    larger) and they do not cancel (``|R_a + R_b| >= MISSING_CANCEL_RATIO (|R_a| + |R_b|)``,
    two large opposite residues fitting a noise wiggle). Returns (verdict, reason)."""
    p = trial.poles_raw
    fa, fb = natural_freq_hz(p[k]), natural_freq_hz(p[-1])
    if abs(fa - fb) < df:
        return False, f"closer than a line to {fa:.5g} Hz"
    b = float(np.max(bandwidth_hz(p[[k, -1]], df)))
    half = max(b, MISSING_MIN_LINES * df)
    loc = (f >= min(fa, fb) - half) & (f <= max(fa, fb) + half)
    c_old, c_new = float(np.sum(e_old[loc] ** 2)), float(np.sum(e_new[loc] ** 2))
    if not c_new <= (1.0 - MISSING_LOCAL_GAIN) * c_old:
        return False, (f"next to {fa:.5g} Hz, local cost {c_old:.3g} -> {c_new:.3g} "
                       f"(less than {100 * MISSING_LOCAL_GAIN:g} % gain)")
    R = np.asarray(trial.model_raw.residues, dtype=complex).reshape(-1, p.size)
    ra, rb = R[:, k], R[:, -1]
    na, nb = float(np.linalg.norm(ra)), float(np.linalg.norm(rb))
    if min(na, nb) < MISSING_MIN_RESIDUE_RATIO * max(na, nb):
        return False, f"next to {fa:.5g} Hz, one residue of the pair is negligible"
    if float(np.linalg.norm(ra + rb)) < MISSING_CANCEL_RATIO * (na + nb):
        return False, f"next to {fa:.5g} Hz, the pair's residues cancel"
    return True, f"a close pair with {fa:.5g} Hz (local cost {c_old:.3g} -> {c_new:.3g})"


def _mains_line(c: float, f: np.ndarray, e: np.ndarray, df: float, z0: float, mains: Sequence[float]) -> Optional[str]:
    """Why the misfit peak at ``c`` Hz is a mains line (step 7), or None.

    On a harmonic ``k m`` of a mains frequency ``m`` (within ``MAINS_LINES`` lines or the grid's
    frequency deviation ``k MAINS_DEVIATION_HZ``) *and* narrower than a mode would be: its
    half-power width (of ``e^2``) is below ``MAINS_WIDTH_FRACTION`` of ``2 zeta c`` with zeta the
    median damping of the fitted poles, and at most ``MAINS_LINES`` lines wider than one line.
    A structural mode at that damping has a measurable half-power bandwidth; an electrical line
    is one or two lines wide."""
    from .peaks import peak_widths

    for m in mains:
        k = int(round(c / m))
        if k < 1 or abs(c - k * m) > max(MAINS_LINES * df, k * MAINS_DEVIATION_HZ):
            continue
        i = int(np.argmin(np.abs(f - c)))
        width = float(peak_widths(e ** 2, [i], rel_height=0.5)[0]) * df
        mode = 2.0 * z0 * c
        if width < MAINS_WIDTH_FRACTION * mode and width <= (1.0 + MAINS_LINES) * df:
            return (f"the misfit peak at {c:.6g} Hz lies on the mains line {k} x {m:g} Hz and is {width:.3g} Hz wide "
                    f"(a mode at {100 * z0:.3g} % damping would be {mode:.3g} Hz wide): not fitted as a mode (leave "
                    "such lines out with --exclude-lines/--exclude-mains, fit_auto(exclude_hz=...))")
    return None


def add_missing_modes(frf: FRFSet, result, fit_kw: dict, warnings_out: list[str],
                       mains: Sequence[float] = MAINS_HZ, df: Optional[float] = None):
    """Step 7: add poles at the resonances the model misses (see module docstring). A trial fit
    that does not converge is a rejected candidate (its convergence warning is not passed on).
    The poles of ``result`` are kept; poles are only added."""
    from .lsfd import LSFDConvergenceWarning
    df = frf.line_spacing_hz if df is None else float(df)
    tried: list[float] = []
    on_mains: list[tuple[float, str]] = []  # reported once at the end, with a count
    added = 0
    f, e, d = _scaled_misfit(frf, result)
    cost = float(np.sum(e ** 2))
    failures = 0
    while added < MAX_ADDED and failures < MAX_FAILED_TRIES:
        cands = [c for c in _missing_candidates(f, e, d) if all(abs(c - t) > 2 * df for t in tried)]
        if not cands:
            break
        c = float(cands[0])
        tried.append(c)
        z0 = float(np.median(damping_ratio(result.poles_raw)))
        mains_why = _mains_line(c, f, e, df, z0, mains)
        if mains_why is not None:
            log.debug(mains_why)
            on_mains.append((c, mains_why))
            continue
        new = pole_from_fz(c, z0)
        start = np.concatenate([result.poles_raw, [new]])
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", LSFDConvergenceWarning)
                trial = fit_bounded(frf, start, {**fit_kw, "max_iter": min(fit_kw["max_iter"], MISSING_TRIAL_ITER)})
        except (ValueError, np.linalg.LinAlgError) as exc:
            log.info("adding a pole at %.6g Hz failed (%s)", c, exc)
            failures += 1
            continue
        if any(issubclass(w.category, LSFDConvergenceWarning) for w in caught):
            log.info("adding a pole at %.6g Hz: the LSFD did not converge; not added", c)
            failures += 1
            continue
        bad, _ = bad_poles(trial, start, df, duplicates=False)
        broad, close = _new_pole_relation(trial.poles_raw, trial.model_raw.residues, df)
        f2, e2, d2 = _scaled_misfit(frf, trial)
        cost2 = float(np.sum(e2 ** 2))
        why = ""
        if broad:
            why = "a broad pole under a sharper one"
        elif np.any(bad):
            why = f"{int(np.sum(bad))} pole(s) fail the checks"
        elif cost2 > (1.0 - MISSING_MIN_GAIN) * cost:
            why = f"cost {cost:.4g} -> {cost2:.4g}"
        else:
            for k in close:
                ok, text = _pair_is_resolved(trial, int(k), f, e, e2, df)
                if not ok:
                    why = text
                    break
        if why:
            log.info("pole at %.6g Hz not added: %s", c, why)
            failures += 1
            continue
        f_new = trial.freq_hz[-1]
        on_line = mains_harmonic_index(f_new, mains, df) is not None
        if on_line and 2.0 * trial.damping[-1] * f_new < MAINS_WIDTH_FRACTION * 2.0 * z0 * f_new:
            msg = (f"a pole tried at {f_new:.6g} Hz ({100 * trial.damping[-1]:.3g} %) sits on a mains line and is much "
                   f"sharper than the modes ({100 * z0:.3g} %): not added")
            log.info(msg)
            warnings_out.append(msg)
            failures += 1
            continue
        msg = (f"added a pole at {f_new:.5g} Hz/{100 * trial.damping[-1]:.3g} % for a resonance the "
               f"model missed (scaled misfit peak at {c:.5g} Hz; cost {cost:.4g} -> {cost2:.4g})")
        if len(close):
            msg += "; " + _pair_is_resolved(trial, int(close[0]), f, e, e2, df)[1]
        log.info(msg)
        warnings_out.append(msg)
        result, f, e, d, cost = trial, f2, e2, d2, cost2
        added += 1
        failures = 0
    if on_mains:
        msg = on_mains[0][1]
        if len(on_mains) > 1:
            rest = sorted(c for c, _ in on_mains[1:])
            shown = ", ".join(f"{c:.6g}" for c in rest[:10]) + (", ..." if len(rest) > 10 else "")
            msg += f"; and {len(rest)} more misfit peak(s) on mains lines, not fitted as modes either: {shown} Hz"
        log.info(msg)
        warnings_out.append(msg)
    return result
