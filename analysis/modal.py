"""Modal model container and FRF synthesis (the paper's eq. (11)).

Symbols
-------
lambda_r : pole of mode r (rad/s), ``sigma_r + j omega_d,r`` with ``sigma_r < 0``.
f_r      : natural frequency ``|lambda_r| / 2 pi`` (Hz).
zeta_r   : damping ratio ``-Re(lambda_r) / |lambda_r|``.
f_d,r    : damped natural frequency ``Im(lambda_r) / 2 pi`` (Hz).
R_ijr    : residue of mode r from reference j to output i.
UR, LR   : upper and lower residual terms.

The synthesised FRF in the form of quantity ``q`` (p = 0, 1, 2 for receptance,
mobility, accelerance) is

    H_ij(w) = sum_r [ R_ijr / (jw - lambda_r) + conj(R_ijr) / (jw - conj(lambda_r)) ]
              + UR_ij * b_U(w) + LR_ij * b_L(w)

with the residual basis ``(b_U, b_L)`` chosen by ``residual_form``:

* ``"paper"``: ``(1, 1/w^2)`` whatever the quantity (the paper's eq. (10)/(11)).
* ``"physical"``: the receptance-equivalent terms carried into the form,
  ``((jw)^p, (jw)^p / w^2)``: receptance ``(1, 1/w^2)``, mobility ``(jw, j/w)``,
  accelerance ``(-w^2, -1)``. UR is then a flexibility (m/N) and LR a
  flexibility times (rad/s)^2 whatever the form, so values compare across forms.
* ``"none"``: no residual terms.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .frf import QUANTITIES, QUANTITY_POWER, FRFSet

__all__ = [
    "ModalModel",
    "RESIDUAL_FORMS",
    "residual_basis",
    "synthesize",
    "transfer",
    "pole_kernels",
    "pole_from_fz",
    "natural_freq_hz",
    "damping_ratio",
    "damped_freq_hz",
    "decay_time_s",
]

RESIDUAL_FORMS = ("physical", "paper", "none")
_POWER = QUANTITY_POWER


def pole_from_fz(freq_hz: np.ndarray | float, zeta: np.ndarray | float) -> np.ndarray:
    """Pole(s) lambda = -zeta w_n + j w_n sqrt(1 - zeta^2) from natural frequency (Hz) and damping ratio."""
    wn = 2 * np.pi * np.asarray(freq_hz, dtype=float)
    z = np.asarray(zeta, dtype=float)
    return -z * wn + 1j * wn * np.sqrt(1 - z ** 2)


def natural_freq_hz(poles: np.ndarray | complex) -> np.ndarray:
    """|lambda| / 2 pi (Hz); ``poles`` in rad/s (an array or one pole)."""
    return np.abs(np.asarray(poles)) / (2 * np.pi)


def damping_ratio(poles: np.ndarray | complex) -> np.ndarray:
    """-Re(lambda) / |lambda| (dimensionless)."""
    p = np.asarray(poles)
    return -np.real(p) / np.abs(p)


def damped_freq_hz(poles: np.ndarray | complex) -> np.ndarray:
    """Im(lambda) / 2 pi (Hz)."""
    return np.imag(np.asarray(poles)) / (2 * np.pi)


def decay_time_s(freq_hz: float, damping: float, decay_db: float) -> float:
    """Seconds for the free decay of a mode (natural frequency Hz, viscous damping ratio) to fall by
    ``decay_db`` dB: its envelope ``exp(-zeta omega t)`` gives ``ln(10^(decay_db/20)) / (damping 2 pi freq_hz)``
    (one time constant ``1 / (zeta omega)`` is 8.69 dB). ValueError unless all three are positive."""
    if not (freq_hz > 0 and damping > 0 and decay_db > 0):
        raise ValueError(f"a decay time needs a positive frequency, damping and decay; got {freq_hz} Hz, "
                         f"damping {damping}, {decay_db} dB")
    return math.log(10 ** (decay_db / 20)) / (damping * 2 * math.pi * freq_hz)


def residual_basis(omega: np.ndarray, quantity: str, residual_form: str) -> np.ndarray:
    """Residual basis functions, shape (2, n_freq) for (UR, LR), or (0, n_freq) for ``"none"``.

    ``omega`` in rad/s; at omega = 0 the 1/w^2 term is set to 0 (undefined there).
    """
    if quantity not in QUANTITIES:
        raise ValueError(f"quantity {quantity!r} is not one of {QUANTITIES}")
    if residual_form not in RESIDUAL_FORMS:
        raise ValueError(f"residual_form {residual_form!r} is not one of {RESIDUAL_FORMS}")
    w = np.asarray(omega, dtype=float)
    if residual_form == "none":
        return np.zeros((0, w.size), dtype=complex)
    with np.errstate(divide="ignore"):
        inv_w2 = np.where(w == 0, 0.0, 1.0 / np.where(w == 0, 1.0, w) ** 2)
    if residual_form == "paper":
        return np.vstack([np.ones_like(w, dtype=complex), inv_w2.astype(complex)])
    s = (1j * w) ** _POWER[quantity]
    return np.vstack([s, s * inv_w2])


@dataclass(frozen=True)
class ModalModel:
    """Poles, residues and residual terms of a modal model.

    poles : (n_modes,) complex, rad/s, upper half plane (Im > 0).
    residues : (n_out, n_ref, n_modes) complex, in the units of the FRF times rad/s.
    upper_residual, lower_residual : (n_out, n_ref) complex or None.
    quantity, residual_form : see module docstring.
    outputs, references : point labels.
    """

    poles: np.ndarray
    residues: np.ndarray
    quantity: str = "accelerance"
    residual_form: str = "physical"
    upper_residual: np.ndarray | None = None
    lower_residual: np.ndarray | None = None
    outputs: tuple = ()
    references: tuple = ()
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        p = np.atleast_1d(np.asarray(self.poles, dtype=complex))
        R = np.asarray(self.residues, dtype=complex)
        if R.ndim == 1:
            R = R[None, None, :]
        if R.ndim != 3 or R.shape[2] != p.size:
            raise ValueError(f"residues must be (n_out, n_ref, n_modes={p.size}); got {R.shape}")
        object.__setattr__(self, "poles", p)
        object.__setattr__(self, "residues", R)
        for name in ("upper_residual", "lower_residual"):
            v = getattr(self, name)
            if v is not None:
                object.__setattr__(self, name, np.asarray(v, dtype=complex).reshape(R.shape[:2]))
        if self.quantity not in QUANTITIES:
            raise ValueError(f"quantity {self.quantity!r} is not one of {QUANTITIES}")
        if self.residual_form not in RESIDUAL_FORMS:
            raise ValueError(f"residual_form {self.residual_form!r} is not one of {RESIDUAL_FORMS}")

    @property
    def freq_hz(self) -> np.ndarray:
        return natural_freq_hz(self.poles)

    @property
    def damping(self) -> np.ndarray:
        return damping_ratio(self.poles)


def pole_kernels(poles: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``1 / (s - lambda_r)`` and ``1 / (s - conj(lambda_r))`` (..., n_modes, n_s) of the poles (..., n_modes)
    at the complex frequencies ``s`` (rad/s): the kernels :func:`transfer` sums."""
    lam = np.asarray(poles, dtype=complex)
    s = np.asarray(s, dtype=complex).ravel()
    return 1.0 / (s - lam[..., :, None]), 1.0 / (s - np.conj(lam)[..., :, None])


def transfer(model: ModalModel, s: np.ndarray, poles: np.ndarray | None = None,
             residues: np.ndarray | None = None,
             kernels: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """The model's transfer function at complex frequencies ``s`` (rad/s), shape (n_out, n_ref, n_s):
    the one synthesis kernel of the package (eq. 11 continued off the j omega axis)::

        H(s) = sum_r [ R_r / (s - lambda_r) + conj(R_r) / (s - conj(lambda_r)) ] + UR b_U(s) + LR b_L(s)

    with the residual bases as functions of s: ``"physical"`` ``(s^p, -s^(p-2))`` (p the quantity's
    power of s), ``"paper"`` ``(1, -1/s^2)``; on ``s = j omega`` these are :func:`residual_basis`.
    At ``s = 0`` the second basis term is set to 0, as :func:`residual_basis` does at omega = 0.
    ``s = j omega`` gives the FRF (:func:`synthesize`); ``s = j omega + a`` the FRF seen through an
    exponential window ``exp(-a t)``.

    ``poles`` (..., n_modes) and ``residues`` (..., n_out, n_ref, n_modes), with the same leading axes: several
    variants of the model's modes at once (its residual terms), shape (..., n_out, n_ref, n_s); each variant as
    the model with those poles and residues gives it. ``kernels``: :func:`pole_kernels` of those poles at ``s``
    when the caller has them already."""
    s = np.asarray(s, dtype=complex).ravel()
    lam = np.asarray(model.poles if poles is None else poles, dtype=complex)
    R = np.asarray(model.residues if residues is None else residues, dtype=complex)
    n_out, n_ref = R.shape[-3:-1]
    lead = R.shape[:-3]
    Rf = R.reshape(*lead, n_out * n_ref, lam.shape[-1])
    # (n_modes, n_s) pole kernels, summed by matrix products (BLAS)
    k, kc = pole_kernels(lam, s) if kernels is None else kernels
    G = Rf @ k + np.conj(Rf) @ kc
    if model.residual_form != "none":
        p = _POWER[model.quantity]
        zero = s == 0
        s_safe = np.where(zero, 1.0, s)
        if model.residual_form == "physical":
            upper, lower = s ** p, -(s_safe ** (p - 2.0))
        else:
            upper, lower = np.ones_like(s), -1.0 / s_safe ** 2
        lower = np.where(zero, 0.0, lower)
        if model.upper_residual is not None:
            G = G + np.asarray(model.upper_residual).reshape(-1, 1) * upper
        if model.lower_residual is not None:
            G = G + np.asarray(model.lower_residual).reshape(-1, 1) * lower
    return G.reshape(*lead, n_out, n_ref, s.size)


def synthesize(model: ModalModel, freq_hz: np.ndarray) -> FRFSet:
    """FRFs of a modal model at ``freq_hz`` (Hz), eq. (11): :func:`transfer` on ``s = j 2 pi f``;
    returns an :class:`FRFSet` in the model's quantity."""
    f = np.asarray(freq_hz, dtype=float)
    H = transfer(model, 2j * np.pi * f)
    return FRFSet(freq_hz=f, H=H, quantity=model.quantity, outputs=model.outputs, references=model.references)
