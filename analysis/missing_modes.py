"""Step 7 of :mod:`analysis.pipeline`: resonances the fitted model misses (see the pipeline's module
docstring). Candidates are the visible peaks (:mod:`analysis.visibility`) no pole accounts for,
then the peaks of the scaled misfit; each is tried by a *local* fit on the residual (the data
minus the model's other poles, over a few bandwidths around the candidate), kept only on clear
evidence, with a guard against mains lines; one full LSFD from all poles follows. Visible peaks
still unaccounted for are named in the warnings and make the fit unsuccessful."""
from __future__ import annotations

import logging
import warnings
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from .bands import MAINS_HZ, harmonic_tolerance_hz, mains_harmonic_index
from .bounded_fit import DAMPING_WINDOW, bad_poles, trust_window_hz
from .fit_checks import DUPLICATE_BANDWIDTHS, DUPLICATE_MAC, bandwidth_hz
from .fit_result import MAX_DAMPING
from .frf import FRFSet
from .lscf import EQUAL_NOISE
from .mac import mac
from .modal import ModalModel, damping_ratio, natural_freq_hz, pole_from_fz, transfer
from .peaks import find_peaks
from .visibility import (
    SAME_FRACTION,
    SAME_LINES,
    VisiblePeak,
    coherence_measured,
    reproduced,
    resonances,
    structure_resonances,
    unaccounted_peaks,
)

if TYPE_CHECKING:
    from .lsfd import LSFDResult

__all__ = ["add_missing_modes", "unfitted_resonances", "structure_verdict", "mains_line_max_lines", "MAINS_HZ",
           "mains_line_poles", "neighbour_damping", "final_fit"]

log = logging.getLogger(__name__)


MISSING_MEDIAN_FACTOR = 4.0
MISSING_DATA_FRACTION = 0.25
#: a misfit peak where the model misses the data by at least the data's own level (the model is no better than
#: none there) is tried even after the strongest misfit peaks failed
WORSE_THAN_DATA = 1.0
MAX_ADDED = 40
MISSING_BANDWIDTH_RATIO = 4.0
MAX_FAILED_TRIES = 2
MISSING_MIN_LINES = 3
MISSING_TRIAL_ITER = 40
MISSING_LOCAL_GAIN = 0.3
MISSING_MIN_RESIDUE_RATIO = 0.05
MISSING_CANCEL_RATIO = 0.2
MAINS_WIDTH_FRACTION = 0.5
#: lines within 3 dB of the top of a steady line (mains) in a record without exponential window: one
#: line when it falls on a line, two when it falls between (the record's main lobe)
MAINS_TOP_LINES = 2
LOCAL_BANDWIDTHS = 4.0
LOCAL_MIN_LINES = 12
VISIBLE_MIN_GAIN = 0.6
MISFIT_MIN_GAIN = 0.7
SPLIT_MIN_GAIN = 0.75
REPRODUCED_MIN_GAIN = 0.2
MAX_FAILED_VISIBLE = 6
NOT_A_RESONANCE_DAMPING_RATIO = 6.0
#: the modes a tried pole's damping is compared with: the model's poles within this fraction of its frequency
#: (their median, when it is above the whole model's); damping changes over a wide band (a group of modes near
#: 900 Hz at 0.1 %, the lightly damped ones of 3-6 kHz at 0.03 %) and a mode is broad only against its neighbours
NEIGHBOUR_DAMPING_FRACTION = 0.1
SPLIT_MIN_RATIO = 0.01
LOCAL_TOL = 1e-7
FINAL_BANDWIDTHS = 0.1
FINAL_DAMPING_WINDOW = 1.25
MAX_FINAL_ROUNDS = 3
PAIR_FRACTION = 0.02


def _synthesize_flat(model: ModalModel, f: np.ndarray) -> np.ndarray:
    """``synthesize(model, f).H`` flattened to (n_frf, n_f), by matrix products (BLAS): the same
    sum (eq. 11), several times faster than the general einsum on big sets."""
    return transfer(model, 2j * np.pi * f).reshape(-1, f.size)


def _scaled_misfit(frf: FRFSet, model: ModalModel, band: Sequence[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(freq_hz, e, d) of step 7: RMS-scaled misfit of ``model`` (raw poles, as the data were
    measured) and the data over the FRFs, per line of ``band``."""
    lo, hi = band
    sel = (frf.freq_hz >= lo) & (frf.freq_hz <= hi)
    f = frf.freq_hz[sel]
    H = frf.H[..., sel].reshape(-1, f.size)
    G = _synthesize_flat(model, f)
    rms = np.sqrt(np.mean(H.real ** 2 + H.imag ** 2, axis=1))
    if frf.meta.get(EQUAL_NOISE):   # principal response functions: one scale (lscf.EQUAL_NOISE)
        rms = np.full_like(rms, np.sqrt(np.mean(rms ** 2)))
    live = np.isfinite(rms) & (rms > 0)
    if not np.all(live):
        H, G, rms = H[live], G[live], rms[live]
    w = (1.0 / rms ** 2)[:, None]
    E = H - G
    e = np.sqrt(np.mean((E.real ** 2 + E.imag ** 2) * w, axis=0))
    d = np.sqrt(np.mean((H.real ** 2 + H.imag ** 2) * w, axis=0))
    return f, e, d


def _missing_candidates(f: np.ndarray, e: np.ndarray, d: np.ndarray,
                        data_fraction: float = MISSING_DATA_FRACTION) -> np.ndarray:
    """Frequencies (Hz) of the misfit peaks of step 7 (above ``MISSING_MEDIAN_FACTOR`` times the misfit's
    median and ``data_fraction`` of the data there), strongest first."""
    level = MISSING_MEDIAN_FACTOR * float(np.median(e))
    pk, _ = find_peaks(e)
    pk = pk[(e[pk] > level) & (e[pk] > data_fraction * d[pk])]
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


def _pair_is_resolved(trial: LSFDResult, k: int, f: np.ndarray, e_old: np.ndarray, e_new: np.ndarray,
                      df: float) -> tuple[bool, str]:
    """Whether the added (last) pole and its close neighbour ``k`` are two modes (step 7).

    The data must say so: the pair is at least a line apart; over the pair's lines (the two
    frequencies +- the larger half-power bandwidth, at least ``MISSING_MIN_LINES`` lines) the
    scaled misfit ``sum e^2`` fell by at least ``MISSING_LOCAL_GAIN`` (the gain of the whole
    trial is checked by the caller); and both poles keep distinct residues:
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


def mains_line_max_lines(df: float, exp_window_tau_s: float | None = None) -> int:
    """The widest top (lines within 3 dB of the maximum) a steady line, e.g. a mains line, has in
    a record of line spacing ``df`` (Hz): ``MAINS_TOP_LINES`` lines, plus, through an exponential
    window of time constant ``exp_window_tau_s`` (s), the whole lines of the window's half-power
    width ``1 / (pi tau)`` (Hz; a decaying line is a Lorentzian). A peak with a wider top is a
    resonance whatever frequency it sits at."""
    extra = 0
    if exp_window_tau_s:
        extra = int(np.floor(1.0 / (np.pi * float(exp_window_tau_s) * float(df)) + 1e-9))
    return MAINS_TOP_LINES + extra


def _mains_line(c: float, f: np.ndarray, e: np.ndarray, df: float, z0: float, mains: Sequence[float],
                max_lines: int = MAINS_TOP_LINES) -> str | None:
    """Why the misfit peak at ``c`` Hz is a mains line (step 7), or None.

    On a harmonic ``k m`` of a mains frequency ``m`` (within :func:`analysis.bands.harmonic_tolerance_hz`)
    *and* narrower than a mode would be: its
    half-power width (of ``e^2``) is below ``MAINS_WIDTH_FRACTION`` of ``2 zeta c`` with zeta the
    median damping of the fitted poles, and at most ``max_lines`` lines wide (the widest a steady
    line is in the record, :func:`mains_line_max_lines`). A structural mode at that damping has a
    measurable half-power bandwidth; an electrical line is one or two lines wide."""
    from .peaks import peak_widths

    for m in mains:
        k = int(round(c / m))
        if k < 1 or abs(c - k * m) > harmonic_tolerance_hz(k, df):
            continue
        i = int(np.argmin(np.abs(f - c)))
        width = float(peak_widths(e ** 2, [i], rel_height=0.5)[0]) * df
        mode = 2.0 * z0 * c
        if width < MAINS_WIDTH_FRACTION * mode and width <= max_lines * df:
            return (f"the misfit peak at {c:.6g} Hz lies on the mains line {k} x {m:g} Hz and is {width:.3g} Hz wide "
                    f"(a mode at {100 * z0:.3g} % damping would be {mode:.3g} Hz wide): not fitted as a mode (leave "
                    "such lines out with --exclude-lines/--exclude-mains, fit_auto(exclude_hz=...))")
    return None


def _with_poles(model: ModalModel, keep: np.ndarray, extra_poles: np.ndarray | None = None,
                extra_residues: np.ndarray | None = None) -> ModalModel:
    """``model`` with the poles ``keep`` (bool mask) and ``extra_poles`` (residues (n_out, n_ref, k))
    appended; the residual terms are kept."""
    from dataclasses import replace

    R = np.asarray(model.residues)[..., keep]
    p = np.asarray(model.poles)[keep]
    if extra_poles is not None and extra_poles.size:
        p = np.concatenate([p, extra_poles])
        R = np.concatenate([R, np.asarray(extra_residues)], axis=-1)
    return replace(model, poles=p, residues=R)


def _line_costs(local: FRFSet, res: LSFDResult, weights: np.ndarray | None) -> np.ndarray:
    """Per-line weighted squared misfit (summed over the FRFs) of an LSFD ``res`` on ``local``."""
    G = _synthesize_flat(res.model_raw, local.freq_hz)
    E = local.H.reshape(-1, local.freq_hz.size) - G
    w2 = np.ones(E.shape[0]) if weights is None else np.asarray(weights, float).reshape(-1) ** 2
    return np.sqrt(np.sum((E.real ** 2 + E.imag ** 2) * w2[:, None], axis=0))


def _residual_terms_only(local: FRFSet, residual_form: str, weights: np.ndarray | None) -> np.ndarray:
    """Per-line misfit (as :func:`_line_costs`) of the residual terms alone fitted to ``local``."""
    from .modal import residual_basis

    B = residual_basis(local.omega, local.quantity, residual_form)
    D = local.H.reshape(-1, local.freq_hz.size)
    if B.shape[0]:
        X, *_ = np.linalg.lstsq(B.T, D.T, rcond=None)
        D = D - (B.T @ X).T
    w2 = np.ones(D.shape[0]) if weights is None else np.asarray(weights, float).reshape(-1) ** 2
    return np.sqrt(np.sum((D.real ** 2 + D.imag ** 2) * w2[:, None], axis=0))


class _Trial:
    """Outcome of one local trial: ``ok``, ``why`` (reason or pair note), the local fit ``fit``,
    the indices ``nb`` of the neighbours it refitted, and whether a rejection says the peak is
    ``not_mode`` (too broad / damped to be a structural resonance, or a mains line)."""

    def __init__(self, ok: bool, why: str, fit: LSFDResult | None = None, nb: np.ndarray | None = None,
                 not_mode: bool = False) -> None:
        self.ok, self.why, self.fit, self.nb, self.not_mode = ok, why, fit, nb, not_mode


def _makes_peak(frf: FRFSet, model: ModalModel, nb_mask: np.ndarray, trial: LSFDResult, peak: VisiblePeak) -> bool:
    """Whether ``model`` with its poles ``nb_mask`` replaced by the ``trial``'s reproduces ``peak``
    while ``model`` does not."""
    new = _with_poles(model, ~nb_mask, trial.poles_raw, trial.model_raw.residues)
    return (not reproduced(frf, peak, lambda f: transfer(model, 2j * np.pi * f))
            and reproduced(frf, peak, lambda f: transfer(new, 2j * np.pi * f)))


def neighbour_damping(model: ModalModel, c: float, z0: float) -> float:
    """The damping ratio a pole tried at ``c`` Hz is compared with: the median of ``model``'s poles (raw) within
    ``NEIGHBOUR_DAMPING_FRACTION`` of ``c`` when that is above ``z0`` (the whole model's median), else ``z0``."""
    f = natural_freq_hz(model.poles)
    near = np.abs(f - float(c)) <= NEIGHBOUR_DAMPING_FRACTION * float(c)
    if not np.any(near):
        return float(z0)
    return max(float(z0), float(np.median(damping_ratio(np.asarray(model.poles)[near]))))


def _local_problem(frf: FRFSet, model: ModalModel, band: Sequence[float], c: float, hw: float, fit_kw: dict,
                   extra: int = 0) -> tuple[FRFSet, np.ndarray, np.ndarray | None, dict, tuple[float, float]] | None:
    """The local problem of step 7 around ``c`` Hz: ``(the data minus the synthesis of every pole farther than
    ``hw`` Hz from c (and of the residual terms) over the lines within ``hw`` of c and of those neighbours, the
    neighbours' mask, the FRF weights, the LSFD options of a local verdict, the window (lo, hi Hz))``; None when
    the window holds too few lines for the neighbours and ``extra`` more poles."""
    from dataclasses import replace

    f_all = natural_freq_hz(model.poles)
    nb_mask = np.abs(f_all - c) < hw
    nb = np.flatnonzero(nb_mask)
    lo = max(float(band[0]), min([c - hw] + [f_all[k] - hw for k in nb]))
    hi = min(float(band[1]), max([c + hw] + [f_all[k] + hw for k in nb]))
    sel = (frf.freq_hz >= lo) & (frf.freq_hz <= hi)
    if int(np.sum(sel)) < 2 * (nb.size + extra) + 4:
        return None
    far = _with_poles(model, ~nb_mask)
    f_loc = frf.freq_hz[sel]
    D = frf.H[..., sel] - transfer(far, 2j * np.pi * f_loc).reshape(frf.H.shape[:2] + (f_loc.size,))
    local = replace(frf.band(lo, hi), H=D)
    kw = {k: v for k, v in fit_kw.items() if k not in ("band", "weights")}
    kw["max_iter"] = min(int(fit_kw.get("max_iter", 100)), MISSING_TRIAL_ITER)
    kw["ftol"], kw["xtol"] = LOCAL_TOL, LOCAL_TOL   # a verdict, not the final estimate (the full LSFD follows)
    return local, nb_mask, fit_kw.get("weights"), kw, (lo, hi)


def _reseat_unresolved(frf: FRFSet, model: ModalModel, band: Sequence[float], fit_kw: dict,
                       df: float) -> tuple[ModalModel, list[str]]:
    """Poles closer than ``MISSING_MIN_LINES`` lines or a quarter of the smaller bandwidth (the resolution rule
    of :func:`_new_pole_relation`) where the whole-band fit left them: two close modes squeezed together, the
    band's far misfit weighed against them (the simulated frame's 995.2 / 1000.2 Hz pair, held at 997.8 and
    1000.1 Hz). Each such pair and its neighbours are refitted once locally, as step 7's trials are (on the
    data minus the other poles, over a few bandwidths), and the local poles are taken when they pass step 6's
    checks, lower the local cost and move a pole by a line or more. Returns the model and a note per pair."""
    from .lsfd import LSFDConvergenceWarning, fit_lsfd, lsfd_at_poles

    notes: list[str] = []
    f0 = natural_freq_hz(model.poles)
    b0 = bandwidth_hz(np.asarray(model.poles), df)
    o = np.argsort(f0)
    close = np.diff(f0[o]) < np.maximum(MISSING_MIN_LINES * df, 0.25 * np.minimum(b0[o][:-1], b0[o][1:]))
    for k in np.flatnonzero(close):
        fa, fb = float(f0[o[k]]), float(f0[o[k + 1]])
        f = natural_freq_hz(model.poles)
        if np.min(np.abs(f - fa)) > 0.5 * df or np.min(np.abs(f - fb)) > 0.5 * df:
            continue   # a refit of a neighbouring pair has moved them already
        loc = _local_problem(frf, model, band, 0.5 * (fa + fb),
                             max(LOCAL_BANDWIDTHS * float(max(b0[o[k]], b0[o[k + 1]])), LOCAL_MIN_LINES * df), fit_kw)
        if loc is None:
            continue
        local, nb_mask, w, kw, _ = loc
        start = np.asarray(model.poles)[nb_mask]
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", LSFDConvergenceWarning)
                now = lsfd_at_poles(local, start, residual_form=kw.get("residual_form", "physical"), weights=w)
                refit = fit_lsfd(local, start, weights=w, freq_window_hz=trust_window_hz(start, df), **kw)
        except (ValueError, np.linalg.LinAlgError):
            continue
        if any(issubclass(x.category, LSFDConvergenceWarning) for x in caught):
            continue
        c_now = float(np.sum(_line_costs(local, now, w) ** 2))
        c_new = float(np.sum(_line_costs(local, refit, w) ** 2))
        moved = float(np.max(np.abs(natural_freq_hz(refit.poles_raw) - natural_freq_hz(start))))
        if np.any(bad_poles(refit, start, df)[0]) or not c_new < c_now or moved < df:
            continue
        notes.append(f"refitted the poles at {fa:.5g} and {fb:.5g} Hz and their neighbours locally (closer than "
                     f"the data resolve): {', '.join(f'{x:.5g}' for x in sorted(natural_freq_hz(refit.poles_raw)))} "
                     f"Hz (local cost {c_now:.4g} -> {c_new:.4g})")
        model = _with_poles(model, ~nb_mask, refit.poles_raw, refit.model_raw.residues)
    return model, notes


def _local_trial(frf: FRFSet, model: ModalModel, band: Sequence[float], c: float, z0: float, fit_kw: dict,
                 min_gain: float, peak: VisiblePeak | None = None) -> _Trial:
    """Try a pole at ``c`` Hz by an LSFD over the lines around it, fitted to the residual of the
    model's other poles: the data minus the synthesis of every pole farther than the local window
    (and of the residual terms). The neighbours inside the window are refitted with and without
    the new pole; the new pole is kept when the local weighted cost falls by ``min_gain`` and
    the pole is a mode of its own (see the module docstring of :mod:`analysis.pipeline`).

    ``peak``: the visible peak tried; a smaller gain (``REPRODUCED_MIN_GAIN``) is enough when the
    model with the trial's poles reproduces that peak within its noise (:func:`analysis.visibility.reproduced`)
    and the model without them does not: the data show the resonance, and its pole accounts for it."""
    from .lsfd import LSFDConvergenceWarning, fit_lsfd

    df = float(frf.line_spacing_hz)
    z_ref = neighbour_damping(model, c, z0)   # the modes near it: the "too broad" scale, and a second start
    new = pole_from_fz(c, z0)
    hw = max(LOCAL_BANDWIDTHS * float(bandwidth_hz(np.array([new]), df)[0]), LOCAL_MIN_LINES * df)
    loc = _local_problem(frf, model, band, c, hw, fit_kw, extra=1)
    if loc is None:
        return _Trial(False, "too few lines around it")
    local, nb_mask, w, kw, (lo, hi) = loc
    nb = np.flatnonzero(nb_mask)
    start_old = np.asarray(model.poles)[nb]
    start = np.concatenate([start_old, [new]])
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", LSFDConvergenceWarning)
            if nb.size:
                base = fit_lsfd(local, start_old, weights=w, freq_window_hz=trust_window_hz(start_old, df), **kw)
                e_old = _line_costs(local, base, w)
            else:
                e_old = _residual_terms_only(local, fit_kw.get("residual_form", "physical"), w)
            trial = fit_lsfd(local, start, weights=w, freq_window_hz=trust_window_hz(start, df), **kw)
            if z_ref > z0 and -trial.poles_raw[-1].real >= 0.99 * DAMPING_WINDOW * -start[-1].real:
                # the new pole ended on its decay-rate check (four times its start's): the modes near it are
                # damped more than the whole model; it starts again at their damping
                start = np.concatenate([start_old, [pole_from_fz(c, z_ref)]])
                trial = fit_lsfd(local, start, weights=w, freq_window_hz=trust_window_hz(start, df), **kw)
    except (ValueError, np.linalg.LinAlgError) as exc:
        return _Trial(False, f"the local fit failed ({exc})")
    if any(issubclass(x.category, LSFDConvergenceWarning) for x in caught):
        return _Trial(False, "the local fit did not converge")
    verdict = _judge_trial(frf, model, (local, nb_mask, w, (lo, hi)), trial, start, e_old, z0, z_ref, c, min_gain,
                           peak)
    z_peak = None if peak is None else float(damping_ratio(_peak_start(peak, df)))
    if verdict.ok or z_peak is None or not z_peak * DAMPING_WINDOW < z0:
        return verdict
    # a visible peak far sharper than the model's modes (its top's width gives less than a DAMPING_WINDOW-th of
    # their damping: out of reach of the first start's decay-rate bound): tried again from that width
    start = np.concatenate([start_old, [pole_from_fz(c, z_peak)]])
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", LSFDConvergenceWarning)
            sharp = fit_lsfd(local, start, weights=w, freq_window_hz=trust_window_hz(start, df), **kw)
    except (ValueError, np.linalg.LinAlgError):
        return verdict
    if any(issubclass(x.category, LSFDConvergenceWarning) for x in caught):
        return verdict
    again = _judge_trial(frf, model, (local, nb_mask, w, (lo, hi)), sharp, start, e_old, z0, z_ref, c, min_gain,
                         peak)
    return again if again.ok else verdict


def _peak_start(peak: VisiblePeak, df: float) -> complex:
    """The start pole (rad/s) the width of a visible peak's top gives (:func:`analysis.visibility.peak_poles`)."""
    from .visibility import peak_poles

    return complex(peak_poles([peak], df)[0])


def _judge_trial(frf: FRFSet, model: ModalModel,
                 problem: tuple[FRFSet, np.ndarray, np.ndarray | None, tuple[float, float]], trial: LSFDResult,
                 start: np.ndarray, e_old: np.ndarray, z0: float, z_ref: float, c: float, min_gain: float,
                 peak: VisiblePeak | None) -> _Trial:
    """The verdict on a local trial fit (:func:`_local_trial`) from ``start`` on the local ``problem`` (the local
    data, the neighbours' mask, the weights, the window lo, hi Hz): the new pole (the last) is kept when it lies in
    the window with a physical damping no broader than a mode, every pole passes the checks, the local cost falls
    by ``min_gain`` (or the trial reproduces ``peak``) and the pole is a mode of its own."""
    local, nb_mask, w, (lo, hi) = problem
    df = float(frf.line_spacing_hz)
    nb = np.flatnonzero(nb_mask)
    f_loc = local.freq_hz
    e_new = _line_costs(local, trial, w)
    c_old, c_new = float(np.sum(e_old ** 2)), float(np.sum(e_new ** 2))
    z_new = float(damping_ratio(trial.poles_raw[-1]))
    f_new = float(natural_freq_hz(trial.poles_raw[-1]))
    if not 0.0 < z_new < MAX_DAMPING or not lo <= f_new <= hi:
        return _Trial(False, f"the pole went to {f_new:.5g} Hz/{100 * z_new:.3g} %", not_mode=True)
    if z_new > NOT_A_RESONANCE_DAMPING_RATIO * max(z_ref, 0.5 * df / max(c, df)):
        return _Trial(False, f"too broad for a mode ({100 * z_new:.3g} % against {100 * z_ref:.3g} % of the modes "
                             "near it)", not_mode=True)
    bad, _ = bad_poles(trial, start, df, duplicates=False)
    if np.any(bad):
        return _Trial(False, f"{int(np.sum(bad))} pole(s) of the local fit fail the checks")
    if not c_new <= (1.0 - min_gain) * c_old and not (
            peak is not None and c_new <= (1.0 - REPRODUCED_MIN_GAIN) * c_old
            and _makes_peak(frf, model, nb_mask, trial, peak)):
        return _Trial(False, f"local cost {c_old:.4g} -> {c_new:.4g} (less than {100 * min_gain:g} % gain)")
    broad, close = _new_pole_relation(trial.poles_raw, trial.model_raw.residues, df)
    if broad:
        return _Trial(False, "a broad pole under a sharper one")
    note = f"local cost {c_old:.4g} -> {c_new:.4g}"
    for k in close:
        ok, text = _pair_is_resolved(trial, int(k), f_loc, e_old, e_new, df)
        if not ok:
            return _Trial(False, text)
        note = text
    return _Trial(True, note, trial, nb)


def add_missing_modes(frf: FRFSet, result: LSFDResult, fit_kw: dict, warnings_out: list[str],
                      mains: Sequence[float] = MAINS_HZ, df: float | None = None,
                      visible: Sequence[VisiblePeak] = ()) -> LSFDResult:
    """Step 7: add poles at the resonances the model misses (see module docstring): first the
    ``visible`` peaks no pole accounts for, then the misfit peaks; each tried by a local fit on
    the residual; then one LSFD from all poles (and step 6's checks). The poles of ``result``
    are kept; poles are only added. Returns the new LSFD result (``result`` when nothing was added)."""
    df = frf.line_spacing_hz if df is None else float(df)
    band = result.band
    model = result.model_raw
    z0 = float(np.median(damping_ratio(result.poles_raw)))
    mains_lines = mains_line_max_lines(df, frf.exp_window_tau_s)
    coherent = coherence_measured(frf)
    tried: list[float] = []
    on_mains: list[tuple[float, str]] = []  # reported once at the end, with a count
    added = 0

    def attempt(c: float, min_gain: float, peak: VisiblePeak | None = None) -> bool:
        nonlocal model, added
        tried.append(c)
        f, e, _ = _scaled_misfit(frf, model, band)
        # a visible peak wider than a mains line is a resonance whatever the misfit's shape; one the coherence
        # confirms is tried, and its fitted pole (resolved far finer than a line) tells a mode from a line
        wide = peak is not None and ((peak.top_hz[1] - peak.top_hz[0]) / df - 1.0 > mains_lines + 0.5
                                     or coherent)
        mains_why = None if wide else _mains_line(c, f, e, df, z0, mains, mains_lines)
        if mains_why is not None:
            log.debug(mains_why)
            on_mains.append((c, mains_why))
            return False
        t = _local_trial(frf, model, band, c, z0, fit_kw, min_gain, peak=peak)
        if not t.ok:
            log.info("pole at %.6g Hz not added: %s", c, t.why)
            return False
        fit = t.fit
        assert fit is not None  # an accepted trial carries its local fit
        f_new, z_new = float(fit.freq_hz[-1]), float(fit.damping[-1])
        # a tried visible peak the coherence confirms: on the harmonic itself (the grid's deviation), not
        # within lines of it
        reach = 0.0 if peak is not None and coherent else df
        if mains_harmonic_index(f_new, mains, reach) is not None and z_new < MAINS_WIDTH_FRACTION * z0:
            msg = (f"a pole tried at {f_new:.6g} Hz ({100 * z_new:.3g} %) sits on a mains line and is much "
                   f"sharper than the modes ({100 * z0:.3g} %): not added")
            log.info(msg)
            warnings_out.append(msg)
            return False
        keep = np.ones(model.poles.size, dtype=bool)
        keep[t.nb] = False
        model = _with_poles(model, keep, fit.poles_raw, fit.model_raw.residues)
        msg = (f"added a pole at {f_new:.5g} Hz/{100 * z_new:.3g} % for a resonance the model missed "
               f"(peak at {c:.5g} Hz; {t.why})")
        log.info(msg)
        warnings_out.append(msg)
        added += 1
        return True

    failures = 0
    while added < MAX_ADDED and failures < MAX_FAILED_VISIBLE:
        left = [v for v in _unaccounted(frf, visible, model, df) if all(abs(v.freq_hz - x) > 0.5 * df for x in tried)]
        if not left:
            break
        failures = 0 if attempt(left[0].freq_hz, VISIBLE_MIN_GAIN, left[0]) else failures + 1
    # close pairs fitted as one pole: where the misfit over a pole's top (+- half its bandwidth)
    # exceeds SPLIT_MIN_RATIO of the data there, a second pole half a bandwidth either side is
    # tried (the pair checks decide)
    f, e, d = _scaled_misfit(frf, model, band)
    for p in sorted(np.asarray(model.poles), key=lambda p: float(natural_freq_hz(p))):
        if added >= MAX_ADDED:
            break
        fk = float(natural_freq_hz(p))
        bk = float(bandwidth_hz(np.array([p]), df)[0])
        top = (f >= fk - 0.5 * bk) & (f <= fk + 0.5 * bk)
        if not np.any(top):
            continue
        ratio = float(np.sum(e[top] ** 2) / max(float(np.sum(d[top] ** 2)), 1e-300))
        if ratio < SPLIT_MIN_RATIO:
            continue
        for side in (-0.5, 0.5):
            c = fk + side * bk
            if all(abs(c - x) > 0.5 * df for x in tried) and attempt(c, SPLIT_MIN_GAIN):
                f, e, d = _scaled_misfit(frf, model, band)
                break
    failures = 0
    while added < MAX_ADDED and failures < MAX_FAILED_TRIES:
        f, e, d = _scaled_misfit(frf, model, band)
        cands = [c for c in _missing_candidates(f, e, d) if all(abs(c - x) > 2 * df for x in tried)]
        if not cands:
            break
        failures = 0 if attempt(float(cands[0]), MISFIT_MIN_GAIN) else failures + 1

    def worse_than_data() -> bool:
        """The strongest misfit peaks of a wide band sit where the FRF is large; a weak mode elsewhere, where
        the model misses the data by at least the data's own level, is tried once whatever failed before it."""
        f, e, d = _scaled_misfit(frf, model, band)
        found = False
        for c in _missing_candidates(f, e, d, WORSE_THAN_DATA):
            if added >= MAX_ADDED:
                break
            if all(abs(c - x) > 2 * df for x in tried) and attempt(float(c), MISFIT_MIN_GAIN):
                found = True
                f, e, d = _scaled_misfit(frf, model, band)
        return found


    worse_than_data()
    _report_on_mains(on_mains, warnings_out, mains, df)
    model, reseated = _reseat(frf, model, band, fit_kw, df, warnings_out)
    if not added and not reseated:
        return result
    final = final_fit(frf, np.asarray(model.poles), fit_kw, warnings_out)
    # the full fit moves every pole a little; where it then misses the data by the data's level, once more
    model = final.model_raw
    if not worse_than_data():
        return final
    return final_fit(frf, np.asarray(model.poles), fit_kw, warnings_out)


def mains_line_poles(poles_raw: np.ndarray, mains: Sequence[float], df: float) -> np.ndarray:
    """Mask of the poles (raw, rad/s) that sit on a harmonic of ``mains`` (Hz, within
    :func:`analysis.bands.harmonic_tolerance_hz` of lines ``df`` Hz) and are much sharper than the modes (damping
    below ``MAINS_WIDTH_FRACTION`` of the median of the others): an electrical line fitted as a mode, the rule
    step 7 applies to the poles it would add."""
    p = np.asarray(poles_raw, dtype=complex)
    out = np.zeros(p.size, dtype=bool)
    if p.size < 2 or not len(mains):
        return out
    f, z = natural_freq_hz(p), damping_ratio(p)
    for k in range(p.size):
        if mains_harmonic_index(float(f[k]), mains, df) is None:
            continue
        out[k] = bool(z[k] < MAINS_WIDTH_FRACTION * float(np.median(np.delete(z, k))))
    return out


def _reseat(frf: FRFSet, model: ModalModel, band: Sequence[float], fit_kw: dict, df: float,
            warnings_out: list[str]) -> tuple[ModalModel, bool]:
    """:func:`_reseat_unresolved`, its notes logged and kept in ``warnings_out``; whether it moved any pole."""
    model, notes = _reseat_unresolved(frf, model, band, fit_kw, df)
    for msg in notes:
        log.info(msg)
    warnings_out += notes
    return model, bool(notes)


def _report_on_mains(on_mains: Sequence[tuple[float, str]], warnings_out: list[str], mains: Sequence[float],
                     df: float) -> None:
    """One warning for the misfit peaks (Hz, reason) step 7 left on mains lines: the first one's reason, and
    the others with their harmonic of ``mains`` (Hz; lines ``df`` Hz apart)."""
    if not on_mains:
        return

    def named(c: float) -> str:
        h = mains_harmonic_index(c, mains, df)
        return f"{c:.6g}" + (f" ({h[0]} x {h[1]:g} Hz)" if h is not None else "")

    msg = on_mains[0][1]
    if len(on_mains) > 1:
        rest = sorted(c for c, _ in on_mains[1:])
        shown = ", ".join(named(c) for c in rest[:10]) + (", ..." if len(rest) > 10 else "")
        msg += f"; and {len(rest)} more misfit peak(s) on mains lines, not fitted as modes either: {shown} Hz"
    log.info(msg)
    warnings_out.append(msg)


def final_fit(frf: FRFSet, poles: np.ndarray, fit_kw: dict, warnings_out: list[str]) -> LSFDResult:
    """One LSFD over the whole band from the poles the local fits found, each held close to its
    local estimate (``FINAL_BANDWIDTHS`` half-power bandwidths in frequency, a factor
    ``FINAL_DAMPING_WINDOW`` in damping): the local fits decided which poles there are; the full
    fit polishes them together and gives the residues and uncertainties of the whole band. On a
    wide band of weak modes an unbounded fit would turn some of them into very damped poles that
    absorb broadband misfit. Poles that leave the band or physical damping are dropped (step 6). Also the refit
    after mains-line poles are dropped (:func:`analysis.pipeline.fit_auto`): the poles kept are where the fit put
    them (a sharp pole step 7 added, the UNESP beam's 54.01 Hz at 0.08 %, is otherwise let out to soak up the
    whole band's misfit around it: 1.5 %, and dropped)."""
    from .lsfd import fit_lsfd

    df = frf.line_spacing_hz
    p = np.asarray(poles)
    for _ in range(MAX_FINAL_ROUNDS):
        res = fit_lsfd(frf, p, freq_window_hz=FINAL_BANDWIDTHS * bandwidth_hz(p, df),
                       damping_window=FINAL_DAMPING_WINDOW, **fit_kw)
        lo, hi = res.band
        fd = res.poles_raw.imag / (2 * np.pi)
        bad = ~((fd >= lo) & (fd <= hi) & (res.damping > 0) & (res.damping < MAX_DAMPING))
        if not np.any(bad) or np.all(bad):
            return res
        msg = "dropped and refitted: " + "; ".join(
            f"{natural_freq_hz(p[k]):.4g} Hz -> {res.freq_hz[k]:.4g} Hz/{100 * res.damping[k]:.3g} %: out of the band "
            "or physical damping" for k in np.flatnonzero(bad))
        log.info(msg)
        warnings_out.append(msg)
        p = p[~bad]
    return res


def _unaccounted(frf: FRFSet, visible: Sequence[VisiblePeak], model: ModalModel, df: float) -> list[VisiblePeak]:
    """The visible peaks ``model`` (raw poles) does not account for, most prominent first: the resonances
    no pole accounts for, and the peaks of an accounted resonance that the model does not make in their own
    FRF (a second mode of a close pair whose peak fell within the first one's half-power band: a candidate
    to try, the local fit decides)."""
    def made(v: VisiblePeak) -> bool:
        return reproduced(frf, v, lambda f: transfer(model, 2j * np.pi * f))

    fitted = natural_freq_hz(model.poles)
    missed, pairs = unaccounted_peaks(visible, fitted, df, made)
    found = missed + [v for v, _ in pairs]
    heads = {id(g[0]) for g in resonances(visible, df)}

    def apart(v: VisiblePeak) -> bool:
        """No pole on the peak itself (within the reach of one peak seen in two FRFs, without the half-power widening)."""
        return not fitted.size or float(np.min(np.abs(fitted - v.freq_hz))) > max(SAME_LINES * df, SAME_FRACTION * v.freq_hz)

    found += [v for v in visible if id(v) not in heads and not any(v is u for u in found) and apart(v) and not made(v)]
    return sorted(found, key=lambda v: -v.prominence_db)


def structure_verdict(frf: FRFSet, visible: Sequence[VisiblePeak], result: LSFDResult,
                      mains: Sequence[float] = MAINS_HZ) -> tuple[list[str], list[str], tuple[float, ...]]:
    """The verdict of step 8 on the resonances of the structure: ``(problems, notes, suspension Hz)``.
    The visible peaks are first split into suspension modes (:func:`analysis.suspension.split_suspension`),
    resonances of the structure and peaks only a few FRFs show (:func:`analysis.visibility.structure_resonances`,
    named in the notes, not counted); the structure's resonances the fit leaves unaccounted for are the
    problems (:func:`unfitted_resonances`)."""
    from .suspension import split_suspension

    elastic, suspension, notes = split_suspension(visible, result.freq_hz)
    kept, left = structure_resonances(elastic, frf.n_outputs * frf.n_references, float(frf.line_spacing_hz))
    fitted = np.asarray(result.freq_hz, float)
    lone = [g[0] for g in left if not fitted.size or np.min(np.abs(fitted - g[0].freq_hz)) > PAIR_FRACTION * g[0].freq_hz]
    if lone:
        n = frf.n_outputs * frf.n_references
        shown = ", ".join(f"{g[0].freq_hz:.5g} Hz ({len({u.curve_index for u in g})} of {n})" for g in left
                          if g[0] in lone)
        notes = [*notes, f"peaks that only a few FRFs show, not in the CMIF, not counted as resonances of the "
                         f"structure: {shown} (a local feature at those points, or an FRF near an antiresonance)"]
    problems, said = unfitted_resonances(frf, kept, result, mains)
    return problems, [*notes, *said], suspension


def unfitted_resonances(frf: FRFSet, visible: Sequence[VisiblePeak], result: LSFDResult,
                        mains: Sequence[float] = MAINS_HZ) -> tuple[list[str], list[str]]:
    """The visible peaks the LSFD ``result`` leaves unaccounted for (:mod:`analysis.visibility`), in
    words: ``(problems, notes)``. A peak on a mains harmonic no wider than a steady line of the
    record (:func:`mains_line_max_lines`: 2 lines within 3 dB of its top, more through a strong
    exponential window) is a note (an electrical line, not a resonance); any other is a problem: the fit is not
    complete. A peak with a fitted pole within ``PAIR_FRACTION`` of it that another peak of its
    curve took is named a possible close pair."""
    df = float(frf.line_spacing_hz)
    mains_lines = mains_line_max_lines(df, frf.exp_window_tau_s)
    model = result.model_raw
    fitted = np.asarray(result.freq_hz, float)
    missed, pairs = unaccounted_peaks(visible, fitted, df,
                                      lambda v: reproduced(frf, v, lambda f: transfer(model, 2j * np.pi * f)),
                                      fitted_bandwidth_hz=bandwidth_hz(result.poles_raw, df))
    problems: list[str] = []
    notes: list[str] = []
    seen: list[float] = []
    for v in missed + [v for v, _ in pairs]:
        if any(abs(v.freq_hz - x) < 0.5 * df for x in seen):
            continue   # the same line in another curve: said once
        seen.append(v.freq_hz)
        where = f"a peak {v.prominence_db:.0f} dB above its neighbouring minima in {v.curve}"
        width_lines = (v.top_hz[1] - v.top_hz[0]) / df - 1.0
        if mains_harmonic_index(v.freq_hz, mains, df) is not None and width_lines <= mains_lines + 0.5:
            notes.append(f"the peak at {v.freq_hz:.5g} Hz ({where}) lies on a mains line and is "
                         f"{width_lines:.0f} line(s) wide: not a resonance")
            continue
        near = fitted[np.abs(fitted - v.freq_hz) <= PAIR_FRACTION * v.freq_hz] if fitted.size else fitted
        if near.size:
            x = float(near[np.argmin(np.abs(near - v.freq_hz))])
            problems.append(f"a possible close pair: the resonance at {v.freq_hz:.5g} Hz ({where}) has no pole of "
                            f"its own; the pole at {x:.5g} Hz may stand for both (more references would separate "
                            "them; or give both frequencies with --poles)")
        else:
            problems.append(f"a resonance at {v.freq_hz:.5g} Hz ({where}) is neither fitted by a pole nor "
                            "reproduced by the model")
    return problems, notes
