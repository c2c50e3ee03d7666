"""The catalogue of physical effects: model extensions with physical parameters.

Each effect is a small pure function pair over plain containers:

* ``apply``: the effect on the simulation. Effects of kind ``"modal"`` act on the
  :class:`analysis.modal.ModalModel` before synthesis (pole and residue changes); effects of
  kind ``"frf"`` act on the synthesised :class:`analysis.frf.FRFSet` (factors or added terms).
* ``fit``: the effect's parameters fitted to measured FRFs by weighted least squares,
  ``S(theta) = sum_{o,r,k in lines} w_ork |H_meas - H_ext(theta)|^2``, on a subset of lines
  (so that a verdict can score them on other lines; see :mod:`analysis.diagnosis.verdict`).

Effects and parameters (SI units; ``omega = 2 pi f`` rad/s; ``p`` = 0, 1, 2 for receptance,
mobility, accelerance of the model):

=======================  =====  ==============================================================
name                     kind   model extension
=======================  =====  ==============================================================
``stiffness_shift``      modal  every natural frequency times ``factor`` (stiffness times
                                factor^2), damping ratios kept; residues times factor^(p-1)
``damping_change``       modal  every damping ratio times ``factor``
``exponential_window``   modal  an exponential window ``exp(-t/exp_window_tau_s)`` on the measured impulse
                                response: ``H_q,w(w) = H_q(j w + 1/exp_window_tau_s)`` exactly, in the
                                measured quantity q (see :func:`synthesize_windowed`)
``mass_loading``         modal  a mass ``mass_kg`` at each output sensor: omega_r^2 / (1 + mu_r),
                                ``mu_r = m sum_o phi_or^2`` (mass-normalised shapes at the
                                outputs, first-order Rayleigh quotient), residues / sqrt(1+mu)^(1+p)
``local_resonator``      modal  a spring-mass ``frequency_hz``, ``zeta`` attached through ``coupling``
                                (``sqrt(m) phi_r`` at its point, per mode) or at output ``point`` with
                                ``mass_kg``: re-analysed with the modes (:mod:`.resonator`)
``missing_mode``         modal  an extra mode ``freq_hz``, ``zeta``, complex ``residue[o][r]``
                                (``[re, im]`` pairs, model units x rad/s)
``residual_modes``       frf    ``H += UR (j w)^q + LR (j w)^q / w^2`` (q of the FRF): the modes
                                outside the band; ``upper`` m/N, ``lower`` m/N (rad/s)^2
``sensor_highpass``      frf    ``H *= (j w / w_c / (1 + j w / w_c))^order``, ``corner_hz``
``time_delay``           frf    ``H *= exp(-j w delay_s)``
``sensitivity_error``    frf    ``H[o] *= gains[o]`` (a wrong calibration of output channel o)
``mains_hum``            frf    ``H += sum_k A_ok / (1 + j (f - k f0) / width_hz)``, lines at the
                                harmonics of ``base_hz`` (50 or 60 Hz); ``harmonics_hz`` those of
                                the band it was fitted on
=======================  =====  ==============================================================

Modules: :mod:`.effect_types` (``Effect``, ``FitContext``, ``EffectError``, shared fit helpers),
:mod:`.processing` (the exponential window and the finite record: exact synthesis as measured),
:mod:`.mains` (mains lines and their cross-validation by harmonics), :mod:`.frf_effects` (residual
terms, sensor high-pass, time delay, sensitivity), :mod:`.resonator` (a spring-mass at a point) and
:mod:`.resonator_search` (its fit: the starts and the refinement); this module holds the modal effects,
the registry and :func:`predict`.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace

import numpy as np
from scipy.linalg.lapack import dsygvd
from scipy.optimize import least_squares

from ..frf import QUANTITY_POWER, FRFSet, convert_quantity
from ..modal import ModalModel, pole_from_fz
from .effect_types import Effect, EffectError, FitContext, ParamRange, mode_residuals, shapes_at_references, split
from .effect_types import check_positive as _check_positive
from .effect_types import fit_scalar as _fit_scalar
from .frf_effects import (
    MAX_GAIN_ERROR,
    apply_residual_modes,
    apply_sensitivity_error,
    apply_sensor_highpass,
    apply_time_delay,
    fit_residual_modes,
    fit_sensitivity_error,
    fit_sensor_highpass,
    fit_time_delay,
)
from .mains import apply_mains_hum, default_hum_width, fit_mains_hum, held_out_mains_hum, hum_kernels, mains_hum_applies
from .mass_frf import FRF_MASSES_KEY, FRFMassLoading, add_frf_masses, frf_masses_kg, uses_frf_masses
from .processing import (
    RECORD_KEY,
    WINDOW_SHIFT_KEY,
    apply_exponential_window,
    apply_record_length,
    synthesize_windowed,
    truncation_tail,
    windowed_transfer,
)
from .resonator import apply_local_resonator
from .resonator_search import RESONATOR_BEYOND_BAND, Catalogue, search_resonator

__all__ = [
    "Effect",
    "EFFECTS",
    "PROCESSING",
    "EffectError",
    "FitContext",
    "predict",
    "effect_names",
    "synthesize_windowed",
    "truncation_tail",
    "apply_record_length",
    "apply_exponential_window",
    "hum_kernels",
    "default_hum_width",
    "held_out_mains_hum",
    "WINDOW_SHIFT_KEY",
    "RECORD_KEY",
    "CATALOGUE",
    "fit_local_resonator",
]

_POWER = QUANTITY_POWER


def _model_power(model: ModalModel) -> int:
    return _POWER[model.quantity]


def _replace_poles(model: ModalModel, poles: np.ndarray, scale: np.ndarray) -> ModalModel:
    """Model with new poles and residues scaled per mode (scale shape (n_modes,))."""
    return replace(model, poles=np.asarray(poles, complex), residues=model.residues * scale[None, None, :])


COARSE_LINES = 600


def _thinned(lines: np.ndarray) -> np.ndarray:
    """Every ``k``-th of the boolean mask ``lines``, at most :data:`COARSE_LINES` of them."""
    idx = np.flatnonzero(lines)
    stride = max(1, int(np.ceil(idx.size / COARSE_LINES)))
    out = np.zeros_like(lines)
    out[idx[::stride]] = True
    return out


def _modal_cost(ctx: FitContext, lines: np.ndarray, effect: str, coarse: bool = False) -> Callable[[dict], float]:
    """Cost of a modal effect's parameters on ``lines``. The model is synthesised at those lines only.
    With ``coarse=True`` (fast grid searches; the final refinement is exact): for effects that move
    every mode alike (stiffness, mass) every ``k``-th line is used (at most ``COARSE_LINES``); for the
    others the modes far outside the band (below f_lo/1.5, above 1.5 f_hi) are a fixed background
    taken from the base model (damping and window changes leave their quasi-static part alone)."""
    if coarse and EFFECTS[effect].moves_every_mode:
        # these effects change the quasi-static part of the modes far outside the band too: keep every
        # mode, thin the lines instead (at most COARSE_LINES)
        lines, coarse = _thinned(lines), False
    f = ctx.measured.freq_hz[lines]
    Hm, W = ctx.measured.H[..., lines], ctx.weights[..., lines]
    base = ctx.base
    background: float | np.ndarray = 0.0
    if coarse:
        near = (base.freq_hz >= f[0] / 1.5) & (base.freq_hz <= f[-1] * 1.5)
        if near.any() and not near.all():
            far_meta = {k: v for k, v in base.meta.items() if k != "frf_correction"}
            if "output_shapes" in far_meta:
                far_meta["output_shapes"] = np.asarray(far_meta["output_shapes"])[:, ~near]
            far = replace(base, poles=base.poles[~near], residues=base.residues[..., ~near], meta=far_meta,
                          upper_residual=None, lower_residual=None)
            prior_modal = [e for e in ctx.prior if _lookup(e)[0].kind == "modal"]
            background = predict(far, f, ctx.measured.quantity, prior_modal).H
            meta = dict(base.meta)
            if "output_shapes" in meta:
                meta["output_shapes"] = np.asarray(meta["output_shapes"])[:, near]
            base = replace(base, poles=base.poles[near], residues=base.residues[..., near], meta=meta)

    def cost(params: dict) -> float:
        H = predict(base, f, ctx.measured.quantity, ctx.effects({"effect": effect, **params})).H + background
        e = Hm - H
        return float(np.sum(W * (e.real ** 2 + e.imag ** 2)))
    return cost


def _summed_log_magnitude(H: np.ndarray) -> np.ndarray:
    return np.log(np.sum(np.abs(H), axis=(0, 1)) + 1e-300)


def _log_shift_candidates(ctx: FitContext, lines: np.ndarray, max_ratio: float = 1.25, n: int = 3) -> list[float]:
    """Frequency ratios that best align the measured and simulated peaks: the ``n`` best local maxima
    of the cross-correlation of the summed log-magnitudes on a log-frequency axis."""
    f = ctx.measured.freq_hz
    sel = lines & (f > 0)
    fl = f[sel]
    npts = 4096
    u = np.linspace(np.log(fl[0]), np.log(fl[-1]), npts)
    a = np.interp(u, np.log(fl), _summed_log_magnitude(ctx.measured.H[..., sel]))
    b = np.interp(u, np.log(fl), _summed_log_magnitude(ctx.sim.H[..., sel]))
    du = u[1] - u[0]
    # keep the peaks, drop the trend (mass and stiffness lines): subtract a 10 % moving average
    k = max(3, int(np.log(1.1) / du) | 1)
    kern = np.ones(k) / k
    a = a - np.convolve(np.pad(a, k // 2, mode="edge"), kern, mode="valid")
    b = b - np.convolve(np.pad(b, k // 2, mode="edge"), kern, mode="valid")
    max_lag = int(np.ceil(np.log(max_ratio) / du))
    lags = np.arange(-max_lag, max_lag + 1)
    score = np.array([np.dot(a[max(0, L):npts + min(0, L)], b[max(0, -L):npts - max(0, L)]) / (npts - abs(L))
                      for L in lags.tolist()])
    peaks = [i for i in range(1, score.size - 1) if score[i] >= score[i - 1] and score[i] >= score[i + 1]]
    peaks = sorted(peaks, key=lambda i: score[i], reverse=True)[:n] or [int(np.argmax(score))]
    return [float(np.exp(lags[i] * du)) for i in peaks]


# --------------------------------------------------------------------------- modal effects
def apply_stiffness_shift(model: ModalModel, params: Mapping) -> ModalModel:
    """All natural frequencies times ``factor`` (stiffness times factor^2), damping ratios kept."""
    a = _check_positive("factor", params.get("factor"), "stiffness_shift")
    p = _model_power(model)
    out = _replace_poles(model, model.poles * a, np.full(model.poles.size, a ** (p - 1)))
    if out.upper_residual is not None:
        out = replace(out, upper_residual=out.upper_residual / a ** 2)
    # a fixed FRF term (meta["frf_correction"]) is warped alike: H_q'(f) = a^(q-2) H_q(f / a)
    meta = dict(out.meta)
    meta["frequency_warp"] = float(meta.get("frequency_warp", 1.0)) * a
    return replace(out, meta=meta)


def fit_stiffness_shift(ctx: FitContext, lines: np.ndarray) -> dict:
    coarse = _modal_cost(ctx, lines, "stiffness_shift", coarse=True)
    cost = _modal_cost(ctx, lines, "stiffness_shift")
    grid = np.unique(np.concatenate([a0 * np.exp(np.linspace(-0.008, 0.008, 17))
                                     for a0 in _log_shift_candidates(ctx, lines, n=6) + [1.0]]))
    vals = [coarse({"factor": x}) for x in grid]
    i = int(np.argmin(vals))
    a = _fit_scalar(lambda x: cost({"factor": x}), grid[max(i - 1, 0):i + 2])
    return {"factor": a, "stiffness_factor": a ** 2}


def apply_damping_change(model: ModalModel, params: Mapping) -> ModalModel:
    """Every damping ratio times ``factor`` (natural frequencies kept)."""
    c = _check_positive("factor", params.get("factor"), "damping_change")
    wn = np.abs(model.poles)
    z = np.clip(-model.poles.real / wn * c, 0.0, 0.99)
    new = -z * wn + 1j * wn * np.sqrt(1 - z ** 2)
    return _replace_poles(model, new, model.poles.imag / new.imag)


#: The damping factors searched (a fit at an end wants more than a damping change can physically be).
DAMPING_RANGE = (0.1, 10.0)


def fit_damping_change(ctx: FitContext, lines: np.ndarray) -> dict:
    coarse = _modal_cost(ctx, lines, "damping_change", coarse=True)
    cost = _modal_cost(ctx, lines, "damping_change")
    grid = np.linspace(np.log(DAMPING_RANGE[0]), np.log(DAMPING_RANGE[1]), 47)
    i = int(np.argmin([coarse({"factor": float(np.exp(x))}) for x in grid]))
    g = _fit_scalar(lambda x: cost({"factor": float(np.exp(x))}), grid[max(i - 1, 0):i + 2])
    return {"factor": float(np.exp(g))}


def fit_exponential_window(ctx: FitContext, lines: np.ndarray) -> dict:
    coarse = _modal_cost(ctx, lines, "exponential_window", coarse=True)
    cost = _modal_cost(ctx, lines, "exponential_window")
    f = ctx.measured.freq_hz[lines]
    # pole shift (1/tau) up to 5 % damping of the lowest simulated mode in the band (or of f_max / 10)
    fn = ctx.base.freq_hz
    inband = fn[(fn >= f[0]) & (fn <= f[-1])]
    f1 = float(inband.min()) if inband.size else f[-1] / 10
    smax = 2 * np.pi * f1 * 0.05
    grid = np.linspace(0.0, smax, 61)
    i = int(np.argmin([coarse({"exp_window_tau_s": 1.0 / max(x, 1e-9)}) for x in grid]))
    s = _fit_scalar(lambda x: cost({"exp_window_tau_s": 1.0 / max(x, 1e-9)}), grid[max(i - 1, 0):i + 2])
    s = max(s, 1e-9)
    return {"exp_window_tau_s": 1.0 / s, "exp_window_pole_shift_per_s": s}


def _mass_sensors(model: ModalModel, sensor: object) -> np.ndarray:
    """Boolean mask of the outputs that carry the mass: every output for ``"all"`` (or None), else the
    output labelled ``sensor``."""
    if sensor is None or sensor == "all":
        return np.ones(len(model.outputs), bool)
    if sensor not in model.outputs:
        raise EffectError(f"mass_loading: sensor {sensor!r} is not one of the outputs {list(model.outputs)}; "
                          "give an output label or 'all'")
    return np.asarray([o == sensor for o in model.outputs])



def _loaded_modes(wn: np.ndarray, loaded: np.ndarray, masses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``K_r V = M_r V diag(w2)`` for ``K_r = diag(wn^2)`` (``wn`` rad/s) and ``M_r = I + m L^T L`` (``L`` the loaded
    outputs' shapes), for every mass m of ``masses`` (kg, shape (G,)) at once: w2 (G, n) ascending (rad/s)^2 and
    V (G, n, n) M_r-normalised (``V^T M_r V = I``). LAPACK's divide-and-conquer generalized solver (``dsygvd``,
    what :func:`scipy.linalg.eigh` calls for these, without its checks per mass) on each mass in turn."""
    n = wn.size
    Mr = np.eye(n)[None] + (np.asarray(masses, float)[:, None, None] * loaded.T[None]) @ loaded[None]
    K = np.diag(np.asarray(wn, float) ** 2)
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(Mr))):
        raise ValueError("mass_loading: the modes or the mass are not finite numbers")
    # each mass's vectors in LAPACK's (column-major) layout, as scipy's stacked eigh returns them: the products
    # that follow then run the same BLAS kernels
    w2, V = np.empty((Mr.shape[0], n)), np.empty(Mr.shape).transpose(0, 2, 1)
    for i, M in enumerate(Mr):
        w2[i], V[i], info = dsygvd(K, M, itype=1, jobz="V", uplo="L")
        if info != 0:
            raise np.linalg.LinAlgError(f"mass_loading: the loaded modes' eigenproblem failed (LAPACK info {info})")
    return w2, V


def _mass_loaded(model: ModalModel, mask: np.ndarray, masses: np.ndarray) -> list[ModalModel]:
    """``model`` with the mass m at the outputs ``mask``, for every m of ``masses`` (kg): the re-analysed modes
    of :func:`apply_mass_loading` (its docstring), the eigenproblems of all masses solved together."""
    poles, residues = _mass_loaded_modes(model, mask, masses)
    return [replace(model, poles=poles[i], residues=residues[i]) for i in range(poles.shape[0])]


def _mass_loaded_modes(model: ModalModel, mask: np.ndarray, masses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The poles (G, n) and residues (G, n_out, n_ref, n) of :func:`_mass_loaded`'s models, G = ``masses.size``."""
    masses = np.asarray(masses, float)
    phi = np.asarray(model.meta["output_shapes"], float)
    loaded = phi[mask]
    lam = np.asarray(model.poles, complex)
    wn, z = np.abs(lam), -lam.real / np.abs(lam)
    order = np.argsort(wn)
    w2, V = _loaded_modes(wn, loaded, masses)
    Vk = np.empty_like(V)
    Vk[:, :, order] = V                                 # new mode i is the i-th lowest old mode
    Vk *= np.where(np.diagonal(Vk, axis1=1, axis2=2) < 0, -1.0, 1.0)[:, None, :]
    wn_new = np.empty_like(wn, shape=w2.shape)
    wn_new[:, order] = np.sqrt(np.maximum(w2, 0.0))
    new = wn_new * (-z + 1j * np.sqrt(1 - z ** 2))[None, :]
    p = _model_power(model)
    d = np.diagonal(Vk, axis1=1, axis2=2)
    R = np.asarray(model.residues, complex)[None] / lam[None, None, None, :] ** p \
        * (d ** 2 * lam.imag[None, :] / new.imag)[:, None, None, :]
    ref = shapes_at_references(model, phi)
    if ref is not None:
        po, pr = phi[None] @ Vk, ref[None] @ Vk
        coupled = (po[:, :, None, :] * pr[:, None, :, :]
                   - (d ** 2)[:, None, None, :] * phi[None, :, None, :] * ref[None, None, :, :])
        R = R + np.where((masses > 0)[:, None, None, None], coupled / (2j * new.imag)[:, None, None, :], 0.0)
    return new, R * new[:, None, None, :] ** p


def apply_mass_loading(model: ModalModel, params: Mapping) -> ModalModel:
    """A mass ``mass_kg`` (kg) at each output sensor, or at the one output ``sensor`` (a label; ``"all"``
    or absent: every output). Needs ``model.meta["output_shapes"]``, the mass-normalised mode shapes
    (1/sqrt(kg)) at the outputs, shape (n_out, n_modes).

    The modes are re-analysed in the model's own modal space: ``K_r = diag(omega_r^2)``,
    ``M_r = I + m Phi_S^T Phi_S`` (S the loaded outputs), ``K_r V = M_r V Omega'^2`` (V M_r-normalised),
    so that the mass couples the modes (to first order this is ``omega_r^2 / (1 + m sum_S phi_r^2)``,
    the Rayleigh quotient; the coupling matters when a heavy sensor sits where neighbouring modes are
    both large). Each mode keeps its damping ratio; its receptance residue becomes
    ``R_r V_rr^2 w_d / w_d' + [(Phi_o V)_r (Phi_ref V)_r - V_rr^2 phi_or phi_ref,r] / (2 j w_d')`` (the fitted
    residue kept where the shapes cannot say more; the coupled part from the shapes, at the references
    from ``meta["reference_shapes"]`` or the outputs' rows; without them the coupled part is left out).

    A simulation given as FRFs (``meta["frf_correction"]``, with a driving point) keeps its modes: the mass
    is recorded in ``meta`` and added to its predicted FRFs by :func:`predict`, which moves the fixed part of
    those FRFs with the modes (:mod:`.mass_frf`)."""
    m = float(params.get("mass_kg", 0.0))
    if not m >= 0:
        raise EffectError(f"mass_loading: mass_kg must be >= 0 (kg), got {m!r}")
    shapes = model.meta.get("output_shapes")
    if shapes is None:
        raise EffectError("mass_loading needs the mode shapes at the outputs (model.meta['output_shapes']); "
                          "simulate from a frame configuration (TOML) instead of an FRF file")
    mask = _mass_sensors(model, params.get("sensor"))
    if uses_frf_masses(model):
        meta = dict(model.meta)
        meta[FRF_MASSES_KEY] = tuple(meta.get(FRF_MASSES_KEY, ())) + ((m, mask),)
        return replace(model, meta=meta)
    return _mass_loaded(model, mask, np.array([m]))[0]


def _mass_grid_costs(ctx: FitContext, lines: np.ndarray, place: str, grid: np.ndarray) -> np.ndarray:
    """The coarse cost (:func:`_modal_cost`, thinned lines) of the mass ``grid`` (kg) at ``place``: the loaded
    modes of the whole grid solved at once (:func:`_mass_loaded`) on the model with the modal effects accepted
    before, each then predicted with the FRF effects accepted before (the order :func:`predict` applies them
    in). A mass added to an FRF-file simulation's FRFs (:mod:`.mass_frf`): the prediction without the masses
    and the receptances between the outputs are computed once for the grid, only the masses change."""
    model, frf_prior = ctx.base, []
    for e in ctx.prior:
        eff, params = _lookup(e)
        if eff.kind == "modal":
            model = eff.apply(model, params)
        else:
            frf_prior.append(dict(e))
    sel = _thinned(lines)
    f, Hm, W = ctx.measured.freq_hz[sel], ctx.measured.H[..., sel], ctx.weights[..., sel]
    mask = _mass_sensors(model, place)
    if uses_frf_masses(model):
        # predict's order: the modal model with its fixed part, the masses, then the FRF effects
        bare = replace(model, meta={k: v for k, v in model.meta.items() if k != FRF_MASSES_KEY})
        loading = FRFMassLoading(bare, predict(bare, f, ctx.measured.quantity))
        prior_kg, mask_kg = frf_masses_kg(model), np.asarray(mask, float)
        loaded_H = loading.loaded_H(prior_kg[None, :] + np.asarray(grid, float)[:, None] * mask_kg[None, :])
        predicted = (_frf_effects(replace(loading.frf, H=H), frf_prior).H for H in loaded_H)
    else:
        # the loaded models' FRFs of the whole grid in one synthesis, as predict gives each
        poles, residues = _mass_loaded_modes(model, mask, grid)
        loaded = _synthesised(model, f, ctx.measured.quantity, model.meta.get("frf_correction"), poles, residues)
        predicted = (_frf_effects(FRFSet(freq_hz=f, H=H, quantity=ctx.measured.quantity, outputs=model.outputs,
                                         references=model.references), frf_prior).H if frf_prior else H
                     for H in loaded)
    vals = []
    for H in predicted:
        e = Hm - H
        vals.append(float(np.sum(W * (e.real ** 2 + e.imag ** 2))))
    return np.array(vals)


def fit_mass_loading(ctx: FitContext, lines: np.ndarray) -> dict:
    """The mass at every output (``sensor`` ``"all"``) or at one output (its label): each placement is
    searched on a grid of the mass (0.1 % frequency steps of its most loaded in-band mode, up to 30 %),
    the two best are refined; the placement with the smaller cost on ``lines`` wins."""
    cost = _modal_cost(ctx, lines, "mass_loading")
    phi = np.asarray(ctx.base.meta["output_shapes"], float)
    f = ctx.measured.freq_hz[lines]
    inband = (ctx.base.freq_hz >= f[0]) & (ctx.base.freq_hz <= f[-1])
    places: list[str] = ["all"] + (list(ctx.base.outputs) if len(ctx.base.outputs) > 1 else [])
    screened = []
    for place in places:
        load = np.sum(phi[_mass_sensors(ctx.base, place)] ** 2, axis=0)
        smax = float(np.max(load[inband])) if inband.any() else float(np.max(load))
        if not smax > 0:
            continue
        grid = np.arange(0.0, 0.7 / smax + 0.002 / smax, 0.002 / smax)
        vals = _mass_grid_costs(ctx, lines, place, grid)
        i = int(np.argmin(vals))
        screened.append((float(vals[i]), place, grid[max(i - 1, 0):i + 2]))
    if not screened:
        raise EffectError("mass_loading: no mode is seen at the outputs (all shapes zero)")
    best: tuple[float, str, float] | None = None
    for _, place, bracket in sorted(screened, key=lambda t: t[0])[:2]:
        def placed(x: float, pl: str = place) -> float:
            return cost({"mass_kg": max(x, 0.0), "sensor": pl})
        m = max(_fit_scalar(placed, bracket), 0.0)
        c = placed(m)
        if best is None or c < best[0]:
            best = (c, place, m)
    assert best is not None
    return {"mass_kg": best[2], "sensor": best[1]}


def apply_missing_mode(model: ModalModel, params: Mapping) -> ModalModel:
    """Add one mode: ``freq_hz`` (Hz), ``zeta``, ``residue`` [[ [re, im] per reference ] per output]."""
    f = _check_positive("freq_hz", params.get("freq_hz"), "missing_mode")
    z = float(params.get("zeta", 0.01))
    if not 0 < z < 1:
        raise EffectError(f"missing_mode: zeta must be in (0, 1), got {z!r}")
    R = np.asarray(params.get("residue"), float)
    shape = model.residues.shape[:2] + (2,)
    if R.shape != shape:
        raise EffectError(f"missing_mode: residue must be [re, im] pairs of shape {shape}, got {R.shape}")
    Rc = (R[..., 0] + 1j * R[..., 1])[..., None]
    return replace(model, poles=np.append(model.poles, pole_from_fz(f, z)),
                   residues=np.concatenate([model.residues, Rc], axis=2))


def fit_missing_mode(ctx: FitContext, lines: np.ndarray) -> dict:
    """The extra mode's frequency, damping and residues on ``lines`` (:func:`_fit_missing_mode`), fitted once per
    context and lines: the local resonator's search starts from the same fit (:mod:`.resonator_search`)."""
    key = ("missing_mode", np.asarray(lines).dtype.str, np.shape(lines), np.asarray(lines).tobytes())
    return ctx.remembered(key, lambda: _fit_missing_mode(ctx, lines))


def _fit_missing_mode(ctx: FitContext, lines: np.ndarray) -> dict:
    f = ctx.measured.freq_hz
    E = ctx.measured.H - ctx.sim.H
    power = np.sum(ctx.weights * np.abs(E) ** 2, axis=(0, 1))
    df = ctx.measured.line_spacing_hz
    # a resonance just past a band edge still shows inside the band: allow 5 % beyond the edges
    lo, hi = f[lines][0] / 1.05, f[lines][-1] * 1.05
    # candidates: the largest local maxima of the weighted residual power (all lines, smoothed) within the
    # frequencies the fit may take (a peak beyond them cannot start it)
    sm = np.convolve(power, np.ones(3) / 3, mode="same")
    order = [k for k in np.argsort(sm)[::-1] if lo <= f[k] <= hi]
    cands: list[float] = []
    for k in order:
        if len(cands) >= 3:
            break
        if all(abs(f[k] - c) > 10 * df for c in cands):
            cands.append(float(f[k]))
    best: tuple[float, float, float, np.ndarray] | None = None
    for fc in cands:
        zs = [(float(np.sum(mode_residuals(ctx, lines, np.array([fc, z]))[0] ** 2)), z)
              for z in (0.002, 0.005, 0.01, 0.02, 0.05)]
        z0 = min(zs)[1]
        res = least_squares(lambda x: mode_residuals(ctx, lines, np.array([x[0], np.exp(x[1])]))[0],
                            np.array([fc, np.log(z0)]), bounds=([lo, np.log(1e-4)], [hi, np.log(0.3)]),
                            x_scale=[df, 0.3], method="trf", max_nfev=100)
        r, R = mode_residuals(ctx, lines, np.array([res.x[0], np.exp(res.x[1])]))
        c = float(np.sum(r ** 2))
        if best is None or c < best[0]:
            best = (c, float(res.x[0]), float(np.exp(res.x[1])), R)
    if best is None:
        raise EffectError("missing_mode: no candidate frequency in the band")
    _, fm, zm, R = best
    return {"freq_hz": fm, "zeta": zm, "residue": R.tolist()}


# --------------------------------------------------------------------------- registry
def fit_local_resonator(ctx: FitContext, lines: np.ndarray) -> dict:
    """The local resonator's fit: :func:`.resonator_search.search_resonator` over this catalogue."""
    return search_resonator(ctx, lines, CATALOGUE)


EFFECTS: dict[str, Effect] = {e.name: e for e in (
    Effect("residual_modes", "frf", apply_residual_modes, fit_residual_modes, "upper",
           "modes outside the band (upper and lower residual terms)",
           advice='Add upper/lower residual terms (modes outside the band) to the model, or widen the '
                  'simulated mode set; the in-band modes are fine.'),
    Effect("sensor_highpass", "frf", apply_sensor_highpass, fit_sensor_highpass, "corner_hz",
           "AC coupling / IEPE / piezo low-frequency roll-off of the response sensor",
           advice='The response sensor rolls off at low frequency (AC coupling / IEPE / piezo): start the '
                  'analysis band well above the corner, use DC coupling, or model the roll-off.'),
    Effect("time_delay", "frf", apply_time_delay, fit_time_delay, "delay_s",
           "a delay between force and response channels (e.g. different anti-alias filters)",
           advice='Force and response channels are delayed against each other (different anti-alias filters '
                  'or sample skew): use matched channels or correct the phase by exp(j w delay).'),
    Effect("mass_loading", "modal", apply_mass_loading, fit_mass_loading, "mass_kg",
           "the accelerometers' mass lowers the frequencies in proportion to the mode shape at their points",
           needs=("output_shapes",), moves_every_mode=True, covered_by_physical="always", on_top_of_physical=False,
           advice="The accelerometers' mass lowers the frequencies: add the sensor masses at their nodes in "
                  'the model, or use lighter sensors.'),
    Effect("local_resonator", "modal", apply_local_resonator, fit_local_resonator, "frequency_hz",
           "a spring-mass attached at a point: a mode more, and the neighbouring modes shifted by it",
           needs=("output_shapes",),
           ranges=(ParamRange("frequency_hz", 1 / RESONATOR_BEYOND_BAND, RESONATOR_BEYOND_BAND,
                              "the resonator's own frequency", band_relative=True),),
           advice="A local resonator (a spring-mass at one point: an absorber, a component on a soft mount, a "
                  "loose part) adds a mode near the fitted frequency and shifts its neighbours: add it to the "
                  "model; the largest coupling names the modes it sits on."),
    Effect("missing_mode", "modal", apply_missing_mode, fit_missing_mode, "freq_hz",
           "a mode the simulation lacks", on_top_of_physical=False,
           advice="The structure has a mode the model lacks: check the model's mode set (a component, a "
                  'local mode, a support or joint degree of freedom) near the fitted frequency.'),
    Effect("stiffness_shift", "modal", apply_stiffness_shift, fit_stiffness_shift, "factor",
           "all natural frequencies scaled alike (stiffness or material off)",
           moves_every_mode=True, covered_by_physical="when_fitted", on_top_of_physical=False,
           advice='All frequencies are off by the same factor: update the material stiffness or the section '
                  'properties (stiffness scales by the square of the fitted factor).'),
    Effect("damping_change", "modal", apply_damping_change, fit_damping_change, "factor",
           "all damping ratios scaled alike",
           ranges=(ParamRange("factor", *DAMPING_RANGE, "the damping factor"),),
           advice="The damping ratios are off by a common factor: update the model's damping."),
    Effect("exponential_window", "modal", apply_exponential_window, fit_exponential_window, "exp_window_tau_s",
           "an exponential window added decay 1/tau to every mode",
           advice='An exponential window added damping sigma = 1/tau: correct the fitted damping (or record '
                  'exp_window_tau_s with the FRFs).'),
    Effect("sensitivity_error", "frf", apply_sensitivity_error, fit_sensitivity_error, "gain",
           "a channel's calibration (sensitivity) is wrong",
           ranges=(ParamRange("gains", 1 / MAX_GAIN_ERROR, MAX_GAIN_ERROR, "a channel's gain", rtol=1e-9),),
           advice="A channel's calibration is wrong: recalibrate or correct the sensitivity of the named "
                  'channel by the fitted gain.'),
    Effect("mains_hum", "frf", apply_mains_hum, fit_mains_hum, "base_hz",
           "lines at the mains frequency (50/60 Hz) and its harmonics", held_out=held_out_mains_hum,
           applies=mains_hum_applies,
           advice='Mains hum at the named base frequency and harmonics: check grounding and cable routing; '
                  'ignore those lines in fits.'),
)}


def effect_names() -> tuple[str, ...]:
    """Names of the catalogue, in its order."""
    return tuple(EFFECTS)


#: Known processing of a measurement (applied to the simulation before it is compared, never fitted as a cause).
PROCESSING: dict[str, Effect] = {e.name: e for e in (
    Effect("record_length", "modal", apply_record_length, lambda ctx, lines: {}, "record_s",
           "the finite record: the response is seen for record_s - pretrigger_s after the pulse"),
)}


def _lookup(spec: Mapping) -> tuple[Effect, dict]:
    if not isinstance(spec, Mapping) or "effect" not in spec:
        raise EffectError(f"an effect is a dict {{'effect': NAME, ...parameters}}; got {spec!r}")
    name, params = split(spec)
    if name in PROCESSING:
        return PROCESSING[name], params
    if name not in EFFECTS:
        raise EffectError(f"unknown effect {name!r}; the catalogue has {', '.join(EFFECTS)}")
    return EFFECTS[name], params


def _correction(corr: FRFSet, freq_hz: np.ndarray, quantity: str, warp: float = 1.0) -> np.ndarray:
    """A fixed FRF term (``base.meta["frf_correction"]``) at ``freq_hz`` in ``quantity``.

    With a stiffness warp ``a`` (all frequencies times a) the term is ``a^(q-2) H_q(f / a)`` in its
    own form q, exact for any sum of modes and residual terms. Between its lines the real and imaginary
    parts are interpolated linearly (edge values held outside)."""
    f = np.asarray(freq_hz, float)
    fe = f / warp
    if corr.freq_hz.size == f.size and np.allclose(corr.freq_hz, fe):
        H = corr.H.copy()
    else:
        H = np.zeros((corr.H.shape[0], corr.H.shape[1], f.size), complex)
        for o in range(H.shape[0]):
            for r in range(H.shape[1]):
                H[o, r] = np.interp(fe, corr.freq_hz, corr.H[o, r].real) + 1j * np.interp(fe, corr.freq_hz, corr.H[o, r].imag)
    H = H * warp ** (_POWER[corr.quantity] - 2)
    return convert_quantity(H, f, corr.quantity, quantity) if corr.quantity != quantity else H


def _synthesised(model: ModalModel, freq_hz: np.ndarray, quantity: str, corr: FRFSet | None,
                 poles: np.ndarray | None = None, residues: np.ndarray | None = None) -> np.ndarray:
    """The FRFs of ``model`` (:func:`windowed_transfer`; with ``poles`` and ``residues`` its variants with those
    modes, leading axes first) plus the fixed FRF term ``corr`` (a base's ``meta["frf_correction"]``, warped by
    the model's stiffness), at ``freq_hz`` (Hz) in ``quantity``."""
    H = windowed_transfer(model, freq_hz, quantity, poles=poles, residues=residues)
    if corr is not None:
        H = H + _correction(corr, freq_hz, quantity, float(model.meta.get("frequency_warp", 1.0)))
    return H


def predict(
    base: ModalModel,
    freq_hz: np.ndarray,
    quantity: str,
    effects: Sequence[Mapping] = (),
    *,
    outputs: Sequence[str] | None = None,
    references: Sequence[str] | None = None,
) -> FRFSet:
    """The simulation extended by ``effects`` (list of ``{"effect": name, **params}``) at ``freq_hz``
    (Hz) in ``quantity``: modal effects change the model, then it is synthesised (eq. 11), converted to
    ``quantity`` and the FRF effects are applied, each in list order. Inputs are not modified.
    An ``exponential_window`` is exact in the measured ``quantity`` (:func:`synthesize_windowed`),
    whatever the model's form, and acts on the structure after the other modal effects.

    A base built from measured-like simulated FRFs may carry ``meta["frf_correction"]``, an FRFSet
    added after synthesis (the part of those FRFs its modal model does not reproduce), so that the
    prediction without effects equals the simulated FRFs. That term is not windowed by an
    ``exponential_window`` (it is a fixed FRF, not a pole-residue model)."""
    model = base
    for spec in effects:
        eff, params = _lookup(spec)
        if eff.kind == "modal":
            model = eff.apply(model, params)
    f = np.asarray(freq_hz, float)
    frf = FRFSet(freq_hz=f, H=_synthesised(model, f, quantity, base.meta.get("frf_correction")), quantity=quantity,
                 outputs=model.outputs, references=model.references)
    if model.meta.get(FRF_MASSES_KEY):
        frf = add_frf_masses(model, frf)
    if outputs is not None or references is not None:
        frf = replace(frf, outputs=frf.outputs if outputs is None else tuple(outputs),
                      references=frf.references if references is None else tuple(references))
    return _frf_effects(frf, effects)


def _frf_effects(frf: FRFSet, effects: Sequence[Mapping]) -> FRFSet:
    """``frf`` with the FRF effects of ``effects`` applied in list order (the modal ones are skipped)."""
    for spec in effects:
        eff, params = _lookup(spec)
        if eff.kind == "frf":
            frf = eff.apply(frf, params)
    return frf


#: The catalogue as the resonator search uses it (:mod:`.resonator_search`): :func:`predict` and the lookup
#: of an applied effect's row.
CATALOGUE = Catalogue(predict=predict, lookup=_lookup, synthesised=_synthesised)
