"""The automatic fit of a large FRF set through its principal response functions.

:func:`analysis.pipeline.fit_auto` hands a set of at least
:data:`analysis.compression.MIN_FRFS` FRFs here. The steps:

1. the band (the user's or :func:`analysis.bands.default_band`) and the FRF weights
   (:func:`analysis.pipeline.rms_weights`, handed over by the pipeline) on the whole set;
2. the principal response functions (:func:`analysis.compression.principal_responses`: a few
   weighted real combinations of the FRFs that keep every resonance; None when no such rank
   exists, and the set is fitted as it is);
3. the whole automatic fit (band edges, stabilization, selection, LSFD, missing modes) on the
   PRFs, unweighted (the weights are in them), the stabilization up to as many modes as the rank
   of the data (``MAX_MODES`` at most) and the selection's clusters cut at ``SELECTION_TOL_FREQ``;
4. one LSFD over all FRFs at the poles found (:func:`analysis.lsfd.lsfd_at_poles`: residues,
   residual terms, S and the poles' standard deviations of the whole set);
5. the verdict on the whole set: :func:`analysis.fit_result.assess_fit` and every visible peak of
   the FRFs accounted for (:func:`analysis.missing_modes.unfitted_resonances`).

The result is a :class:`analysis.fit_result.FitResult` like the uncompressed fit's, with the
stabilization diagram of the PRFs and a warning that says how many PRFs carried the search.
"""
from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import replace
from typing import Any, TypeVar

import numpy as np

from .bands import default_band, default_max_modes, exclude_lines
from .fit_messages import stop
from .fit_result import FitResult, assess_fit
from .frf import FRFSet
from .lscf import parse_band
from .progress import progress
from .threads import limits_blas_threads

__all__ = ["fit_compressed", "with_compression", "MAX_MODES"]

F = TypeVar("F", bound=Callable[..., FitResult])

#: the stabilization of the PRFs goes up to as many modes as the data's rank, at most this many
MAX_MODES = 120
#: the selection's cluster tolerance on the PRFs (relative frequency; ``selection_options`` of the
#: user replace it): the poles of thousands of FRFs scatter far less from order to order than those
#: of a few, and at the stabilization's 1 % two modes 1 % apart were taken for one (4 to 7 of 40
#: modes lost on the scanning-vibrometer benchmark; none at 0.4 %)
SELECTION_TOL_FREQ = 0.004


def with_compression(fit: F, rms_weights: Callable[[FRFSet, tuple[float, float]], np.ndarray]) -> F:
    """Wrap :func:`analysis.pipeline.fit_auto` (``fit``, with its FRF weights ``rms_weights``): a call
    on a set of at least :data:`analysis.compression.MIN_FRFS` FRFs, without ``compress=False`` or
    ``per_frf=True``, goes through :func:`fit_compressed` (when the set compresses)."""
    from .compression import worth_compressing

    @functools.wraps(fit)
    def run(frf: FRFSet, **options: Any) -> FitResult:
        if (options.get("compress") is not False and not options.get("per_frf") and isinstance(frf, FRFSet)
                and worth_compressing(frf)):
            done = fit_compressed(frf, fit, {k: v for k, v in options.items() if k != "compress"}, rms_weights)
            if done is not None:
                return done
        return fit(frf, **options)

    return run  # type: ignore[return-value]


@limits_blas_threads
def fit_compressed(frf: FRFSet, fit: Callable[..., FitResult], options: dict[str, Any],
                   rms_weights: Callable[[FRFSet, tuple[float, float]], np.ndarray]) -> FitResult | None:
    """The automatic fit of ``frf`` through its PRFs (module docstring), or None when the set does
    not compress (the caller then fits it as it is). ``fit`` is :func:`analysis.pipeline.fit_auto`
    as it fits a set uncompressed; ``options`` its keyword arguments (without ``compress``);
    ``rms_weights`` its FRF weights (:func:`analysis.pipeline.rms_weights`)."""
    from .compression import principal_responses
    from .fit_checks import unsupported_poles
    from .lsfd import lsfd_at_poles, sorted_by_frequency
    from .mains_grid import mains_for_fit
    from .missing_modes import structure_verdict
    from .visibility import visible_peaks

    band = options.get("band")
    lo, hi = parse_band(band, frf.freq_hz) if band is not None else default_band(frf)
    weighting = str(options.get("frf_weighting", "rms")).lower()
    shape = (frf.n_outputs, frf.n_references)
    weights = rms_weights(frf, (lo, hi)) if weighting == "rms" else np.ones(shape)
    mm = options.get("max_modes")
    mm = int(mm) if mm is not None else default_max_modes(frf, (lo, hi))
    if options.get("n_modes") is not None:
        mm = max(mm, int(options["n_modes"]) + 4)
    residual_form = str(options.get("residual_form", "physical"))
    progress("fit: principal response functions of %d FRFs", shape[0] * shape[1])
    comp = principal_responses(frf, (lo, hi), weights, mm, residual_form)
    if comp is None:
        return None
    if options.get("max_modes") is None:
        # the rank says how many modes there are (2 per mode and 2 per residual term): the
        # stabilization goes to twice that
        mm = max(mm, min(comp.n_signal, MAX_MODES))
    selection = options.get("selection_options")
    if selection is None:
        selection = {"tol_freq": SELECTION_TOL_FREQ}
    # the mains grid from the FRFs themselves (their coherence shows it), not from their principal responses
    mains, grid = mains_for_fit(options.get("mains_hz", "auto"), frf)
    inner = fit(comp.frf, **{**options, "frf_weighting": "none", "max_modes": mm, "selection_options": selection,
                             "mains_hz": mains})
    band_fit = inner.band
    full = frf
    exclude_hz = options.get("exclude_hz")
    if exclude_hz is not None and len(exclude_hz):
        full, _ = exclude_lines(frf, exclude_hz)
    progress("fit: residues of %d FRFs at %d poles", shape[0] * shape[1], inner.lsfd.poles.size)
    lsfd = lsfd_at_poles(full, inner.lsfd.poles_raw, band=band_fit, residual_form=residual_form, weights=weights,
                         method=inner.lsfd.method,
                         message=stop("compressed", inner=inner.lsfd.message)[1])
    bad, why = unsupported_poles(full, lsfd.poles_raw, lsfd.model_raw.residues, weights)
    dropped: list[str] = []
    if np.any(bad) and not np.all(bad):
        dropped.append("dropped pole(s) without support in the structure's response: " + "; ".join(why))
        lsfd = lsfd_at_poles(full, np.asarray(lsfd.poles_raw)[~bad], band=band_fit, residual_form=residual_form,
                             weights=weights, method=inner.lsfd.method, message=lsfd.message)
    if not inner.lsfd.success:   # the search's own verdict on convergence carries over
        lsfd = replace(lsfd, status=inner.lsfd.status, success=False, message=inner.lsfd.message)
    lsfd = sorted_by_frequency(lsfd)
    problems = assess_fit(lsfd, band_fit)
    left, notes, suspension = structure_verdict(full, visible_peaks(full, band_fit), lsfd, mains)
    said = grid.fit_note() if grid is not None else []
    warnings_out = [comp.describe(), *said, *inner.warnings, *dropped, *notes]
    return FitResult(lsfd=lsfd, stabilization=inner.stabilization, band=band_fit, selected_poles=inner.selected_poles,
                     warnings=tuple(dict.fromkeys(warnings_out)), problems=tuple(problems + left),
                     suspension_hz=suspension)
