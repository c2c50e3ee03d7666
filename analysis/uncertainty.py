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

The noise the data show at each mode
------------------------------------
A fit's covariance takes one noise variance for every line (its residual's mean square) and lines
whose noise is independent. Neither holds for an impact test near the top of the hammer's band: the
force spectrum falls, the noise relative to the FRF grows there (a soft hit's modes near the band's
top sit in lines ten times noisier than the band's average), and the exponential window on the
responses makes neighbouring lines' noise correlated. :func:`mode_noise_factor` gives, per mode, the
factor by which the variance of its pole is larger than the fit says, from the data: the per-line
noise variance of each FRF ``v_k`` (:func:`analysis.reciprocity.frf_error_variance`, from the coherence
and the averages; without coherence the fit's own) and the lines' correlation ``rho_m`` from the recorded window. For
one pole with the sensitivity ``g_k = dH_k / dlambda = R / (j w_k - lambda)^2`` of each FRF, the
least-squares estimate moves by ``Re(sum g_k^* e_k) / sum |g_k|^2``, whose variance over the fit's
``noise_var / (2 sum |g_k|^2)`` is

    c = sum_FRF Re(g^H D Rho D g) / (noise_var sum_FRF |g|^2),   D = diag(sqrt(v_k)),
    Rho_kl = E[e_k e_l^*] / sqrt(v_k v_l) = rho_(l-k),  rho_m = x / (x - 2 pi j m),  x = 2 T / tau

(windowed white noise: ``rho_m = sum_n w_n^2 exp(2 pi j m n / N) / sum_n w_n^2`` with
``w = exp(-t / tau)`` over the record ``T = 1 / line spacing``). The mode's standard deviations of
frequency and damping are the fit's times ``sqrt(max(c, 1))``: never more certain than the fit says.
It is a one-pole (diagonal) approximation of the sandwich covariance; it stops working where two
modes share their lines so closely that their poles' errors are strongly correlated, and where the
coherence is near 1 for reasons other than a small noise (a distortion repeated in every hit).
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
    "window_line_correlation",
    "mode_noise_factor",
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


def window_line_correlation(exp_window_tau_s: float | None, line_spacing_hz: float, n_lags: int) -> np.ndarray:
    """Correlation ``rho_m = E[e_k e_(k+m)^*] / E|e_k|^2`` (m = 0..n_lags) of the noise of lines m apart
    when the responses carry an exponential window ``exp(-t / tau)`` over the record ``T = 1 / line
    spacing``: ``x / (x - 2 pi j m)``, ``x = 2 T / tau`` (module docstring); ``rho_0 = 1`` and no
    correlation without a window (``exp_window_tau_s`` None or 0)."""
    m = np.arange(n_lags + 1)
    if not exp_window_tau_s or not line_spacing_hz > 0:
        return (m == 0).astype(complex)
    x = 2.0 / (float(exp_window_tau_s) * float(line_spacing_hz))
    return x / (x - 2j * np.pi * m)


#: lines each side of a mode whose noise enters :func:`mode_noise_factor` (its sensitivity has fallen by
#: 1/LAG_LINES^2 at the window's edge, and the window correlation is summed over as many lags)
LAG_LINES = 64


def mode_noise_factor(poles_raw: np.ndarray, residues: np.ndarray, freq_hz: np.ndarray, noise_var: float,
                      line_var: np.ndarray | None = None, exp_window_tau_s: float | None = None) -> np.ndarray:
    """Per mode, the factor ``c`` by which its pole's variance exceeds the fit's (module docstring).

    poles_raw : (m,) rad/s as fitted to the data (the window's decay included).
    residues : (n_out, n_ref, m) of the fitted pole-residue model in the data's quantity.
    freq_hz : (N,) the lines fitted (Hz, equally spaced).
    noise_var : the fit's ``E|e|^2`` per line (:attr:`analysis.lsfd.LSFDResult.noise_var`).
    line_var : (n_out, n_ref, N) per-line ``E|e|^2`` (:func:`analysis.reciprocity.frf_error_variance`); None: ``noise_var``
        on every line (only the window's correlation then counts).
    exp_window_tau_s : the responses' exponential window (s), or None.
    Returns (m,) factors; NaN for a mode with no sensitivity or a fit without a noise estimate.
    """
    lam = np.atleast_1d(np.asarray(poles_raw, complex))
    R = np.asarray(residues, complex)
    f = np.asarray(freq_hz, float)
    jw = 2j * np.pi * f
    n_frf = R.shape[0] * R.shape[1]
    Rf = R.reshape(n_frf, lam.size)
    sd = (np.full((n_frf, f.size), np.sqrt(noise_var)) if line_var is None
          else np.sqrt(np.asarray(line_var, float).reshape(n_frf, f.size)))
    df = float(f[1] - f[0]) if f.size > 1 else 0.0
    rho = window_line_correlation(exp_window_tau_s, df, LAG_LINES)
    out = np.full(lam.size, np.nan)
    if not (noise_var > 0 and np.isfinite(noise_var)):
        return out
    for r in range(lam.size):
        k0 = int(np.argmin(np.abs(f - abs(lam[r].imag) / (2 * np.pi))))
        sel = slice(max(k0 - 4 * LAG_LINES, 0), min(k0 + 4 * LAG_LINES + 1, f.size))
        kern = 1.0 / (jw[sel] - lam[r]) ** 2
        num = den = 0.0
        for i in range(n_frf):
            g = Rf[i, r] * kern
            u = sd[i, sel] * g                      # D g
            if not np.all(np.isfinite(u)):
                continue
            # u^H Rho u with Rho_kl = rho_(l-k): the lag-0 term plus twice the real part of each positive lag
            q = float(np.sum(np.abs(u) ** 2))
            for m in range(1, min(LAG_LINES, u.size - 1) + 1):
                if rho[m] == 0:
                    break
                q += 2.0 * float(np.real(rho[m] * np.sum(np.conj(u[:-m]) * u[m:])))
            num += q
            den += float(np.sum(np.abs(g) ** 2))
        if den > 0:
            out[r] = num / (noise_var * den)
    return out
