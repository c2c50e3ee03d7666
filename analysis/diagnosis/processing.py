"""Known processing of a measurement, applied to a simulation so that it is seen as measured: the
exponential window on the responses and the finite record after the pulse (exact, per mode, in the
measured quantity)."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from ..frf import QUANTITY_POWER, FRFSet, convert_quantity, window_pole_shift
from ..modal import ModalModel, pole_kernels, transfer
from .effect_types import EffectError

__all__ = ["WINDOW_SHIFT_KEY", "RECORD_KEY", "apply_exponential_window", "apply_record_length", "truncation_tail",
           "synthesize_windowed", "windowed_transfer", "synthesis_derivative"]

_POWER = QUANTITY_POWER
WINDOW_SHIFT_KEY = "exp_window_pole_shift_per_s"  # model.meta key: summed 1/tau of the exponential windows (1/s)
RECORD_KEY = "record_after_pulse_s"                # model.meta key: response record length after the hammer pulse (s)


def apply_exponential_window(model: ModalModel, params: Mapping) -> ModalModel:
    """An exponential window ``exp(-t/exp_window_tau_s)`` (s) on the measured responses.

    The window multiplies the impulse response of the *measured* quantity, so its effect depends on
    the quantity the model is synthesised in; the model's poles and residues are therefore left as
    they are and the pole shift ``1/exp_window_tau_s`` (1/s) is recorded in ``meta[WINDOW_SHIFT_KEY]``
    (several windows add their shifts). :func:`predict` then synthesises the exact windowed FRF with
    :func:`synthesize_windowed`."""
    tau = float(params.get("exp_window_tau_s", params.get("tau_s", np.inf)))  # "tau_s": older effect specs
    if not (tau > 0 and np.isfinite(tau)):
        raise EffectError(f"exponential_window: exp_window_tau_s must be a finite number > 0 (s), got {tau!r}")
    meta = dict(model.meta)
    meta[WINDOW_SHIFT_KEY] = float(meta.get(WINDOW_SHIFT_KEY, 0.0)) + window_pole_shift(tau)
    return replace(model, meta=meta)


def apply_record_length(model: ModalModel, params: Mapping) -> ModalModel:
    """The finite record of the measurement (known processing, not a catalogue effect): the response
    is recorded for ``record_s`` (s) from ``pretrigger_s`` (s) before the hammer pulse, so only
    ``T = record_s - pretrigger_s`` of each impulse response after the pulse is seen. Recorded in
    ``meta[RECORD_KEY]``; :func:`synthesize_windowed` applies it."""
    T = float(params.get("record_s", np.nan)) - float(params.get("pretrigger_s", 0.0))
    if not (np.isfinite(T) and T > 0):
        raise EffectError(f"record_length: record_s - pretrigger_s must be a positive time (s), got {params!r}")
    return replace(model, meta={**model.meta, RECORD_KEY: T})


def truncation_tail(model: ModalModel, s: np.ndarray, quantity: str, record_s: float,
                    poles: np.ndarray | None = None, residues: np.ndarray | None = None,
                    kernels: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """What a record of ``record_s`` seconds after the pulse misses of each mode's impulse response
    in the measured ``quantity``, at the Laplace points ``s`` (rad/s):

        H_T(s) = sum_r N_r / (s - lambda_r) (1 - exp((lambda_r - s) T)) + c.c.,  N_r = R_r lambda_r^(q-p)

    so the tail returned, ``exp(-s T) sum_r N_r exp(lambda_r T) / (s - lambda_r) + c.c.``, is
    subtracted from the full FRF. At the DFT lines ``exp(-j w_k T_rec) = 1``; the residual terms (mass
    and stiffness lines, deltas at t = 0) are not truncated. (n_out, n_ref, n_freq) complex; ``poles`` and
    ``residues`` with leading axes: the model's variants (:func:`analysis.modal.transfer`), (..., n_out, n_ref, n_freq).
    ``kernels``: :func:`analysis.modal.pole_kernels` of the poles at ``s`` when the caller has them already."""
    lam = np.asarray(model.poles if poles is None else poles, complex)
    R = np.asarray(model.residues if residues is None else residues, complex)
    N = R * (lam ** float(_POWER[quantity] - _POWER[model.quantity]))[..., None, None, :]
    a = N * np.exp(lam * record_s)[..., None, None, :]
    n_out, n_ref = a.shape[-3:-1]
    lead = a.shape[:-3]
    both = np.concatenate([lam, np.conj(lam)], axis=-1)     # the poles and their conjugates, one product
    den = np.concatenate(pole_kernels(lam, s) if kernels is None else kernels, axis=-2)
    tail = (np.concatenate([a, np.conj(a)], axis=-1).reshape(*lead, n_out * n_ref, both.shape[-1]) @ den
            ).reshape(*lead, n_out, n_ref, s.size)
    return tail * np.exp(-s * record_s)


def synthesize_windowed(model: ModalModel, freq_hz: np.ndarray, quantity: str,
                        pole_shift_per_s: float | None = None) -> FRFSet:
    """FRFs of ``model`` in ``quantity`` as measured through an exponential window ``exp(-t/tau)``,
    ``sigma_w = pole_shift_per_s = 1/tau`` (1/s; default ``model.meta[WINDOW_SHIFT_KEY]``, 0 without a window).

    Multiplying the impulse response ``h_q(t)`` of the measured quantity q by ``exp(-sigma_w t)`` shifts its
    Laplace transform: ``H_q,w(j w) = H_q(j w + sigma_w)``. With the model in form p,
    ``H_q(s) = s^(q-p) H_p(s)`` and ``H_p(s) = sum_r [R_r / (s - lambda_r) + c.c.] + UR b_U(s) + LR b_L(s)``,
    so the exact windowed FRF is

        H_q,w(w) = (j w + sigma_w)^(q-p) H_p(j w + sigma_w).

    Equivalently every pole of the measured quantity's pole-residue model moves by ``-sigma_w`` with the same
    residues (e.g. accelerance from receptance: ``N_r = R_r lambda_r^2`` over ``s - lambda_r``), a
    constant (feed-through, a delta at t = 0) is unchanged and a term ``c s`` (delta') becomes
    ``c (s + sigma_w)``. Converting the shifted receptance by ``(j w)^(q-p)`` instead errs by about
    ``(q-p) sigma_w / w`` relative. Residual terms are continued as the functions of s they are on the
    j w axis and shifted alike: ``"physical"`` basis ``(s^p, -s^(p-2))``, ``"paper"`` ``(1, -1/s^2)``
    (a constant UR is unchanged; LR, a rigid-body/mass line, becomes its windowed version).
    A fixed FRF term (``meta["frf_correction"]``) is not part of this (see :func:`predict`).
    With ``meta[RECORD_KEY]`` (:func:`apply_record_length`) the finite record is applied too
    (:func:`truncation_tail`, at the windowed ``s``: the window and the record act on the same response).
    Returns an :class:`FRFSet` in ``quantity``; with ``sigma_w = 0`` and no record this is plain synthesis and
    conversion (its FRFs: :func:`windowed_transfer`)."""
    f = np.asarray(freq_hz, float)
    H = windowed_transfer(model, f, quantity, pole_shift_per_s)
    return FRFSet(freq_hz=f, H=H, quantity=quantity, outputs=model.outputs, references=model.references)


def windowed_transfer(model: ModalModel, freq_hz: np.ndarray, quantity: str, pole_shift_per_s: float | None = None,
                      poles: np.ndarray | None = None, residues: np.ndarray | None = None) -> np.ndarray:
    """The FRFs of :func:`synthesize_windowed` (n_out, n_ref, n_freq); with ``poles`` (..., n_modes) and
    ``residues`` (..., n_out, n_ref, n_modes) those of the model's variants with these modes, all at once
    (..., n_out, n_ref, n_freq): each as :func:`synthesize_windowed` gives the model with those modes."""
    if quantity not in _POWER:
        raise EffectError(f"quantity {quantity!r} is not one of {tuple(_POWER)}")
    sigma_w = float(model.meta.get(WINDOW_SHIFT_KEY, 0.0)) if pole_shift_per_s is None else float(pole_shift_per_s)
    if not (np.isfinite(sigma_w) and sigma_w >= 0):
        raise EffectError(f"exponential window pole shift must be a finite number >= 0 (1/s), got {sigma_w!r}")
    f = np.asarray(freq_hz, float)
    record = model.meta.get(RECORD_KEY)
    s = 2j * np.pi * f + sigma_w
    # the record's tail sums the same pole kernels as the synthesis: computed once
    kernels = pole_kernels(model.poles if poles is None else poles, s) if record else None
    if sigma_w == 0.0:
        # the model's synthesis (eq. 11) in its own quantity, converted: one FRF set built (the fits call this often)
        H = transfer(model, 2j * np.pi * f, poles, residues, kernels)
        H = convert_quantity(H, f, model.quantity, quantity) if model.quantity != quantity else H
    else:
        H = transfer(model, s, poles, residues, kernels) * s ** float(_POWER[quantity] - _POWER[model.quantity])
    if record:
        H = H - truncation_tail(model, s, quantity, float(record), poles, residues, kernels)
    return H


def _pole_sums(R: np.ndarray, dR: np.ndarray, lam: np.ndarray, dlam: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``sum_i [dR_i k_i + R_i dlambda_i k_i^2] + c.c. of the residues and poles``, ``k_i = 1 / (s - lambda_i)``,
    (n_out, n_ref, n_s, P) for ``R`` (n_out, n_ref, n), ``dR`` (n_out, n_ref, n, P), ``dlam`` (n, P) of real
    parameters: with ``E = R dlambda`` and ``kc`` the conjugate poles' kernels, ``k dR + kc conj(dR) =
    (k + kc) Re dR + j (k - kc) Im dR`` and ``k^2 E + kc^2 conj(E)`` alike, one real matrix product."""
    n_out, n_ref, n, P = dR.shape
    k1 = 1.0 / (s[:, None] - lam[None, :])
    c1 = 1.0 / (s[:, None] - np.conj(lam)[None, :])
    k2, c2 = k1 * k1, c1 * c1
    kernels = np.concatenate([k1 + c1, 1j * (k1 - c1), k2 + c2, 1j * (k2 - c2)], axis=1)      # (n_s, 4n)
    E = R[:, :, :, None] * dlam[None, None]
    terms = np.concatenate([np.moveaxis(dR, 2, 0).reshape(n, -1), np.moveaxis(E, 2, 0).reshape(n, -1)])
    terms = np.concatenate([terms[:n].real, terms[:n].imag, terms[n:].real, terms[n:].imag])   # (4n, n_out n_ref P)
    out = np.ascontiguousarray(kernels.real) @ terms + 1j * (np.ascontiguousarray(kernels.imag) @ terms)
    return out.reshape(s.size, n_out, n_ref, P).transpose(1, 2, 0, 3)


def synthesis_derivative(model: ModalModel, freq_hz: np.ndarray, quantity: str, dpoles: np.ndarray,
                         dresidues: np.ndarray) -> np.ndarray:
    """The derivative of :func:`synthesize_windowed` ``(model, freq_hz, quantity).H`` when the poles and residues
    move by ``dpoles`` (n_modes, P; rad/s per parameter) and ``dresidues`` (n_out, n_ref, n_modes, P; the
    model's form), the residual terms fixed: (n_out, n_ref, n_freq, P) complex. With ``k = q - p`` and
    ``s = j w + sigma_w``, ``H = s^k sum_i [R_i / (s - lambda_i) + c.c.] - H_T`` (:func:`truncation_tail`), so

        dH = s^k sum_i [dR_i / (s - lambda_i) + R_i dlambda_i / (s - lambda_i)^2 + c.c.] - dH_T,
        dH_T = exp(-s T) sum_i [dN_i / (s - lambda_i) + N_i dlambda_i / (s - lambda_i)^2 + c.c.],

    ``N_i = R_i lambda_i^k exp(lambda_i T)``, ``dN_i = exp(lambda_i T) [dR_i lambda_i^k + R_i (k lambda_i^(k-1)
    + T lambda_i^k) dlambda_i]``."""
    if quantity not in _POWER:
        raise EffectError(f"quantity {quantity!r} is not one of {tuple(_POWER)}")
    sigma_w = float(model.meta.get(WINDOW_SHIFT_KEY, 0.0))
    s = 2j * np.pi * np.asarray(freq_hz, float) + sigma_w
    k = float(_POWER[quantity] - _POWER[model.quantity])
    lam = np.asarray(model.poles, complex)
    R = np.asarray(model.residues, complex)
    dlam, dR = np.asarray(dpoles, complex), np.asarray(dresidues, complex)
    with np.errstate(divide="ignore", invalid="ignore"):
        dH = _pole_sums(R, dR, lam, dlam, s) * (s ** k)[:, None]
    record = model.meta.get(RECORD_KEY)
    if record:
        T = float(record)
        e = np.exp(lam * T)
        N = R * (lam ** k * e)[None, None, :]
        dN = (dR * (lam ** k * e)[None, None, :, None]
              + (R * ((k * lam ** (k - 1) + T * lam ** k) * e)[None, None, :])[..., None] * dlam[None, None])
        dH = dH - _pole_sums(N, dN, lam, dlam, s) * np.exp(-s * T)[:, None]
    return dH
