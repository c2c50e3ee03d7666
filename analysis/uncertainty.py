"""Pole uncertainty: covariance from the fit, propagation to (f_n, zeta), Fisher information, Cramer-Rao bound.

Noise model
-----------
Each FRF line carries additive circular complex Gaussian noise ``e`` with
``E|e|^2 = noise_var`` (so Re e and Im e are independent with variance ``noise_var / 2``).
The model is written in real parameters and real residuals (rows ``[Re; Im]``), so the
Fisher information is ``F = J^T J / (noise_var / 2)`` with ``J`` the real Jacobian of the
stacked model with respect to all real parameters.

Parameters (real), in this order
--------------------------------
``theta = (sigma_1, omega_1, ..., sigma_m, omega_m)`` with ``lambda_r = sigma_r + j omega_r``
(rad/s), then for every FRF ``(o, i)`` in C order (output-major) its linear parameters
``(Re R_1, Im R_1, ..., Re R_m, Im R_m, Re UR, Im UR, Re LR, Im LR)`` (residual terms only
when the model's ``residual_form`` has them; they are estimated even when zero).

Cramer-Rao bound of the poles
-----------------------------
The linear parameters of each FRF are nuisance parameters; the bound on ``theta`` is the
inverse of the Schur complement ``F_tt - F_tc F_cc^-1 F_ct = sum_f J_f^T P_f J_f / (noise_var/2)``
where ``P`` projects out the span of the linear basis: the variable-projection Gram matrix
(:func:`analysis._lsfd_kernels.projected_gram`).

Propagation to natural frequency and damping
--------------------------------------------
``f = |lambda| / 2 pi``, ``zeta = -sigma / |lambda|``::

    df/dsigma = sigma / (2 pi |lambda|),      df/domega = omega / (2 pi |lambda|)
    dzeta/dsigma = -omega^2 / |lambda|^3,     dzeta/domega = sigma omega / |lambda|^3

and ``cov(f, zeta) = G cov(sigma, omega) G^T`` (first order).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._lsfd_kernels import ProjectedProblem, poles_to_theta, projected_gram, theta_to_poles
from .modal import ModalModel

__all__ = [
    "fz_jacobian",
    "fz_covariance",
    "fz_std",
    "covariance_from_normal",
    "fisher_information",
    "crlb_poles",
    "CRLB",
]

#: refuse to build dense Fisher matrices larger than this many elements
_MAX_DENSE = 50_000_000


def fz_jacobian(poles: np.ndarray) -> np.ndarray:
    """(m, 2, 2) derivatives ``d(f_hz, zeta) / d(sigma, omega)`` per pole (rows f, zeta)."""
    lam = np.atleast_1d(np.asarray(poles, dtype=complex))
    s, w = lam.real, lam.imag
    a = np.abs(lam)
    G = np.empty((lam.size, 2, 2))
    G[:, 0, 0] = s / (2 * np.pi * a)
    G[:, 0, 1] = w / (2 * np.pi * a)
    G[:, 1, 0] = -w ** 2 / a ** 3
    G[:, 1, 1] = s * w / a ** 3
    return G


def fz_covariance(poles: np.ndarray, cov_poles: np.ndarray) -> np.ndarray:
    """Covariance (2m x 2m) of ``(f_1, zeta_1, ..., f_m, zeta_m)`` from that of
    ``(Re lambda_1, Im lambda_1, ...)`` (first-order propagation; f in Hz)."""
    G = fz_jacobian(poles)
    m = G.shape[0]
    cov = np.asarray(cov_poles, dtype=float)
    if cov.shape != (2 * m, 2 * m):
        raise ValueError(f"cov_poles must be ({2 * m}, {2 * m}) for {m} poles; got {cov.shape}")
    Gb = np.zeros((2 * m, 2 * m))
    for r in range(m):
        Gb[2 * r:2 * r + 2, 2 * r:2 * r + 2] = G[r]
    return Gb @ cov @ Gb.T


def fz_std(poles: np.ndarray, cov_poles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Standard deviations of natural frequency (Hz) and damping ratio per pole."""
    c = fz_covariance(poles, cov_poles)
    v = np.sqrt(np.clip(np.diag(c), 0.0, None))
    return v[0::2].copy(), v[1::2].copy()


def covariance_from_normal(JtJ: np.ndarray, real_var: float) -> np.ndarray:
    """``real_var * (J^T J)^-1`` computed on the diagonally scaled matrix (pseudo-inverse if singular).

    ``real_var`` is the variance of one real residual (``noise_var / 2``).
    """
    d = np.sqrt(np.abs(np.diag(JtJ)))
    d[d == 0] = 1.0
    M = JtJ / np.outer(d, d)
    try:
        Minv = np.linalg.inv(M)
        if not np.all(np.isfinite(Minv)):
            raise np.linalg.LinAlgError("non-finite inverse")
    except np.linalg.LinAlgError:
        Minv = np.linalg.pinv(M)
    return real_var * Minv / np.outer(d, d)


def _model_problem(model: ModalModel, freq_hz: np.ndarray) -> tuple[ProjectedProblem, np.ndarray]:
    f = np.asarray(freq_hz, dtype=float)
    if f.ndim != 1 or f.size < 2 or np.any(f <= 0):
        raise ValueError("freq_hz must be a 1-D array of positive frequencies (Hz)")
    n_frf = model.residues.shape[0] * model.residues.shape[1]
    prob = ProjectedProblem(2 * np.pi * f, np.zeros((n_frf, f.size), dtype=complex), model.quantity,
                            model.residual_form)
    return prob, poles_to_theta(model.poles)


def _mode_coef(model: ModalModel) -> np.ndarray:
    R = model.residues.reshape(-1, model.poles.size)       # (n_frf, m)
    c = np.empty((2 * model.poles.size, R.shape[0]))
    c[0::2] = R.real.T
    c[1::2] = R.imag.T
    return c


def fisher_information(model: ModalModel, freq_hz: np.ndarray, noise_var: float) -> np.ndarray:
    """Full Fisher information matrix of the model's real parameters (order in the module docstring).

    Built from the explicit stacked Jacobian (analytic derivatives), so it is meant for
    small problems and for checking; :func:`crlb_poles` gives the pole bound for any size.

    Parameters
    ----------
    model : the true modal model (poles rad/s, residues, residual form).
    freq_hz : (N,) lines (Hz) at which the FRFs are observed.
    noise_var : ``E|e|^2`` of the circular complex noise per line (FRF units squared).
    """
    if not noise_var > 0:
        raise ValueError(f"noise_var must be > 0; got {noise_var}")
    prob, theta = _model_problem(model, freq_hz)
    A, E = prob.basis(theta)
    coef = _mode_coef(model)
    m = model.poles.size
    n_frf = coef.shape[1]
    P = A.shape[1]
    n_par = 2 * m + n_frf * P
    rows = A.shape[0] * n_frf
    if rows * n_par > _MAX_DENSE:
        raise ValueError(f"the dense Jacobian would hold {rows * n_par} elements; use crlb_poles for large problems")
    J = np.zeros((rows, n_par))
    N2 = A.shape[0]
    for f in range(n_frf):
        blk = slice(f * N2, (f + 1) * N2)
        for r in range(m):
            a, b = coef[2 * r, f], coef[2 * r + 1, f]
            e1, e2 = E[:, 2 * r], E[:, 2 * r + 1]
            J[blk, 2 * r] = a * e1 + b * e2
            J[blk, 2 * r + 1] = a * e2 - b * e1
        J[blk, 2 * m + f * P:2 * m + (f + 1) * P] = A
    return J.T @ J / (noise_var / 2.0)


@dataclass(frozen=True)
class CRLB:
    """Cramer-Rao lower bound of the poles.

    freq_hz_std, damping_std : (m,) lower bounds on the standard deviation of f_n (Hz) and zeta.
    cov_poles : (2m, 2m) bound on the covariance of (Re lambda_1, Im lambda_1, ...) (rad/s)^2.
    cov_fz : (2m, 2m) bound on the covariance of (f_1, zeta_1, ...).
    """

    freq_hz_std: np.ndarray
    damping_std: np.ndarray
    cov_poles: np.ndarray
    cov_fz: np.ndarray


def crlb_poles(model: ModalModel, freq_hz: np.ndarray, noise_var: float) -> CRLB:
    """Cramer-Rao bound of natural frequency and damping of every mode of ``model``.

    For FRFs observed at ``freq_hz`` (Hz) with circular complex Gaussian noise of variance
    ``noise_var`` per line, estimating all parameters of the model (poles shared by all
    FRFs, residues and residual terms per FRF). See the module docstring.
    """
    if not noise_var > 0:
        raise ValueError(f"noise_var must be > 0; got {noise_var}")
    prob, theta = _model_problem(model, freq_hz)
    A, E = prob.basis(theta)
    norms = np.sqrt(np.einsum("ij,ij->j", A, A))
    Q, _ = np.linalg.qr(A / norms)
    JtJ, _ = projected_gram(Q, E, _mode_coef(model))
    cov = covariance_from_normal(JtJ, noise_var / 2.0)
    poles = theta_to_poles(theta)
    cfz = fz_covariance(poles, cov)
    v = np.sqrt(np.clip(np.diag(cfz), 0.0, None))
    return CRLB(freq_hz_std=v[0::2].copy(), damping_std=v[1::2].copy(), cov_poles=cov, cov_fz=cfz)
