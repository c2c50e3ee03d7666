"""The whole diagnosis in one call: :func:`diagnose` (measurement and simulation in, :class:`Diagnosis` out).

Steps: the measurement (an :class:`~analysis.frf.FRFSet` or a file) is read and cut to its band (the
data's own band for a file, and for an FE simulation the band where its mesh has converged); the
simulation (a pole-residue :class:`~analysis.modal.ModalModel`, an FRF set turned into one by the
automatic fit, or an FE model with physical causes, :class:`analysis.diagnosis.physical.PhysicalSimulation`)
is compared, the causes are fitted and cross-validated (:func:`analysis.diagnosis.verdict.diagnose_frfs`),
and a recording's hits get the time-data stage (:mod:`analysis.diagnosis.timedata_stage`; an
``unexplained`` verdict becomes the time-data cause that counts) and the level stage: soft against
hard hits and, given a simulation of the recorded test, the ``joint_nonlinearity`` cause, which
becomes the verdict when present (:func:`analysis.diagnosis.joint_nonlinearity.level_dependence`).
"""
from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..frf import FRFSet
from ..modal import ModalModel
from ..threads import blas_threads
from .joint_nonlinearity import JointSimulationFactory
from .verdict import Diagnosis, diagnose_frfs

__all__ = ["diagnose", "model_with_correction", "simulation_model", "driving_point_shapes", "as_receptance",
           "noise_with_simulated_frfs"]

log = logging.getLogger(__name__)


def driving_point_shapes(model: ModalModel, at: str = "outputs") -> np.ndarray | None:
    """Mass-normalised mode shapes (1/sqrt(kg)) at the outputs, (n_out, n_modes), scaled from a fitted
    model's residues through a driving point (an output with the label of a reference: same node and
    direction); None without one. For a real mode the receptance residue is ``phi_o phi_d / (2 j w_d)``
    and a model of quantity power p has ``lambda^p`` times it, so ``A_o = 2 j w_d R_od / lambda^p =
    phi_o phi_d`` and ``phi_o = A_o / sqrt(A_d)``. A mode not seen at the driving point gets zeros.
    ``at="references"``: the shapes at the references instead, (n_ref, n_modes), from the driving point's
    row (``phi_r = A_dr / sqrt(A_d)``)."""
    from ..frf import QUANTITY_POWER
    from .effect_types import driving_point

    dp = driving_point(model)
    if dp is None:
        return None
    i_d, j_d = dp
    lam = np.asarray(model.poles, complex)
    A = 2j * lam.imag[None, None, :] * np.asarray(model.residues) / lam[None, None, :] ** QUANTITY_POWER[model.quantity]
    a_d = A[i_d, j_d]
    seen = np.abs(a_d) > 1e-6 * np.max(np.abs(a_d), initial=0.0)
    root = np.where(seen, np.sqrt(np.where(seen, a_d, 1.0)), 1.0)
    rows = A[:, j_d, :] if at == "outputs" else A[i_d, :, :]
    return np.where(seen[None, :], np.real(rows / root[None, :]), 0.0)


def as_receptance(model: ModalModel) -> ModalModel:
    """The model's modes in receptance form (residues ``R / lambda^p``; physical residual terms are the
    same numbers in every form, other residual terms are dropped).

    A pole-residue model of accelerance is the receptance model times ``s^2`` *minus* the polynomial
    ``sum_r R_r (s + lambda_r) + c.c.`` (``lambda^2 / (s - lambda) = s^2 / (s - lambda) - (s + lambda)``),
    which a fit cancels with its residual terms. An effect that moves the poles (a mass, a stiffness)
    changes that polynomial too and would leave a constant error below the first mode and between
    modes; in receptance form a moved mode changes the measured quantity by exactly ``s^p`` times its
    receptance change."""
    from ..frf import QUANTITY_POWER

    p = QUANTITY_POWER[model.quantity]
    if p == 0:
        return model
    keep = model.residual_form == "physical"
    return replace(model, residues=np.asarray(model.residues) / np.asarray(model.poles)[None, None, :] ** p,
                   quantity="receptance", residual_form=model.residual_form if keep else "none",
                   upper_residual=model.upper_residual if keep else None,
                   lower_residual=model.lower_residual if keep else None)


def model_with_correction(model: ModalModel, sim: FRFSet, above_band: bool = True,
                          band_hz: tuple[float, float] | None = None, refit: bool = True) -> ModalModel:
    """The fitted ``model`` (in receptance form, :func:`as_receptance`; with a driving point and
    ``above_band``, plus the pseudo-mode just above the band that the FRFs' tail shows,
    :func:`analysis.diagnosis.above_band.with_above_band_mode`, fitted in ``band_hz``, the band the
    model was fitted in: default the FRFs' lines; with ``refit``, all of it refitted to ``sim`` in
    receptance, :func:`analysis.diagnosis.base_refit.refit_in_receptance`) plus, in
    ``meta["frf_correction"]``, what it misses of the simulated FRFs ``sim``, so that the prediction
    without effects is the simulated FRFs themselves (modal effects move only the fitted modes); with a
    driving point also ``meta["output_shapes"]`` (:func:`driving_point_shapes`), so that the
    accelerometers' mass can be fitted.

    ``model`` describes the structure (window-corrected poles, as :attr:`analysis.lsfd.LSFDResult.model`).
    FRFs that carry their own processing (a recording's exponential window ``sim.exp_window_tau_s`` and
    finite record, :func:`analysis.diagnosis.verdict.known_processing`) are fitted as they show the modes
    (the window's decay in every pole) and the model returned is again the structure's; the correction is
    what the model *seen through that processing* misses, so that a measurement processed alike is
    predicted as the simulated FRFs themselves and the window is not counted twice."""
    from ..frf import window_pole_shift
    from ..lsfd import seen_through_window
    from .above_band import with_above_band_mode
    from .base_refit import refit_in_receptance
    from .compare import line_weights
    from .effects import predict
    from .verdict import known_processing

    # fitted as the simulated FRFs show the modes (through their window), then back to the structure's poles
    shift = window_pole_shift(sim.exp_window_tau_s)
    model = seen_through_window(as_receptance(model), sim.exp_window_tau_s)
    if above_band:
        labelled = replace(model, outputs=tuple(sim.outputs), references=tuple(sim.references))
        rec = sim if sim.quantity == model.quantity else sim.as_quantity(model.quantity)
        model = with_above_band_mode(labelled, rec, line_weights(replace(rec, coherence=None)), band_hz)
    if refit:
        model = refit_in_receptance(replace(model, outputs=tuple(sim.outputs), references=tuple(sim.references)),
                                    sim, band_hz)
    model = replace(model, poles=np.asarray(model.poles, complex) + shift)
    # in the simulated FRFs' own quantity: a windowed model converted to another form is not the window
    # seen in that form, so the correction is exact only where the window acted
    syn = predict(model, sim.freq_hz, sim.quantity, known_processing(sim))
    corr = replace(sim, H=sim.H - syn.H, coherence=None)
    meta = dict(model.meta)
    meta["frf_correction"] = corr
    labelled = replace(model, outputs=tuple(sim.outputs), references=tuple(sim.references))
    shapes = driving_point_shapes(labelled)
    if shapes is not None:
        meta["output_shapes"] = shapes
        meta["reference_shapes"] = driving_point_shapes(labelled, at="references")
    return replace(model, outputs=tuple(sim.outputs), references=tuple(sim.references), meta=meta)


def simulation_model(sim: FRFSet, measured: FRFSet, source: str = "the simulation",
                     band: tuple[float, float] | None = None) -> ModalModel:
    """A simulation given as FRFs, at the measured points, as a modal model (automatic fit, in ``band``
    (Hz) when the user gave one: its warnings then speak of that band) with the correction of
    :func:`model_with_correction`. Raises :class:`InputError` when points are missing."""
    from ..inputs import InputError
    from ..pipeline import FitError, fit_auto
    from .compare import common_points

    outs, refs = common_points(measured, sim)
    if len(outs) != measured.n_outputs or len(refs) != measured.n_references:
        raise InputError(f"{source} lacks some measured points: it has outputs {list(sim.outputs)} and references "
                         f"{list(sim.references)}; measured {list(measured.outputs)} / {list(measured.references)}")
    sim = sim.select(outs, refs)
    try:
        result = fit_auto(sim, band=band)
    except FitError as exc:
        raise InputError(f"cannot build a modal model of the simulated FRFs in {source}: {exc}") from None
    return model_with_correction(result.lsfd.model, sim, band_hz=result.band)


def noise_with_simulated_frfs(measured: FRFSet, sim: FRFSet, extra_noise_db: dict) -> float | None:
    """The noise level (dB, :func:`analysis.diagnosis.compare.error_db`'s scale) of the difference between
    ``measured`` and a simulation given as *measured-like* FRFs ``sim`` (another capture, an exported
    test): the measurement's own level (the largest of :func:`~analysis.diagnosis.compare.noise_level`
    and ``extra_noise_db``) plus the simulated FRFs' (their :func:`~analysis.diagnosis.compare.noise_level`
    on the measured lines and points, with the measured weights), added as powers: two noisy captures of
    one structure differ by both noises. None when ``sim`` lacks the measured lines (another line spacing)
    or points."""
    from .compare import common_points, effective_noise_db, line_weights, noise_level

    f = measured.freq_hz
    outs, refs = common_points(measured, sim)
    if len(outs) != measured.n_outputs or len(refs) != measured.n_references:
        return None
    at = np.searchsorted(sim.freq_hz, f)
    if np.any(at >= sim.freq_hz.size) or not np.allclose(sim.freq_hz[np.minimum(at, sim.freq_hz.size - 1)], f,
                                                         rtol=0.0, atol=1e-9 * max(float(f[-1]), 1.0)):
        return None
    picked = sim.select(list(measured.outputs), list(measured.references))
    if picked.quantity != measured.quantity:
        picked = picked.as_quantity(measured.quantity)
    picked = replace(picked, freq_hz=f.copy(), H=picked.H[..., at],
                     coherence=None if picked.coherence is None else picked.coherence[..., at])
    if not np.all(np.isfinite(picked.H)):
        return None
    w = line_weights(measured)
    own = effective_noise_db({**extra_noise_db, **noise_level(measured, w)})
    theirs = effective_noise_db(noise_level(picked, w))
    return float(10 * np.log10(10 ** (own / 10) + 10 ** (theirs / 10)))


def _is_physical(x: Any) -> bool:
    return all(hasattr(x, a) for a in ("causes", "modes", "model"))


def diagnose(
    measured: FRFSet | str | Path,
    simulated: Any,
    *,
    band: tuple | str | None = None,
    effects: Sequence[str] | None = None,
    estimator: str | None = None,
    physical: Any = None,
    recording: str | Path | None = None,
    extra_noise_db: dict | None = None,
    joint_simulation: JointSimulationFactory | None = None,
    **rule: Any,
) -> Diagnosis:
    """Compare a measurement with a simulation and name what differs (``docs/diagnosis.md``).

    measured : FRF set, or a file (recording ``.h5`` or UFF 58) read with ``estimator``.
    simulated : a :class:`ModalModel` at the measured points (any quantity); an :class:`FRFSet`
        or FRF file with the measured points (turned into a modal model by the automatic fit); or an
        FE model with physical causes (``causes``, ``modes``, ``model``: e.g.
        :class:`simulator.physical.FrameVariants`), whose unchanged model is the simulation.
    band : ``(lo, hi)`` Hz; None: a file gets the band from its data (analyser, hammer, coherence)
        and an FRF set is used on its own lines (but a 0 Hz line); ``"data"``: from the data for an FRF
        set too. With an FE model and a band from the data, the band stops where the FE mesh has converged.
    effects : only these causes (names of the catalogue or of the physical causes).
    physical : the FE model when ``simulated`` is its :class:`ModalModel` already.
    recording : the recording whose hits made ``measured`` (a file given as ``measured`` is used when
        it is a recording): the noise from the hits' scatter and the time-data stage.
    extra_noise_db : further noise estimates (dB) as :func:`diagnose_frfs` takes them.
    joint_simulation : builds the simulation of the recorded test for the ``joint_nonlinearity`` cause
        (:data:`analysis.diagnosis.joint_nonlinearity.JointSimulationFactory`; the face builds it, e.g.
        from a simulator config); without it a recording's levels are compared but no joint is named.
    rule : the decision rule's settings of :func:`diagnose_frfs` (``z_min``, ``min_gain_db``, ...).

    Raises :class:`analysis.inputs.InputError` for unreadable or inconsistent input and
    :class:`analysis.diagnosis.EffectError` for unknown effects. Neither input is modified.
    """
    from ..inputs import detect_format, load_input

    if isinstance(measured, (str, Path)):
        path = Path(measured)
        if recording is None and detect_format(path) == "recording":
            recording = path
        measured = load_input(path, estimator=estimator)
        if band is None:
            band = "data"
    # one BLAS thread count for every stage below (the FE model's eigenproblems, the fits): a small problem
    # run with a thread per core costs more CPU than its work when other programs keep the cores busy
    with blas_threads(float(measured.H.size)):
        return _diagnose_set(measured, simulated, band=band, effects=effects, estimator=estimator, physical=physical,
                             recording=recording, extra_noise_db=extra_noise_db, joint_simulation=joint_simulation,
                             **rule)


def _diagnose_set(measured: FRFSet, simulated: Any, *, band: tuple | str | None, effects: Sequence[str] | None,
                  estimator: str | None, physical: Any, recording: str | Path | None, extra_noise_db: dict | None,
                  joint_simulation: JointSimulationFactory | None, **rule: Any) -> Diagnosis:
    """:func:`diagnose` of a measurement read already (``recording``: the file when it is one)."""
    from ..bands import default_band
    from ..inputs import InputError, load_input
    from .compare import common_points

    sim_frfs: FRFSet | None = None
    if _is_physical(simulated):
        physical, base = simulated, simulated.model(None, {})
    elif isinstance(simulated, ModalModel):
        base = simulated
    elif isinstance(simulated, (FRFSet, str, Path)):
        source = str(simulated) if not isinstance(simulated, FRFSet) else "the simulation"
        sim = simulated if isinstance(simulated, FRFSet) else load_input(Path(simulated), estimator=estimator)
        user_band = (float(band[0]), float(band[1])) if band is not None and not isinstance(band, str) else None
        base = simulation_model(sim, measured, source, band=user_band)
        sim_frfs = sim
    else:
        raise InputError(f"the simulation is a {type(simulated).__name__}; give a modal model, an FRF set or file, "
                         "or an FE model with physical causes")
    if isinstance(band, str):
        if band != "data":
            raise InputError(f"band {band!r}: give (lo, hi) in Hz, None or 'data'")
        lo, hi = default_band(measured)
        if physical is not None and hasattr(physical, "converged_below_hz"):
            top = float(physical.converged_below_hz())
            if top < hi:
                log.info("band %.4g-%.4g Hz: the simulation's mesh is converged only below %.4g Hz", lo, top, top)
                hi = top
        measured = measured.band(lo, hi)
    elif band is not None:
        measured = measured.band(float(band[0]), float(band[1]))
    positive = measured.freq_hz > 0
    if not positive.all() and np.count_nonzero(positive) >= 2:
        # the 0 Hz line (an FRF set used on all its lines): no modal content, and undefined in receptance,
        # the form the simulation's modes are compared in
        measured = measured.band(float(measured.freq_hz[positive][0]), float(measured.freq_hz[-1]))
    finite = np.all(np.isfinite(measured.H), axis=(0, 1))
    if not finite.all():
        raise InputError(f"the measurement holds NaN/inf lines at {np.count_nonzero(~finite)} frequencies; "
                         "give a band that excludes them")
    outs, refs = common_points(measured, base)
    measured = measured.select(outs, refs)
    noise = dict(extra_noise_db or {})
    if recording is not None and "hits" not in noise:
        from .compare import line_weights
        from .hit_noise import hit_scatter_noise_db

        noise["hits"] = hit_scatter_noise_db(recording, measured, line_weights(measured))
    if sim_frfs is not None:
        both = noise_with_simulated_frfs(measured, sim_frfs, noise)
        if both is not None:
            noise["simulation"] = both
    diag = diagnose_frfs(measured, base, effects=effects, physical=physical, extra_noise_db=noise, **rule)
    if recording is None:
        return diag
    band_hz = (float(measured.freq_hz[0]), float(measured.freq_hz[-1]))
    return _level_stage(_time_data_stage(diag, recording, band_hz, base), recording, band_hz, joint_simulation)


def _time_data_stage(diag: Diagnosis, recording: str | Path, band_hz: tuple[float, float],
                     base: ModalModel) -> Diagnosis:
    """``diag`` with the recording's time-data causes in ``band_hz`` (Hz); an ``unexplained`` verdict becomes
    the one that counts."""
    from .timedata_stage import time_data_causes

    try:
        timed = time_data_causes(recording, band_hz, base)
    except ValueError as exc:
        log.warning("time data not analysed: %s", exc)
        return diag
    if not timed:
        return diag
    present = [c for c in timed if c["present"]]
    counted = sorted((c for c in present if c.get("counts")), key=lambda c: -c.get("gain_db", 0.0))
    verdict = diag.verdict
    if verdict == "unexplained" and counted:
        verdict = counted[0]["effect"]
    elif verdict == "unexplained" and any(c["effect"] == "amplitude_nonlinearity" for c in present):
        verdict = "amplitude_nonlinearity"
    return replace(diag, verdict=verdict, time_data=timed,
                   time_data_verdict=counted[0]["effect"] if counted else "none")


def _level_stage(diag: Diagnosis, recording: str | Path, band_hz: tuple[float, float],
                 simulation: JointSimulationFactory | None) -> Diagnosis:
    """``diag`` with the recording's level dependence in the diagnosis band ``band_hz`` (Hz); a present
    ``joint_nonlinearity`` cause becomes the verdict and the named cause (the FRF comparison's verdict kept
    as ``linear_verdict``). Levels that cannot be compared (no mode to fit) leave ``diag`` as it is."""
    from ..errors import FitError
    from .joint_nonlinearity import level_dependence, named_joint

    try:
        levels = level_dependence(recording, band_hz, simulation)
    except (FitError, ValueError) as exc:
        log.warning("force levels not compared: %s", exc)
        return diag
    if levels is None:
        return diag
    cause = levels.get("cause") or {}
    if not cause.get("present"):
        return replace(diag, level_dependence=levels)
    return replace(diag, level_dependence=levels, linear_verdict=diag.verdict, verdict="joint_nonlinearity",
                   named=[named_joint(cause)])
