"""The whole fit: band selection, stabilization, automatic pole selection, nonlinear LSFD.

This is the paper's Fig. 1 flow with the choices made automatically:

Modules: :mod:`analysis.bands` (steps 1 and 4), :mod:`analysis.bounded_fit` (5-6),
:mod:`analysis.missing_modes` (7, 8), :mod:`analysis.visibility` (the visible peaks),
:mod:`analysis.fit_result` (the verdict); this module runs them.

1. **Band** (paper sec. 3.1). Default: from the lowest reliable line to the top line. The
   lowest ``LOW_LINES`` lines (f < LOW_LINES * df: the record is too short there, and an
   IEPE sensor rolls off) are skipped; with coherence available, leading lines where the
   median coherence over the FRFs is below ``MIN_COHERENCE`` are skipped too. A user band
   is used as given (checked against the data).
2. **Stabilization** up to ``max_modes`` (default ``2 * peaks + 8``, from the peaks of the
   summed FRF magnitude, capped to ``[12, 60]``) with LSCF or LSCE.
3. **Selection** (:mod:`analysis.selection`), or the user's poles / frequencies. On data whose
   coherence comes from at least ``SEED_MIN_AVERAGES`` averages (or does not say how many), one
   more start pole at each visible peak no selected pole lies near (:func:`_with_visible_peaks`);
   without coherence the visible peaks are left to step 7.
4. **Band edges**: a selected pole within ``EDGE_BANDWIDTHS`` half-power bandwidths
   (``2 zeta f``) of a band edge sits on the edge; the paper (sec. 3.1, Fig. 4) shows the
   fit then suffers. An automatic edge is moved outwards (as far as the data and the
   low-line limit allow) so the resonance is inside with its margin; if it cannot be, or
   the band was the user's, a warning is logged and kept in the result's ``warnings``.
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
   problem. Each LSFD of the automatic fit stops at the latest once the Gauss-Newton step still to
   go is below ``SDTOL`` standard deviations of the poles (the slow tail of a fit to noisy data
   changes them by less than that). And with a frequency *trust region*: each pole's damped frequency is held
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
   noted in the result's ``warnings``.
7. **Missing resonances** (:mod:`analysis.missing_modes`). Candidates, in this order: the
   *visible peaks* (:mod:`analysis.visibility`: a peak of an FRF or of the first CMIF curve
   standing >= 10 dB above its neighbouring minima, clean in the coherence over its top) that no
   pole accounts for, strongest first; then, for every pole whose misfit over its top exceeds
   ``SPLIT_MIN_RATIO`` of the data there, a second pole half a bandwidth either side (a close pair
   fitted as one); then the peaks of the scaled misfit ``e(f) = sqrt(mean_o |H_o - G_o|^2 /
   rms_o^2)`` above ``MISSING_MEDIAN_FACTOR`` times its median and ``MISSING_DATA_FRACTION`` of the
   data's ``d(f)``. Each candidate is tried by a *local* LSFD: over a few bandwidths around it,
   on the data minus the synthesis of the model's other poles (and residual terms), its
   neighbours refitted with and without the new pole; it is kept when the local weighted cost
   falls by ``VISIBLE_MIN_GAIN`` (split: ``SPLIT_MIN_GAIN``; misfit: ``MISFIT_MIN_GAIN``; a
   visible peak the model then reproduces within the noise: ``REPRODUCED_MIN_GAIN``), the
   pole is physical and not much broader than the modes, passes the checks of step 6, is not a
   broad pole under a sharper one, and a close neighbour keeps a distinct residue
   (:func:`analysis.missing_modes._pair_is_resolved`). A candidate on a mains harmonic
   (``mains_hz``) much narrower than a mode and no wider than a steady line of the record
   (:func:`analysis.missing_modes.mains_line_max_lines`) is not tried (reported in the warnings). The local
   trials cost a few milliseconds each (tens of lines instead of the whole band); poles closer than the
   data resolve are refitted locally with their neighbours
   (:func:`analysis.missing_modes._reseat_unresolved`); one LSFD over the whole band follows from all
   poles, each held within ``FINAL_BANDWIDTHS`` half-power bandwidths and a factor
   ``FINAL_DAMPING_WINDOW`` in damping of its local estimate (on a wide band an unbounded fit turns
   weak modes into very damped poles that absorb broadband misfit).
   The step also runs with the user's frequencies/poles (poles are only added). Lines given in
   ``exclude_hz`` are left out of the LSFD and of this step (:func:`exclude_lines`).
8. **Verdict**: suspension modes (:mod:`analysis.suspension`: resonances at most a fifth of the
   first elastic mode's frequency, up to six) are named in the warnings and ``suspension_hz``, not
   counted as missed resonances; every other visible peak the final model leaves unaccounted for is named in the
   result's ``problems`` (``success`` is then False): "a resonance at F Hz ... is neither
   fitted by a pole nor reproduced by the model", or "a possible close pair" when a pole within
   2 % stands for it and a neighbour. When the stabilization keeps no pole but the data (with
   coherence) show visible peaks, the fit starts from those peaks.
"""
from __future__ import annotations

import logging
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from .bands import (
    FitError,
    check_band_edges,
    default_band,
    default_max_modes,
    exclude_lines,
    mains_harmonics,
    measured_up_to,
    unsupported_band_text,
    upper_limits,
)
from .bounded_fit import drop_bad_poles, fit_bounded
from .compressed_fit import with_compression
from .fit_checks import unsupported_poles
from .fit_messages import verdict_message
from .fit_result import FitResult, assess_fit
from .frf import FRFSet, window_pole_shift
from .lscf import parse_band
from .mains_grid import mains_for_fit
from .missing_modes import add_missing_modes, final_fit, structure_verdict
from .modal import damping_ratio, natural_freq_hz
from .progress import progress
from .selection import faster_than_window, poles_from_frequencies, select_poles
from .stabilization import StabilizationResult, stabilization
from .threads import limits_blas_threads
from .visibility import VisiblePeak, coherence_bounds_nothing, n_averages, peak_poles, visible_peaks
from .work_limits import check_model_order

__all__ = ["fit_auto", "FitResult", "default_band", "default_max_modes", "check_band_edges", "FitError", "rms_weights",
           "exclude_lines", "mains_harmonics"]

log = logging.getLogger(__name__)


@limits_blas_threads
def fit_auto(
    frf: FRFSet,
    *,
    band: Sequence[float] | None = None,
    max_modes: int | None = None,
    n_modes: int | None = None,
    method: str = "lm",
    residual_form: str = "physical",
    initial: str | Sequence[complex] | Sequence[float] | np.ndarray = "lscf",
    per_frf: bool = False,
    max_iter: int = 100,
    refine_lsfd: bool = False,
    selection_options: dict | None = None,
    add_missing: bool = True,
    frf_weighting: str = "rms",
    mains_hz: Sequence[float] | str | None = "auto",
    exclude_hz: Sequence[float] | None = None,
    compress: bool | None = None,
) -> FitResult:
    """Automatic modal fit of an FRF set; returns a :class:`~analysis.fit_result.FitResult`.

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
        warnings). "auto" (default): the grid the data show (:func:`analysis.mains_grid.detect_mains_grid`;
        both 50 and 60 Hz when it is unknown; a detected grid is named in the warnings). None or
        () disables the guard.
    exclude_hz : frequencies (Hz) whose lines (within ``EXCLUDE_LINES`` lines) are left out of
        the LSFD and of the misfit of step 7 altogether (zero weight), e.g. mains harmonics;
        see :func:`mains_harmonics`. The stabilization still sees all lines.
    compress : None (default): a set of at least :data:`analysis.compression.MIN_FRFS` FRFs (and
        not ``per_frf``) is searched for its poles on its principal response functions and its
        residues fitted on all FRFs (:func:`analysis.compressed_fit.with_compression`, which wraps
        this function at the end of the module and reads this argument); False: never.

    Returns
    -------
    :class:`analysis.fit_result.FitResult`: ``.lsfd`` (the LSFD result), ``.stabilization``
    (None when complex poles were given), ``.band`` (the fitted band), ``.selected_poles``,
    ``.warnings``, and the verdict ``.success`` (converged *and* physically sensible), ``.status``,
    ``.problems``, ``.message``. Non-convergence is a status, never an exception.

    Examples
    --------
    Two modes (40 Hz at 1 %, 95 Hz at 2 % of critical damping) seen at two points:

    >>> import numpy as np
    >>> from analysis import ModalModel, fit_auto, synthesize
    >>> from analysis.modal import pole_from_fz
    >>> model = ModalModel(pole_from_fz([40.0, 95.0], [0.01, 0.02]), [[[-20j, 50j]], [[30j, 25j]]],
    ...                    quantity="receptance")
    >>> frf = synthesize(model, np.arange(1.0, 200.0, 0.25))       # lines in Hz
    >>> fit = fit_auto(frf)
    >>> fit.success, fit.status
    (True, 'converged')
    >>> np.round(fit.freq_hz, 3), np.round(100 * fit.damping, 3)   # Hz, % of critical
    (array([40., 95.]), array([1., 2.]))
    """
    from .lsfd import LSFDConvergenceWarning, fit_lsfd, sorted_by_frequency  # lazy: this module imports alone

    if not isinstance(frf, FRFSet):
        raise TypeError(f"frf must be an analysis.frf.FRFSet; got {type(frf).__name__}")
    weighting = str(frf_weighting).lower()
    if weighting not in ("rms", "none"):
        raise ValueError(f"frf_weighting must be 'rms' or 'none'; got {frf_weighting!r}")
    mains, grid = mains_for_fit(mains_hz, frf)
    user_band = band is not None
    if user_band:
        lo, hi = parse_band(band, frf.freq_hz)
    else:
        lo, hi = default_band(frf)
    # how far an automatic edge may move: within what the data support (default_band)
    limits = default_band(frf) if not user_band else (lo, float(frf.freq_hz[-1]))
    warnings_out: list[str] = []
    if grid is not None:
        warnings_out += grid.fit_note()

    stab_method, given_complex, given_freqs = _initial_kind(initial)
    given = given_complex if given_complex is not None else given_freqs
    if given is not None:  # before anything is built for them: as many modes as the band's lines support
        check_model_order(int(given.size), int(np.sum((frf.freq_hz >= lo) & (frf.freq_hz <= hi))),
                          frf.n_outputs * frf.n_references, "the given poles:", band_hz=(lo, hi))
    progress("fit: band %.6g..%.6g Hz (%d lines, %d FRFs)", lo, hi,
             int(np.sum((frf.freq_hz >= lo) & (frf.freq_hz <= hi))), frf.n_outputs * frf.n_references)
    stab: StabilizationResult | None = None
    if given_complex is None:
        mm = int(max_modes) if max_modes is not None else default_max_modes(frf, (lo, hi))
        if n_modes is not None:
            mm = max(mm, int(n_modes) + 4)
        progress("fit: stabilization (%s) up to %d modes", stab_method.upper(), mm)
        stab = stabilization(frf, mm, method=stab_method, band=(lo, hi), refine_lsfd=refine_lsfd)
        seed_peaks = given_freqs is None and n_modes is None and add_missing
        poles = _start_poles(frf, (lo, hi), stab, mm, given_freqs, n_modes, selection_options, seed_peaks,
                             warnings_out)
    else:
        poles = given_complex
    # no start slower than the exponential window alone (negative damping once it is removed)
    poles = faster_than_window(poles, window_pole_shift(frf.exp_window_tau_s))

    # the start poles move the edges; whether a mode ends up near an edge is said from the fitted poles
    (lo2, hi2), _ = check_band_edges(poles, (lo, hi), limits, (not user_band, not user_band))
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
    fit_kw: dict[str, Any] = dict(method=method, band=(lo2, hi2), residual_form=residual_form, per_frf=per_frf, max_iter=max_iter,
                  weights=rms_weights(fit_frf, (lo2, hi2)) if weighting == "rms" else None, sdtol=SDTOL)
    progress("fit: LSFD (%s) from %d poles", method.upper(), np.asarray(poles).size)
    if given_complex is not None:
        result = fit_lsfd(fit_frf, poles, **fit_kw)
    else:
        with warnings.catch_warnings():
            # the status is read below ("LSFD did not converge" in the warnings): not a second notice
            warnings.simplefilter("ignore", LSFDConvergenceWarning)
            result = fit_bounded(fit_frf, poles, fit_kw)
        result = drop_bad_poles(fit_frf, result, fit_kw, warnings_out)
    visible = visible_peaks(fit_frf, (lo2, hi2))
    complete_search = add_missing and n_modes is None
    if complete_search:
        # the user's poles/frequencies are kept: step 7 only adds (it never drops a pole)
        progress("fit: looking for resonances the model misses")
        result = add_missing_modes(fit_frf, result, fit_kw, warnings_out, mains, df=frf.line_spacing_hz,
                                   visible=visible)
    if given_complex is None:
        result = _drop_unsupported(fit_frf, result, fit_kw, warnings_out)
        if len(mains) == 1:   # one grid known (the user's, or the one the data show)
            result = _drop_mains_lines(fit_frf, result, fit_kw, mains, warnings_out)
    if not result.success:
        warnings_out.append(verdict_message("not converged", lsfd=result.message))
        log.warning("%s", warnings_out[-1])
    n_avg = n_averages(frf)
    if n_avg.size and np.all(n_avg == 1):
        warnings_out.append("one average per point: the coherence is 1 everywhere and says nothing about the noise; "
                            "the standard deviations and weights rest on the misfit alone (take several hits per point)")
    result = sorted_by_frequency(result)
    _, edge_warn = check_band_edges(result.poles_raw, (lo2, hi2), (lo2, hi2), (False, False))
    warnings_out += edge_warn
    for w in edge_warn:
        log.warning(w)
    problems = assess_fit(result, (lo2, hi2))
    limits_hz = upper_limits(frf)
    beyond = (unsupported_band_text(hi2, limits_hz, where="the structure",
                                    continuous=frf.meta.get("excitation") == "continuous") if user_band else None)
    if beyond:   # the default band stops at these limits; a user's band may not
        if np.any(np.asarray(result.freq_hz) > (measured_up_to(limits_hz) or np.inf)):   # a mode where nothing was measured
            problems.append(beyond)
        else:
            warnings_out.append(beyond)
            log.warning(beyond)
    left, notes, suspension = structure_verdict(fit_frf, visible, result, mains)
    warnings_out += notes
    problems += left
    for p in problems:
        log.warning("implausible fit: %s", p)
    return FitResult(lsfd=result, stabilization=stab, band=(lo2, hi2), selected_poles=selected,
                     warnings=tuple(dict.fromkeys(warnings_out)), problems=tuple(problems), suspension_hz=suspension)


def _drop_unsupported(frf: FRFSet, result: Any, fit_kw: dict[str, Any], warnings_out: list[str]) -> Any:
    """The poles neither the CMIF nor a consistent shape supports (:func:`analysis.fit_checks.unsupported_poles`)
    dropped and the rest refitted from where they ended, the drop named in the warnings."""
    bad, why = unsupported_poles(frf, result.poles_raw, result.model_raw.residues, fit_kw.get("weights"))
    if not np.any(bad) or np.all(bad):
        return result
    msg = "dropped pole(s) without support in the structure's response: " + "; ".join(why)
    log.info(msg)
    warnings_out.append(msg)
    # the refit is checked as the first fit was (a pole it moves out of the band is dropped, not reported)
    return drop_bad_poles(frf, fit_bounded(frf, np.asarray(result.poles_raw)[~bad], fit_kw), fit_kw, warnings_out)


def _drop_mains_lines(frf: FRFSet, result: Any, fit_kw: dict[str, Any], mains: Sequence[float],
                      warnings_out: list[str]) -> Any:
    """The poles on a line of the mains grid ``mains`` (Hz) much sharper than the modes
    (:func:`analysis.missing_modes.mains_line_poles`) dropped and the rest refitted, the drop named in the
    warnings: the selection's poles get the rule step 7 applies to the poles it adds."""
    from .missing_modes import mains_line_poles

    bad = mains_line_poles(result.poles_raw, mains, float(frf.line_spacing_hz))
    if not np.any(bad) or np.all(bad):
        return result
    fn, z = natural_freq_hz(result.poles_raw[bad]), damping_ratio(result.poles_raw[bad])
    msg = ("dropped pole(s) on a mains line, much sharper than the modes: "
           + ", ".join(f"{a:.6g} Hz/{100 * b:.3g} %" for a, b in zip(fn, z))
           + f" (grid {', '.join(f'{m:g}' for m in mains)} Hz; --mains none keeps them)")
    log.info(msg)
    warnings_out.append(msg)
    # a line's pole is sharp and small: the others stay where the fit put them (held as step 7's final fit holds them)
    return final_fit(frf, np.asarray(result.poles_raw)[~bad], fit_kw, warnings_out)


def _initial_kind(initial: str | Sequence[complex] | Sequence[float] | np.ndarray
                  ) -> tuple[str, np.ndarray | None, np.ndarray | None]:
    """``fit_auto``'s ``initial``: (stabilization method, the user's complex poles or None, the
    user's natural frequencies in Hz or None)."""
    if isinstance(initial, str):
        stab_method = initial.lower()
        if stab_method not in ("lsce", "lscf"):
            raise ValueError(f"initial must be 'lsce', 'lscf' or an array of poles/frequencies; got {initial!r}")
        return stab_method, None, None
    arr = np.atleast_1d(np.asarray(initial))
    if arr.size == 0:
        raise ValueError("no initial poles given: pass poles (rad/s), frequencies (Hz) or 'lsce'/'lscf'")
    if np.iscomplexobj(arr) and np.any(arr.imag != 0):
        return "lscf", arr.astype(complex), None
    return "lscf", None, arr.real.astype(float)


def _start_poles(frf: FRFSet, band: tuple[float, float], stab: StabilizationResult, max_modes: int,
                 given_freqs: np.ndarray | None, n_modes: int | None, selection_options: dict | None,
                 seed_peaks: bool, warnings_out: list[str]) -> np.ndarray:
    """Steps 2-3: the LSFD's start from the stabilization diagram: the user's frequencies, or the
    selection plus the visible peaks no selected pole lies near (``seed_peaks``, data whose coherence
    is trusted: :func:`_with_visible_peaks`); the visible peaks alone when the diagram keeps no pole.
    Raises FitError when there is no start at all."""
    lo, hi = band
    if given_freqs is not None:
        poles = poles_from_frequencies(given_freqs, stab, window_shift=window_pole_shift(frf.exp_window_tau_s))
    else:
        poles = select_poles(stab, n_modes=n_modes, **(selection_options or {}))
    if poles.size == 0 and not coherence_bounds_nothing(frf):   # peaks confirmed by the coherence only
        poles = _poles_from_peaks(frf, band, stab, warnings_out)
    elif poles.size and seed_peaks and _peaks_trusted(frf):
        poles = _with_visible_peaks(frf, band, stab, poles)
    if poles.size == 0:
        raise FitError(
            f"no stable physical poles found in {lo:.6g}..{hi:.6g} Hz up to {max_modes} modes: raise --order, "
            "change the band, or give the poles (--poles F1,F2,...)"
        )
    return poles


#: every LSFD of the automatic fit also stops once the step still to go is below this many standard
#: deviations of the poles (``fit_lsfd(sdtol=...)``): the remaining error is a hundredth of the
#: statistical one, and the slow tail of iterations that changes the poles by less is not run
SDTOL = 0.01

#: averages per FRF from which the coherence confirms a visible peak for the fit's start
SEED_MIN_AVERAGES = 3


def _peaks_trusted(frf: FRFSet) -> bool:
    """Whether the visible peaks of ``frf`` may start the fit: the set carries coherence, and it comes
    from at least ``SEED_MIN_AVERAGES`` averages per FRF or the number of averages is not known (FRFs
    read from a file that does not say: their coherence is taken as the analyser's, as for any peak's
    visibility). Without coherence a visible peak is only a bump 10 dB high and two lines wide, which
    the noise of a finely resolved FRF shows by the dozen where the excitation has no energy; such peaks
    are left to step 7's local trials."""
    if coherence_bounds_nothing(frf):   # none, or one average's (1 on every line)
        return False
    n_avg = n_averages(frf)
    return n_avg.size == 0 or bool(np.all(n_avg >= SEED_MIN_AVERAGES))


def _with_visible_peaks(frf: FRFSet, band: tuple[float, float], stab: StabilizationResult,
                        poles: np.ndarray) -> np.ndarray:
    """The selected ``poles`` and one more at each visible peak (:mod:`analysis.visibility`) that no
    selected pole lies near, with the selected poles' median damping (:func:`peak_poles`): the data
    show at least that many modes, and a whole-band LSFD started with fewer drags its poles between resonances (a pole pulled
    halfway between two modes fits neither and leaves the search for the missed ones without
    clean neighbours). Not for data whose coherence comes from fewer than ``SEED_MIN_AVERAGES``
    averages (:func:`_peaks_trusted`): noise reaches a coherence of 0.9 on a tenth of the lines with
    two averages, on a hundredth with three (``0.1 ** (n - 1)``), so only then does the coherence
    confirm a visible peak; there the peaks are left to step 7's local trials."""
    from .visibility import unaccounted_peaks

    # peaks are found on the whole record (a resonance just inside an edge has a flank outside it,
    # and its prominence is measured there), then kept inside the band; a pole near an edge then
    # moves the edge (step 4)
    peaks = [v for v in visible_peaks(frf, (float(frf.freq_hz[0]), band[1])) if v.freq_hz >= band[0]]
    missed, _ = unaccounted_peaks(peaks, natural_freq_hz(poles), frf.line_spacing_hz)
    if not missed:
        return poles
    shift = window_pole_shift(frf.exp_window_tau_s)   # the window's decay: the same for every mode
    extra = peak_poles(missed, frf.line_spacing_hz, float(np.median(damping_ratio(np.asarray(poles) + shift))), shift)
    log.info("the fit starts from %d selected pole(s) and %d visible peak(s) at %s Hz", poles.size, extra.size,
             ", ".join(f"{natural_freq_hz(p):.5g}" for p in extra))
    return np.concatenate([np.asarray(poles), extra])


def _poles_from_peaks(frf: FRFSet, band: tuple[float, float], stab: StabilizationResult,
                      warnings_out: list[str]) -> np.ndarray:
    """Starting poles at the visible peaks (:mod:`analysis.visibility`) when the stabilization
    kept none and the data carry coherence: one per distinct peak frequency (peaks within ``max(MATCH_FRACTION f, MATCH_LINES
    df)`` are one), damping from each peak's half-power width (:func:`peak_poles`). Empty when the
    data show no peak either."""
    from .visibility import MATCH_FRACTION, MATCH_LINES

    df = frf.line_spacing_hz
    freqs: list[float] = []
    kept: list[VisiblePeak] = []
    for v in visible_peaks(frf, band):   # most prominent first
        if all(abs(v.freq_hz - x) > max(MATCH_FRACTION * x, MATCH_LINES * df) for x in freqs):
            freqs.append(v.freq_hz)
            kept.append(v)
    if not freqs:
        return np.zeros(0, dtype=complex)
    msg = (f"the stabilization kept no pole in {band[0]:.6g}..{band[1]:.6g} Hz; the fit starts from the "
           f"{len(freqs)} visible peak(s) at {', '.join(f'{x:.5g}' for x in sorted(freqs))} Hz")
    log.info(msg)
    warnings_out.append(msg)
    return peak_poles(kept, df)


def rms_weights(frf: FRFSet, band: tuple[float, float]) -> np.ndarray:
    """Per-FRF amplitude weights (n_out, n_ref) over the band (step 5): ``1 / sigma_o``, the
    FRF's noise level. With coherence in the data, ``sigma_o^2 = mean_k |H|^2 (1 - g^2) / g^2``
    (the H1 estimate's variance up to the number of averages, which is common to all FRFs of
    a recording), floored at ``(1e-3 RMS_o)^2``; without coherence (or where it says no
    noise at all) ``sigma_o`` is taken proportional to the FRF's RMS. An all-zero FRF gets the
    median weight (it carries no information either way)."""
    sel = (frf.freq_hz >= band[0]) & (frf.freq_hz <= band[1])
    if not np.any(sel):
        raise FitError(f"no line of the data lies in the band {band[0]:.6g}..{band[1]:.6g} Hz; choose a band inside the data")
    i0, i1 = np.flatnonzero(sel)[[0, -1]]
    H = frf.H[..., i0:i1 + 1]   # a view (the band's lines are contiguous)
    rms = np.sqrt((np.einsum("...k,...k->...", H.real, H.real) + np.einsum("...k,...k->...", H.imag, H.imag))
                  / H.shape[-1])
    ok = np.isfinite(rms) & (rms > 0)
    if not np.any(ok):
        raise FitError("all FRFs are zero in the band; nothing to fit")
    sigma = rms.copy()
    if frf.coherence is not None:
        p2 = H.real ** 2 + H.imag ** 2
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


fit_auto = with_compression(fit_auto, rms_weights)   # large sets: the pole search on their PRFs
