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
from .rule import DEFAULT_RULE, DecisionRule, step
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
    measured: FRFSet | str | Path | Sequence[FRFSet | str | Path],
    simulated: Any,
    *,
    band: tuple | str | None = None,
    effects: Sequence[str] | None = None,
    estimator: str | None = None,
    physical: Any = None,
    recording: str | Path | None = None,
    extra_noise_db: dict | None = None,
    joint_simulation: JointSimulationFactory | None = None,
    levels: Sequence[float] | None = None,
    measured_modes: Any = None,
    rule: DecisionRule = DEFAULT_RULE,
) -> Diagnosis:
    """Compare a measurement with a simulation and name what differs (``docs/diagnosis.md``).

    measured : FRF set, or a file (recording ``.h5`` or UFF 58) read with ``estimator``; with ``levels``
        a sequence of them.
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
    levels : one structure measured at several drive levels: ``measured`` is then a sequence (FRF sets or
        files), one per level (any positive unit: N, V...). The lowest level is compared with the simulation
        as above; the levels are compared with one another mode by mode
        (:func:`analysis.diagnosis.joint_nonlinearity.measured_levels`) and, when the modes move beyond their
        uncertainty, ``joint_nonlinearity`` (an amplitude-dependent stiffness and damping) becomes the verdict,
        with the per-mode shifts per level in ``level_dependence`` (the comparison's verdict kept as
        ``linear_verdict``).
    measured_modes : the measured modes for the physical stage
        (:class:`analysis.diagnosis.physical.MeasuredModes`); None: the automatic fit of the measurement.
    rule : the decision rule (:class:`analysis.diagnosis.rule.DecisionRule`): every threshold of every
        stage (FRF-level catalogue, physical causes, time data), one object; the result's ``trace`` lists
        the rules that decided, in order.

    Raises :class:`analysis.inputs.InputError` for unreadable or inconsistent input and
    :class:`analysis.diagnosis.EffectError` for unknown effects. Neither input is modified.

    Examples
    --------
    A simulation of two modes against a measurement (1 % noise) whose damping is twice the simulated:

    >>> import numpy as np
    >>> from dataclasses import replace
    >>> from analysis import ModalModel, synthesize
    >>> from analysis.diagnosis import diagnose
    >>> from analysis.modal import pole_from_fz
    >>> sim = ModalModel(pole_from_fz([40.0, 95.0], [0.01, 0.02]), [[[-20j, 50j]], [[30j, 25j]]],
    ...                  quantity="receptance", outputs=("a:1:X", "b:1:X"), references=("a:1:X",))
    >>> measured = synthesize(replace(sim, poles=pole_from_fz([40.0, 95.0], [0.02, 0.04])),
    ...                       np.arange(1.0, 200.0, 0.25))
    >>> noise = 1 + 0.01 * np.random.default_rng(0).standard_normal(measured.H.shape)
    >>> diag = diagnose(replace(measured, H=measured.H * noise), sim, effects=["damping_change", "stiffness_shift"])
    >>> diag.verdict, round(diag.causes[0]["parameters"]["factor"], 2)
    ('damping_change', 2.0)
    """
    from ..inputs import InputError, detect_format, load_input

    if levels is not None:
        return _diagnose_levels(measured, simulated, levels, band=band, effects=effects, estimator=estimator,
                                physical=physical, extra_noise_db=extra_noise_db, joint_simulation=joint_simulation,
                                measured_modes=measured_modes, rule=rule)
    if not isinstance(measured, (FRFSet, str, Path)):
        raise InputError(f"{len(measured)} measurements: give levels (one drive level each) to compare one "
                         "structure at several levels, or one measurement")
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
                             measured_modes=measured_modes, rule=rule)


def _diagnose_levels(measured: Any, simulated: Any, levels: Sequence[float], *, band: tuple | str | None,
                     **kw: Any) -> Diagnosis:
    """:func:`diagnose` of one structure measured at several drive ``levels`` (``measured``: one FRF set or
    file per level): the lowest level against the simulation, then the levels against one another in the
    diagnosis band; a present ``joint_nonlinearity`` becomes the verdict (the comparison's kept as
    ``linear_verdict``, its named causes after it)."""
    from ..inputs import InputError, load_input
    from .joint_nonlinearity import measured_levels, named_levels

    items = [measured] if isinstance(measured, (FRFSet, str, Path)) else list(measured)
    lv = [float(v) for v in levels]
    if len(items) < 2 or len(items) != len(lv):
        raise InputError(f"{len(items)} measurement(s) and {len(lv)} level(s): give at least two measurements of "
                         "one structure, one level each")
    if not all(np.isfinite(v) and v > 0 for v in lv) or len(set(lv)) < len(lv):
        raise InputError(f"levels {lv}: give one positive, different drive level per measurement")
    sets = [m if isinstance(m, FRFSet) else load_input(Path(m), estimator=kw.get("estimator")) for m in items]
    low = int(np.argmin(lv))
    diag = diagnose(items[low], simulated, band=band, **kw)          # a recording's hits feed its noise
    band_hz = (float(diag.measured.freq_hz[0]), float(diag.measured.freq_hz[-1]))
    found = measured_levels(sets, lv, band_hz)
    cause = found["cause"]
    values = {"levels": lv, **{k: v for k, v in cause.items() if isinstance(v, (int, float, str, bool))}}
    if not cause["present"]:
        trace = [*diag.trace, step("levels", None, values, "the modes do not move between the levels: verdict kept")]
        return replace(diag, level_dependence=found, trace=trace)
    trace = [*diag.trace, step("levels", "joint_nonlinearity", values,
                               f"verdict joint_nonlinearity (the comparison with the simulation said {diag.verdict})")]
    return replace(diag, level_dependence=found, linear_verdict=diag.verdict, verdict="joint_nonlinearity",
                   named=[named_levels(cause), *diag.named], trace=trace)


def _diagnose_set(measured: FRFSet, simulated: Any, *, band: tuple | str | None, effects: Sequence[str] | None,
                  estimator: str | None, physical: Any, recording: str | Path | None, extra_noise_db: dict | None,
                  joint_simulation: JointSimulationFactory | None, measured_modes: Any = None,
                  rule: DecisionRule = DEFAULT_RULE) -> Diagnosis:
    """:func:`diagnose` of a measurement read already (``recording``: the file when it is one)."""
    from ..bands import default_band
    from ..inputs import InputError, load_input
    from .compare import common_points

    sim_frfs: FRFSet | None = None
    user_band = (float(band[0]), float(band[1])) if band is not None and not isinstance(band, str) else None
    if _is_physical(simulated):
        physical, base = simulated, simulated.model(None, {})
    elif isinstance(simulated, ModalModel):
        base = simulated
    elif isinstance(simulated, (FRFSet, str, Path)):
        source = str(simulated) if not isinstance(simulated, FRFSet) else "the simulation"
        sim = simulated if isinstance(simulated, FRFSet) else load_input(Path(simulated), estimator=estimator)
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
    stray = None
    if recording is not None:
        from .compare import line_weights
        from .stray_hits import without_stray_hits

        # a hit that measured another FRF than the others of its point (struck elsewhere) is left out
        stray = without_stray_hits(recording, measured, line_weights(measured), rule)
        if stray is not None:
            measured = stray.measured
    if recording is not None and "hits" not in noise:
        from .hit_noise import hit_scatter_noise_db

        skip = {i for d in stray.dropped for i in d["hits"]} if stray is not None else set()
        noise["hits"] = hit_scatter_noise_db(recording, measured, line_weights(measured), skip=skip)
    if sim_frfs is not None:
        both = noise_with_simulated_frfs(measured, sim_frfs, noise)
        if both is not None:
            noise["simulation"] = both
    if physical is not None and user_band is not None and measured_modes is None:
        measured_modes = _measured_modes_in(measured, user_band)
    diag = diagnose_frfs(measured, base, effects=effects, physical=physical, extra_noise_db=noise,
                         measured_modes=measured_modes, rule=rule)
    if recording is None:
        return diag
    band_hz = (float(measured.freq_hz[0]), float(measured.freq_hz[-1]))
    diag = _time_data_stage(diag, recording, band_hz, base)
    if stray is not None:
        left_out = [{"reference": d["reference"], "hits": d["hits"], "excess_db": d["excess_db"]} for d in stray.dropped]
        trace = [step("stray_hits", "stray_hit", {"left_out": left_out, "stray_excess_db": rule.stray_excess_db},
                      "the hits left out before the comparison"), *diag.trace]
        diag = replace(diag, trace=trace, time_data=[stray.cause(), *diag.time_data],
                       time_data_verdict=diag.time_data_verdict if diag.time_data_verdict not in (None, "none")
                       else "stray_hit")
    return _level_stage(diag, recording, band_hz, joint_simulation)


def _measured_modes_in(measured: FRFSet, band: tuple[float, float]) -> Any:
    """The measured modes fitted in the user's ``band`` (Hz), so the fit's warnings name its edges, not
    those of a band from the data; None when the fit fails (the physical stage then says why)."""
    from ..errors import ImpactlabError
    from .physical_verdict import measure_modes

    try:
        return measure_modes(measured, band)
    except (ImpactlabError, ValueError, np.linalg.LinAlgError):
        return None


def _time_data_stage(diag: Diagnosis, recording: str | Path, band_hz: tuple[float, float],
                     base: ModalModel) -> Diagnosis:
    """``diag`` with the recording's time-data causes in ``band_hz`` (Hz), judged by ``diag.rule``; an
    ``unexplained`` verdict becomes the one that counts."""
    from .timedata_stage import time_data_causes

    try:
        timed = time_data_causes(recording, band_hz, base, diag.rule)
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
    trace = [*diag.trace, step("time_data", counted[0]["effect"] if counted else None,
                               {"present": [c["effect"] for c in present], "counted": [c["effect"] for c in counted],
                                "frf_verdict": diag.verdict},
                               f"verdict {verdict}" if verdict != diag.verdict else "verdict kept")]
    return replace(diag, verdict=verdict, time_data=timed, trace=trace,
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
    trace = [*diag.trace, step("joint_nonlinearity", "joint_nonlinearity",
                               {k: v for k, v in cause.items() if isinstance(v, (int, float, str, bool))},
                               f"verdict joint_nonlinearity (the FRF comparison said {diag.verdict})")]
    return replace(diag, level_dependence=levels, linear_verdict=diag.verdict, verdict="joint_nonlinearity",
                   named=[named_joint(cause)], trace=trace)
