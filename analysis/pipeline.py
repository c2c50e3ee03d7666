"""The whole fit: band selection, stabilization, automatic pole selection, nonlinear LSFD.

This is the paper's Fig. 1 flow with the choices made automatically:

1. **Band** (paper sec. 3.1). Default: from the lowest reliable line to the top line. The
   lowest ``LOW_LINES`` lines (f < LOW_LINES * df: the record is too short there, and an
   IEPE sensor rolls off) are skipped; with coherence available, leading lines where the
   median coherence over the FRFs is below ``MIN_COHERENCE`` are skipped too. A user band
   is used as given (checked against the data).
2. **Stabilization** up to ``max_modes`` (default ``2 * peaks + 8``, from the peaks of the
   summed FRF magnitude, capped to ``[12, 60]``) with LSCF or LSCE.
3. **Selection** (:mod:`analysis.selection`), or the user's poles / frequencies.
4. **Band edges**: a selected pole within ``EDGE_BANDWIDTHS`` half-power bandwidths
   (``2 zeta f``) of a band edge sits on the edge; the paper (sec. 3.1, Fig. 4) shows the
   fit then suffers. An automatic edge is moved outwards (as far as the data and the
   low-line limit allow) so the resonance is inside with its margin; if it cannot be, or
   the band was the user's, a warning is logged and kept in ``stab.meta["warnings"]``.
5. **LSFD** (:func:`analysis.lsfd.fit_lsfd`, Gauss-Newton or Levenberg-Marquardt) from the
   selected poles, with residual terms for the modes outside the band. Each FRF is weighted
   by ``1 / its noise level`` in the band (``frf_weighting="rms"``, the default,
   :func:`rms_weights`): from the coherence when the data have it
   (``mean |H|^2 (1 - g^2) / g^2``), otherwise taken proportional to the FRF's RMS. FRFs of
   very different level (driving point vs a far cross point) then count by their quality,
   not their size, so a mode that only weak-but-clean FRFs show is fitted as a mode instead
   of being sacrificed to the strong FRFs' misfit (ULiege, no coherence: 87.8, 118.0 and
   135.4 Hz are recovered only so), while a weak *and noisy* FRF is not blown up (the demo
   recording: 1/RMS alone would weight FRFs that are 40 % noise 1600 times up). For noise
   that is a fixed fraction of each FRF's level 1/RMS is the maximum-likelihood weighting.
   The reported S, noise variance and standard deviations are then those of the weighted
   problem. And with a frequency *trust region*: each pole's damped frequency is held
   (bound constraint, projected steps) within ``MIGRATE_BANDWIDTHS`` half-power bandwidths (``2 zeta f`` of the start
   pole, at least two lines) of where it started. A weak initial pole the data do not
   support is otherwise not driven to zero residue: it slides onto a strong neighbour and
   shares (and spoils) its resonance.
6. **Check** (:mod:`analysis.fit_checks`): poles the LSFD moved out of the band or to
   damping outside ``(0, MAX_DAMPING)``, poles that ended on the edge of their trust region
   (they wanted to migrate), and poles that
   *duplicate* another (within its half-bandwidth with a residue MAC > 0.8) came from
   spurious initial poles; they are dropped and the LSFD repeated from the starts of the
   remaining poles (same trust regions), up to ``MAX_CHECK_ROUNDS`` times; each drop is
   noted in ``stab.meta["warnings"]``.
7. **Missing resonances**: the misfit of every FRF, scaled by that FRF's RMS in the band
   (so weak-but-clean FRFs count like strong ones), is averaged over the FRFs:
   ``e(f) = sqrt(mean_o |H_o - G_o|^2 / rms_o^2)``, and likewise ``d(f)`` for the data.
   Peaks of ``e`` above ``MISSING_MEDIAN_FACTOR`` times its median and above
   ``MISSING_DATA_FRACTION`` of ``d`` are resonances the model misses (modes the
   stabilization did not stabilise, or a close pair fitted as one pole). The strongest is
   tried first: a pole at that frequency (damping: the median of the fitted ones) is added
   and the LSFD repeated; the new model is kept when the scaled cost ``sum e^2`` falls by at
   least ``MISSING_MIN_GAIN``, step 6 finds nothing wrong with the new poles, and the new
   pole is a mode of its own: not a broad pole under a much sharper one (within the larger
   half-bandwidth, bandwidths more than ``MISSING_BANDWIDTH_RATIO`` apart: that absorbs the
   misfit of a sharp peak, e.g. leakage; two genuine close modes have similar damping). A new
   pole closer to a neighbour than ``MISSING_MIN_LINES`` lines or a quarter of the smaller
   bandwidth, or a duplicate of it (step 6), is kept only on clear evidence: at least a line
   apart, the local cost over the pair's lines falls by ``MISSING_LOCAL_GAIN`` and both keep
   distinct residues (:func:`_pair_is_resolved`). A candidate on a mains harmonic (``mains_hz``)
   much narrower than a mode at the median damping is not tried (reported in the warnings,
   :func:`_mains_line`). The step also runs with the user's frequencies/poles (they are kept,
   poles are only added). Lines given in ``exclude_hz`` are left out of the LSFD and of this
   misfit (:func:`exclude_lines`). Repeated until no candidate is left (at most
   ``MAX_ADDED`` poles, and at most ``MAX_FAILED_TRIES`` rejected candidates in a row: each
   try is a full LSFD, capped at ``MISSING_TRIAL_ITER`` iterations). ``G`` is synthesised from the
   raw poles (window damping included), as the data were measured.
"""
from __future__ import annotations

import logging
import warnings
from dataclasses import replace
from typing import Optional, Sequence, Union

import numpy as np
from scipy.signal import find_peaks

from .frf import FRFSet
from .mac import mac
from .lscf import parse_band
from .fit_checks import (DUPLICATE_BANDWIDTHS, DUPLICATE_MAC, MIGRATE_BANDWIDTHS, bandwidth_hz, duplicate_poles,
                         migrated_poles)
from .modal import damping_ratio, natural_freq_hz, pole_from_fz, transfer
from .selection import poles_from_frequencies, select_poles
from .stabilization import StabilizationResult, stabilization
from .errors import ImpactlabError

__all__ = ["fit_auto", "default_band", "default_max_modes", "check_band_edges", "FitError", "rms_weights",
           "exclude_lines", "mains_harmonics"]

log = logging.getLogger(__name__)

LOW_LINES = 5
MIN_COHERENCE = 0.8
EDGE_BANDWIDTHS = 3.0
MAX_DAMPING = 0.2
MAX_CHECK_ROUNDS = 4
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
MAINS_HZ = (50.0, 60.0)
MAINS_LINES = 2.0
MAINS_DEVIATION_HZ = 0.1
MAINS_WIDTH_FRACTION = 0.5
EXCLUDE_LINES = 2.0


class FitError(ImpactlabError, ValueError):
    """The automatic fit cannot go on (no stable poles, band too narrow...); the message says what to do."""


def default_band(frf: FRFSet) -> tuple[float, float]:
    """Default band (Hz): skip the lowest ``LOW_LINES`` lines and leading low-coherence lines."""
    f = frf.freq_hz
    if f.size < 16:
        raise FitError(f"the FRFs hold only {f.size} lines; at least 16 are needed")
    df = frf.line_spacing_hz
    lo = max(float(f[0]), LOW_LINES * df)
    if frf.coherence is not None and np.any(np.isfinite(frf.coherence)):
        c = np.nanmedian(frf.coherence.reshape(-1, f.size), axis=0)
        head = np.flatnonzero(f <= f[0] + 0.1 * (f[-1] - f[0]))
        ok = head[c[head] >= MIN_COHERENCE]
        # a leading run of low coherence (within the lowest 10 % of the span) moves the edge
        if ok.size and ok[0] > 0:
            lo = max(lo, float(f[ok[0]]))
    lo_line = f[f >= lo - 1e-9 * abs(lo)][0]
    return float(lo_line), float(f[-1])


def default_max_modes(frf: FRFSet, band: tuple[float, float]) -> int:
    """Largest model size for the stabilization: ``2 * peaks + 8`` clipped to [12, 60], where
    ``peaks`` counts the peaks of the summed FRF magnitude (dB) with 3 dB prominence."""
    sel = (frf.freq_hz >= band[0]) & (frf.freq_hz <= band[1])
    s = np.sqrt(np.nansum(np.abs(frf.H[..., sel].reshape(-1, int(sel.sum()))) ** 2, axis=0))
    s = 20 * np.log10(np.maximum(s, np.max(s) * 1e-12 + 1e-300))
    peaks, _ = find_peaks(s, prominence=3.0)
    return int(np.clip(2 * peaks.size + 8, 12, 60))


def check_band_edges(
    poles: np.ndarray, band: tuple[float, float], limits: tuple[float, float], movable: tuple[bool, bool]
) -> tuple[tuple[float, float], list[str]]:
    """Move band edges away from resonances (see module docstring, step 4).

    poles : rad/s; band : current (lo, hi) Hz; limits : how far each edge may go (Hz);
    movable : whether each edge may move. Returns the new band and the warnings.
    """
    lo, hi = band
    warn: list[str] = []
    f = natural_freq_hz(poles)
    bw = 2.0 * damping_ratio(poles) * f
    for fi, b in zip(f, bw):
        margin = EDGE_BANDWIDTHS * b
        if fi - lo < margin:
            want = fi - margin
            if movable[0] and want >= limits[0]:
                lo = want
            else:
                warn.append(
                    f"the mode at {fi:.4g} Hz lies within {EDGE_BANDWIDTHS:g} half-power bandwidths of the lower "
                    f"band edge {lo:.4g} Hz; its estimate may be biased (lower the edge below {want:.4g} Hz if the "
                    "data allow, or raise it above the mode)"
                )
        if hi - fi < margin:
            want = fi + margin
            if movable[1] and want <= limits[1]:
                hi = want
            else:
                warn.append(
                    f"the mode at {fi:.4g} Hz lies within {EDGE_BANDWIDTHS:g} half-power bandwidths of the upper "
                    f"band edge {hi:.4g} Hz; its estimate may be biased (raise the edge above {want:.4g} Hz if the "
                    "data allow, or lower it below the mode)"
                )
    return (lo, hi), warn


def fit_auto(
    frf: FRFSet,
    *,
    band: Optional[Sequence[float]] = None,
    max_modes: Optional[int] = None,
    n_modes: Optional[int] = None,
    method: str = "lm",
    residual_form: str = "physical",
    initial: Union[str, Sequence[complex], Sequence[float], np.ndarray] = "lscf",
    per_frf: bool = False,
    max_iter: int = 100,
    refine_lsfd: bool = False,
    selection_options: Optional[dict] = None,
    add_missing: bool = True,
    frf_weighting: str = "rms",
    mains_hz: Optional[Sequence[float]] = MAINS_HZ,
    exclude_hz: Optional[Sequence[float]] = None,
):
    """Automatic modal fit of an FRF set; returns ``(LSFDResult, StabilizationResult)``.

    Parameters
    ----------
    frf : the FRFs.
    band : (lo_hz, hi_hz) or None for :func:`default_band`.
    max_modes : largest model size of the stabilization (None: :func:`default_max_modes`).
    n_modes : keep the n_modes most persistent pole clusters (None: all that pass the rule).
    method : LSFD iteration, "lm" or "gn".
    residual_form : "physical", "paper" or "none" (see :mod:`analysis.modal`).
    initial : "lscf" or "lsce" (stabilization method), or the user's poles: complex (rad/s,
        used as they are) or real natural frequencies (Hz, damping taken from the
        stabilization diagram, see :func:`analysis.selection.poles_from_frequencies`).
    per_frf, max_iter : passed to :func:`analysis.lsfd.fit_lsfd`.
    refine_lsfd : build the stabilization diagram from LSFD-refined poles (slower).
    selection_options : keyword options of :func:`analysis.selection.select_clusters`.
    frf_weighting : "rms" (default): the LSFD weights every FRF by ``1 / its noise level`` in
        the band (from the coherence, else its RMS; :func:`rms_weights`, step 5); "none":
        unweighted (the paper's S).
    add_missing : after the fit, look for resonances the model misses (step 7 of the module
        docstring) and add poles for them. Also done with the user's frequencies or poles: their
        poles are kept and poles are only added (``add_missing=False``: the user's model as
        given); not done when ``n_modes`` is given (the user chose the model size).
    mains_hz : mains frequencies (Hz) of the guard of step 7: a misfit peak on a harmonic of one
        of them that is much narrower than a mode is not fitted as a mode (reported in the
        warnings). None or () disables the guard.
    exclude_hz : frequencies (Hz) whose lines (within ``EXCLUDE_LINES`` lines) are left out of
        the LSFD and of the misfit of step 7 altogether (zero weight), e.g. mains harmonics;
        see :func:`mains_harmonics`. The stabilization still sees all lines.

    Returns
    -------
    (LSFDResult, StabilizationResult or None): the stabilization is None when complex poles
    were given. ``stab.meta`` holds ``"band"`` (the fitted band), ``"warnings"`` and
    ``"selected_poles"``.
    """
    from .lsfd import fit_lsfd  # lazy import: keeps this module importable on its own

    if not isinstance(frf, FRFSet):
        raise TypeError(f"frf must be an analysis.frf.FRFSet; got {type(frf).__name__}")
    weighting = str(frf_weighting).lower()
    if weighting not in ("rms", "none"):
        raise ValueError(f"frf_weighting must be 'rms' or 'none'; got {frf_weighting!r}")
    mains = tuple(float(m) for m in (mains_hz or ()))
    if any(not np.isfinite(m) or m <= 0 for m in mains):
        raise ValueError(f"mains_hz must hold positive frequencies in Hz (or be None); got {mains_hz!r}")
    user_band = band is not None
    if user_band:
        lo, hi = parse_band(band, frf.freq_hz)
    else:
        lo, hi = default_band(frf)
    # how far an automatic edge may move: down to the lowest reliable line, up to the last line
    limits = (default_band(frf)[0] if not user_band else lo, float(frf.freq_hz[-1]))
    warnings_out: list[str] = []

    given_complex = None
    given_freqs = None
    if isinstance(initial, str):
        stab_method = initial.lower()
        if stab_method not in ("lsce", "lscf"):
            raise ValueError(f"initial must be 'lsce', 'lscf' or an array of poles/frequencies; got {initial!r}")
    else:
        arr = np.atleast_1d(np.asarray(initial))
        if arr.size == 0:
            raise ValueError("no initial poles given: pass poles (rad/s), frequencies (Hz) or 'lsce'/'lscf'")
        if np.iscomplexobj(arr) and np.any(arr.imag != 0):
            given_complex = arr.astype(complex)
        else:
            given_freqs = arr.real.astype(float)
        stab_method = "lscf"

    stab: Optional[StabilizationResult] = None
    if given_complex is None:
        mm = int(max_modes) if max_modes is not None else default_max_modes(frf, (lo, hi))
        if n_modes is not None:
            mm = max(mm, int(n_modes) + 4)
        stab = stabilization(frf, mm, method=stab_method, band=(lo, hi), refine_lsfd=refine_lsfd)
        if given_freqs is not None:
            poles = poles_from_frequencies(given_freqs, stab)
        else:
            poles = select_poles(stab, n_modes=n_modes, **(selection_options or {}))
        if poles.size == 0:
            raise FitError(
                f"no stable physical poles found in {lo:.6g}..{hi:.6g} Hz up to {mm} modes: raise --order, "
                "change the band, or give the poles (--poles F1,F2,...)"
            )
    else:
        poles = given_complex

    (lo2, hi2), warn = check_band_edges(poles, (lo, hi), limits, (not user_band, not user_band))
    warnings_out += warn
    for w in warn:
        log.warning(w)
    if (lo2, hi2) != (lo, hi):
        log.info("band moved from %.6g..%.6g Hz to %.6g..%.6g Hz to keep resonances off its edges", lo, hi, lo2, hi2)
    sel = (frf.freq_hz >= lo2) & (frf.freq_hz <= hi2)
    lo2, hi2 = float(frf.freq_hz[sel][0]), float(frf.freq_hz[sel][-1])
    selected = np.asarray(poles)
    fit_frf = frf
    if exclude_hz is not None and len(exclude_hz):
        fit_frf, n_out_lines = exclude_lines(frf, exclude_hz)
        warnings_out.append(f"{n_out_lines} line(s) around {', '.join(f'{x:.6g}' for x in sorted(exclude_hz))} Hz "
                            "left out of the fit (zero weight)")
        log.info(warnings_out[-1])
    fit_kw = dict(method=method, band=(lo2, hi2), residual_form=residual_form, per_frf=per_frf, max_iter=max_iter,
                  weights=rms_weights(fit_frf, (lo2, hi2)) if weighting == "rms" else None)
    if given_complex is not None:
        result = fit_lsfd(fit_frf, poles, **fit_kw)
    else:
        result = _fit_bounded(fit_frf, poles, fit_kw)
        result = _drop_bad_poles(fit_frf, result, fit_kw, warnings_out)
    if add_missing and n_modes is None:
        # the user's poles/frequencies are kept: step 7 only adds (it never drops a pole)
        result = _add_missing_modes(fit_frf, result, fit_kw, warnings_out, mains, df=frf.line_spacing_hz)
    if not result.success:
        warnings_out.append(f"LSFD did not converge: {result.message}")
        log.warning("LSFD did not converge: %s", result.message)
    info = {"band": (lo2, hi2), "warnings": warnings_out, "selected_poles": selected}
    if stab is not None:
        stab = replace(stab, meta={**stab.meta, **info})
    return result, stab


def mains_harmonics(mains_hz: float, band: Sequence[float]) -> list[float]:
    """Multiples ``k * mains_hz`` (Hz, k >= 1) inside ``band`` = (lo, hi) Hz."""
    m = float(mains_hz)
    if not np.isfinite(m) or m <= 0:
        raise ValueError(f"the mains frequency must be > 0 Hz; got {mains_hz!r}")
    lo, hi = float(band[0]), float(band[1])
    k0 = max(1, int(np.ceil(lo / m)))
    return [k * m for k in range(k0, int(np.floor(hi / m)) + 1)]


def exclude_lines(frf: FRFSet, freqs_hz: Sequence[float], n_lines: float = EXCLUDE_LINES) -> tuple[FRFSet, int]:
    """The FRFs without the lines within ``n_lines`` line spacings of any of ``freqs_hz`` (Hz),
    and how many lines were left out. Dropping a line is the same as weighting it zero in the
    least-squares cost (``sum_k |w_k e_k|^2``); it also keeps the per-FRF weights usable."""
    x = np.asarray(freqs_hz, dtype=float).ravel()
    if x.size and not np.all(np.isfinite(x)):
        raise ValueError(f"frequencies to exclude must be finite (Hz); got {list(freqs_hz)!r}")
    f = frf.freq_hz
    tol = (n_lines + 1e-6) * frf.line_spacing_hz
    drop = np.zeros(f.size, dtype=bool)
    for v in x:
        drop |= np.abs(f - v) <= tol
    if not np.any(drop):
        return frf, 0
    keep = ~drop
    if int(keep.sum()) < 16:
        raise FitError(f"excluding the lines around {list(x)} Hz leaves only {int(keep.sum())} lines; exclude fewer")
    coh = None if frf.coherence is None else np.asarray(frf.coherence)[..., keep]
    return replace(frf, freq_hz=f[keep], H=frf.H[..., keep], coherence=coh), int(drop.sum())


def rms_weights(frf: FRFSet, band: tuple[float, float]) -> np.ndarray:
    """Per-FRF amplitude weights (n_out, n_ref) over the band (step 5): ``1 / sigma_o``, the
    FRF's noise level. With coherence in the data, ``sigma_o^2 = mean_k |H|^2 (1 - g^2) / g^2``
    (the H1 estimate's variance up to the number of averages, which is common to all FRFs of
    a recording), floored at ``(1e-3 RMS_o)^2``; without coherence (or where it says no
    noise at all) ``sigma_o`` is taken proportional to the FRF's RMS. An all-zero FRF gets the
    median weight (it carries no information either way)."""
    sel = (frf.freq_hz >= band[0]) & (frf.freq_hz <= band[1])
    H = frf.H[..., sel]
    p2 = H.real ** 2 + H.imag ** 2
    rms = np.sqrt(np.mean(p2, axis=-1))
    ok = np.isfinite(rms) & (rms > 0)
    if not np.any(ok):
        raise FitError("all FRFs are zero in the band; nothing to fit")
    sigma = rms.copy()
    if frf.coherence is not None:
        g2 = np.clip(np.asarray(frf.coherence, dtype=float)[..., sel], 1e-3, 1.0)
        with np.errstate(invalid="ignore"):
            nv = np.nanmean(p2 * (1.0 - g2) / g2, axis=-1)
        have = ok & np.isfinite(nv) & (nv > 0)
        if np.any(have):
            sigma = np.where(have, np.sqrt(np.maximum(np.where(have, nv, 0.0), (1e-3 * rms) ** 2)), rms)
            # FRFs without a usable coherence take the median noise-to-level ratio of the others
            ratio = float(np.median(sigma[have] / rms[have]))
            sigma = np.where(have, sigma, ratio * rms)
    w = np.full(rms.shape, float(np.median(1.0 / sigma[ok])))
    w[ok] = 1.0 / sigma[ok]
    return w / float(np.max(w[ok]))


def _trust_window_hz(start: np.ndarray, df: float) -> np.ndarray:
    """Half-width (Hz) of each pole's frequency trust region: MIGRATE_BANDWIDTHS bandwidths."""
    return MIGRATE_BANDWIDTHS * bandwidth_hz(start, df)


def _fit_bounded(frf: FRFSet, start: np.ndarray, fit_kw: dict):
    """LSFD with each pole's damped frequency held within ``MIGRATE_BANDWIDTHS`` half-power
    bandwidths of its start (the trust region, steps 5-7)."""
    from .lsfd import fit_lsfd

    return fit_lsfd(frf, start, freq_window_hz=_trust_window_hz(start, frf.line_spacing_hz), **fit_kw)


def _bad_poles(result, start: np.ndarray, df: float, duplicates: bool = True) -> tuple[np.ndarray, list[str]]:
    """Mask of fitted poles to drop (step 6) and the reasons (``duplicates=False``: without the
    duplicate check; step 7 judges its new pole's neighbours itself)."""
    lo, hi = result.band
    fd = result.poles_raw.imag / (2 * np.pi)
    z = result.damping
    out_of_range = ~((fd >= lo) & (fd <= hi) & (z > 0) & (z < MAX_DAMPING))
    on_bound = np.abs(result.poles_raw.imag - start.imag) / (2 * np.pi) >= 0.99 * _trust_window_hz(start, df)
    migrated = (migrated_poles(start, result.poles_raw, df) | on_bound) & ~out_of_range
    moved = np.abs(natural_freq_hz(result.poles_raw) - natural_freq_hz(start)) / bandwidth_hz(start, df)
    dup = duplicate_poles(result.poles_raw, result.model.residues, df, moved=moved) & ~out_of_range & ~migrated
    if not duplicates:
        dup = np.zeros_like(dup)
    why = []
    edge = f"pulled to its trust-region edge ({MIGRATE_BANDWIDTHS:g} half-power bandwidths from its start)"
    for mask, text in ((out_of_range, "moved out of the band or to unphysical damping"),
                       (migrated, edge),
                       (dup, "duplicates a neighbour (same resonance, same shape)")):
        for k in np.flatnonzero(mask):
            why.append(f"{natural_freq_hz(start[k]):.4g} Hz -> {result.freq_hz[k]:.4g} Hz/{100 * z[k]:.3g} %: {text}")
    return out_of_range | migrated | dup, why




def _drop_bad_poles(frf: FRFSet, result, fit_kw: dict, warnings_out: list[str]):
    """Step 6: drop out-of-range, migrated and duplicate poles and refit (see module docstring)."""
    df = frf.line_spacing_hz
    anchor = np.asarray(result.initial_poles if result.initial_poles is not None else result.poles_raw)
    for _ in range(MAX_CHECK_ROUNDS):
        bad, why = _bad_poles(result, anchor, df)
        if not np.any(bad) or np.all(bad):
            break
        msg = f"dropped {int(bad.sum())} pole(s) and refitted: " + "; ".join(why)
        log.info(msg)
        warnings_out.append(msg)
        # the kept poles restart from their own starts, with the same trust regions
        anchor = anchor[~bad]
        result = _fit_bounded(frf, anchor, fit_kw)
    return result


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
    from scipy.signal import peak_widths

    for m in mains:
        k = int(round(c / m))
        if k < 1 or abs(c - k * m) > max(MAINS_LINES * df, k * MAINS_DEVIATION_HZ):
            continue
        i = int(np.argmin(np.abs(f - c)))
        width = float(peak_widths(e ** 2, [i], rel_height=0.5)[0][0]) * df
        mode = 2.0 * z0 * c
        if width < MAINS_WIDTH_FRACTION * mode and width <= (1.0 + MAINS_LINES) * df:
            return (f"the misfit peak at {c:.6g} Hz lies on the mains line {k} x {m:g} Hz and is {width:.3g} Hz wide "
                    f"(a mode at {100 * z0:.3g} % damping would be {mode:.3g} Hz wide): not fitted as a mode (leave "
                    "such lines out with --exclude-lines/--exclude-mains, fit_auto(exclude_hz=...))")
    return None


def _add_missing_modes(frf: FRFSet, result, fit_kw: dict, warnings_out: list[str],
                       mains: Sequence[float] = MAINS_HZ, df: Optional[float] = None):
    """Step 7: add poles at the resonances the model misses (see module docstring). A trial fit
    that does not converge is a rejected candidate (its convergence warning is not passed on).
    The poles of ``result`` are kept; poles are only added."""
    from .lsfd import LSFDConvergenceWarning
    df = frf.line_spacing_hz if df is None else float(df)
    tried: list[float] = []
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
            log.info(mains_why)
            warnings_out.append(mains_why)
            continue
        new = pole_from_fz(c, z0)
        start = np.concatenate([result.poles_raw, [new]])
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", LSFDConvergenceWarning)
                trial = _fit_bounded(frf, start, {**fit_kw, "max_iter": min(fit_kw["max_iter"], MISSING_TRIAL_ITER)})
        except (ValueError, np.linalg.LinAlgError) as exc:
            log.info("adding a pole at %.6g Hz failed (%s)", c, exc)
            failures += 1
            continue
        if any(issubclass(w.category, LSFDConvergenceWarning) for w in caught):
            log.info("adding a pole at %.6g Hz: the LSFD did not converge; not added", c)
            failures += 1
            continue
        bad, _ = _bad_poles(trial, start, df, duplicates=False)
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
        on_line = any(k >= 1 and abs(f_new - k * m) <= max(MAINS_LINES * df, k * MAINS_DEVIATION_HZ)
                      for m in mains for k in [int(round(f_new / m))])
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
    return result
