"""Nonlinear least-squares frequency-domain (LSFD) modal fit: Gauss-Newton and Levenberg-Marquardt.

The model is the paper's eq. (10)/(11)::

    H_ij(w) = sum_r [ R_ijr / (jw - lambda_r) + conj(R_ijr) / (jw - conj(lambda_r)) ] + residual terms

with poles ``lambda_r`` (rad/s) shared by every FRF of the set, residues ``R_ijr`` free per
FRF, and the residual terms of :func:`analysis.modal.residual_basis` (``"paper"``:
``UR + LR / w^2``). The sum of squared errors (eq. (14), summed over all FRFs)

    S = sum_ij sum_k |H_ij(w_k) - G_ij(w_k)|^2

is minimised over the poles by Gauss-Newton (eq. (7)) or Levenberg-Marquardt (eq. (9));
the residues and residual terms are solved exactly at each iterate (variable projection,
see :mod:`analysis._lsfd_kernels`). The mathematics, mu update and stopping rules are in
``docs/lsfd.md``.

Exponential window
------------------
A window ``w(t) = exp(-t / tau)`` on the responses turns every mode ``R e^{lambda t}`` into
``R e^{(lambda - 1/tau) t}``: each pole is shifted by ``-1/tau`` (rad/s) and the residues are
unchanged. The fit sees the shifted poles (``poles_raw``); with ``correct_exp_window`` the
reported poles are ``lambda = lambda_raw + 1/tau``. ``initial_poles`` are taken as seen in the
data (raw), as LSCE/LSCF on the same FRFs return them.
"""
from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from ._gn import run_gn
from ._lm import run_lm
from ._lsfd_kernels import NLSOutcome, ProjectedProblem, Status, poles_to_theta, theta_to_poles
from .fit_messages import STOPS, stop
from .frf import FRFSet, window_pole_shift
from .modal import RESIDUAL_FORMS, ModalModel, damped_freq_hz, damping_ratio, natural_freq_hz
from .threads import limits_blas_threads
from .uncertainty import covariance_from_normal, fz_std

__all__ = ["fit_lsfd", "lsfd_at_poles", "LSFDResult", "LSFDConvergenceWarning", "rank_one_split", "METHODS", "Status",
           "seen_through_window", "sorted_by_frequency"]

log = logging.getLogger(__name__)

METHODS = ("lm", "gn")


class LSFDConvergenceWarning(RuntimeWarning):
    """The LSFD iteration stopped at ``max_iter`` before meeting its tolerances."""


@dataclass(frozen=True)
class LSFDResult:
    """Outcome of :func:`fit_lsfd`.

    poles : (m,) complex rad/s, after exponential-window correction (Im > 0).
    poles_raw : (m,) as fitted to the data (window damping included).
    freq_hz, damping, damped_freq_hz : natural frequency (Hz), damping ratio, damped frequency (Hz) of ``poles``.
    freq_hz_std, damping_std : standard deviations from the Jacobian and the residual variance.
    model : the fitted :class:`ModalModel` (``poles`` corrected; residues in FRF units x rad/s).
    mode_shapes : (n_out, m) complex psi; participation : (m, n_ref) complex L; ``R[:, :, r] ~ psi_r L_r``
        (each L_r scaled so that its largest entry is 1; single reference: L = 1, psi = residues).
    sse : final S (weighted when weights are given); history : S per iteration (first = initial S).
    iterations, nfev : iterations done, model evaluations.
    status, message, success : see :class:`analysis._lsfd_kernels.Status` (> 0 is success).
    method : "lm" or "gn" (for :func:`lsfd_at_poles`: the iteration that found the poles); band : (lo, hi) Hz
        of the lines used.
    noise_var : estimated ``E|e|^2`` per line, ``2 S / (2 N n_frf - n_params)`` (N: lines of non-zero weight).
    cov_poles : (2m, 2m) covariance of (Re lambda_1, Im lambda_1, Re lambda_2, ...) (rad/s)^2.
    per_frf : with ``per_frf=True``, one result per (output, reference) FRF (C order), else None.
    initial_poles : the poles the iteration started from (raw).
    """

    poles: np.ndarray
    poles_raw: np.ndarray
    freq_hz: np.ndarray
    damping: np.ndarray
    damped_freq_hz: np.ndarray
    freq_hz_std: np.ndarray
    damping_std: np.ndarray
    model: ModalModel
    mode_shapes: np.ndarray | None
    participation: np.ndarray | None
    sse: float
    history: list
    iterations: int
    nfev: int
    status: int
    message: str
    success: bool
    method: str
    band: tuple
    noise_var: float
    cov_poles: np.ndarray
    per_frf: list | None = None
    initial_poles: np.ndarray | None = field(default=None, repr=False)

    @property
    def model_raw(self) -> ModalModel:
        """The fitted model *as measured*: ``model`` with the raw poles (the exponential window's
        damping included). Compare this one with the (windowed) data; ``model`` is the structure."""
        return replace(self.model, poles=np.asarray(self.poles_raw, dtype=complex).copy())


def seen_through_window(model: ModalModel, exp_window_tau_s: float | None) -> ModalModel:
    """The model as seen through an exponential window ``exp(-t / tau)``: every pole shifted by
    ``-1/tau`` (rad/s), residues and residual terms unchanged (see the module docstring).
    ``model`` describes the structure (window-corrected poles, as ``LSFDResult.model``);
    ``None`` or 0 for ``exp_window_tau_s`` returns the model unchanged."""
    if not exp_window_tau_s:
        return model
    return replace(model, poles=np.asarray(model.poles, dtype=complex) - window_pole_shift(exp_window_tau_s))


def rank_one_split(residues: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split ``R[:, :, r]`` (n_out x n_ref) per mode into ``psi_r L_r`` by its leading singular pair.

    Returns ``psi`` (n_out, m), ``L`` (m, n_ref) with the largest-magnitude entry of each ``L_r``
    equal to 1, and the ratio ``s_2 / s_1`` per mode (0 for an exact rank-one residue matrix).
    """
    R = np.asarray(residues, dtype=complex)
    n_out, n_ref, m = R.shape
    psi = np.zeros((n_out, m), dtype=complex)
    L = np.ones((m, n_ref), dtype=complex)
    ratio = np.zeros(m)
    if m == 0:
        return psi, L, ratio
    U, s, Vh = np.linalg.svd(np.moveaxis(R, 2, 0), full_matrices=False)   # all modes in one call
    ok = s[:, 0] != 0
    lr = Vh[:, 0, :]                                                       # (m, n_ref)
    c = lr[np.arange(m), np.argmax(np.abs(lr), axis=1)]
    L[ok] = lr[ok] / c[ok, None]
    psi[:, ok] = (U[ok, :, 0] * (s[ok, 0] * c[ok])[:, None]).T
    if s.shape[1] > 1:
        ratio[ok] = s[ok, 1] / s[ok, 0]
    return psi, L, ratio


# --------------------------------------------------------------------------- input checks
def _check_poles(initial_poles: np.ndarray) -> np.ndarray:
    p = np.atleast_1d(np.asarray(initial_poles))
    if p.ndim != 1 or p.size == 0:
        raise ValueError("initial_poles must be a non-empty 1-D array of complex poles (rad/s)")
    if not np.iscomplexobj(p):
        raise ValueError(
            "initial_poles must be complex poles sigma + j omega_d in rad/s; "
            "build them from (f_n Hz, zeta) with analysis.modal.pole_from_fz"
        )
    p = p.astype(complex)
    if not np.all(np.isfinite(p)):
        raise ValueError("initial_poles contain NaN or infinity")
    if np.any(p.imag <= 0):
        raise ValueError(
            "initial_poles must lie in the upper half plane (Im lambda > 0, one pole per mode); "
            "drop the conjugates / real poles"
        )
    if np.any(p.real >= 0):
        raise ValueError("initial_poles must be stable (Re lambda < 0); drop or fix the unstable poles")
    d = np.abs(p[:, None] - p[None, :])
    np.fill_diagonal(d, np.inf)
    if np.any(d <= 1e-9 * np.abs(p)[:, None]):
        raise ValueError("initial_poles contain duplicates; give each mode once")
    return p


def _check_weights(weights: np.ndarray | None, n_out: int, n_ref: int,
                   n_freq: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    if weights is None:
        return None, None
    w = np.asarray(weights, dtype=float)
    if not np.all(np.isfinite(w)) or np.any(w < 0) or not np.any(w > 0):
        raise ValueError("weights must be finite, >= 0 and not all zero")
    if w.shape == (n_freq,):
        return w, None
    if w.shape == (n_out, n_ref):
        if np.any(w == 0):
            raise ValueError("FRF weights must be > 0; drop an FRF with FRFSet.select instead of weighting it 0")
        return None, w.reshape(-1)
    raise ValueError(
        f"weights must have shape (n_freq,) = ({n_freq},) for per-line weights or (n_out, n_ref) = "
        f"({n_out}, {n_ref}) for per-FRF weights; got {w.shape}"
    )


# --------------------------------------------------------------------------- main entry
@limits_blas_threads
def fit_lsfd(
    frf: FRFSet,
    initial_poles: np.ndarray,
    *,
    method: str = "lm",
    band: tuple[float, float] | None = None,
    residual_form: str = "physical",
    per_frf: bool = False,
    max_iter: int = 100,
    ftol: float = 1e-12,
    xtol: float = 1e-10,
    mu0: float | None = None,
    correct_exp_window: bool = True,
    weights: np.ndarray | None = None,
    freq_window_hz: float | np.ndarray | None = None,
    damping_window: float | None = None,
    sdtol: float | None = None,
) -> LSFDResult:
    """Fit global poles, residues and residual terms to an FRF set by nonlinear least squares.

    Parameters
    ----------
    frf : the FRFs (any quantity; the residual basis follows ``frf.quantity``).
    initial_poles : (m,) complex rad/s, Im > 0, Re < 0, as seen in the data (e.g. from LSCE).
    method : "lm" (Levenberg-Marquardt, eq. (9)) or "gn" (Gauss-Newton, eq. (7)).
    band : (lo_hz, hi_hz) lines to use, or None for all.
    residual_form : "physical", "paper" (UR + LR/w^2) or "none"; see :mod:`analysis.modal`.
    per_frf : also fit every (output, reference) FRF alone with its own poles (``result.per_frf``).
    max_iter : iteration cap (reaching it gives status 0 and an :class:`LSFDConvergenceWarning`).
    ftol : stop when the relative decrease of S on an accepted step is <= ftol.
    xtol : stop when ``max_r |d lambda_r| / |lambda_r| <= xtol``.
    mu0 : initial LM damping relative to the diagonal of J^T J (default 1e-3); ignored by GN.
    correct_exp_window : remove ``1/frf.exp_window_tau_s`` from every pole's decay rate.
    weights : (n_freq,) per-line or (n_out, n_ref) per-FRF amplitude weights: S = sum |w e|^2.
    freq_window_hz : frequency trust region, a scalar or (m,) half-widths in Hz: every step is
        projected so that pole r's damped frequency stays within ``freq_window_hz[r]`` of its
        initial value (a bound constraint). A pole that ends on its bound wanted to go
        elsewhere (typically a weak spurious pole drawn to a strong neighbour); see
        :mod:`analysis.pipeline`. None: no bound.
    damping_window : a factor F > 1: every pole's decay rate ``-Re lambda`` is held within
        ``[sigma_0 / F, F sigma_0]`` of its initial value (a bound constraint, with
        ``freq_window_hz`` or alone). A weak mode of a wide band otherwise may be turned into a
        very damped pole that absorbs broadband misfit (leakage, non-modal content). None: no bound.
    sdtol : also stop when the Gauss-Newton step still to go is below ``sdtol`` standard deviations
        of the poles (their covariance from the residual variance ``S / dof``; e.g. 0.01: the
        remaining error is a hundredth of the statistical one). On noisy data this ends the slow
        tail of the iteration that ``ftol`` waits for; noise-free data keep converging to
        round-off. None: ``ftol``/``xtol`` only.

    Returns
    -------
    :class:`LSFDResult`. Non-convergence, divergence of GN, unstable or collapsing poles are
    reported in ``status`` / ``message`` / ``success``, never raised (the messages:
    :mod:`analysis.fit_messages`).

    Examples
    --------
    The FRFs of two modes, fitted from poles 1 Hz off and at the wrong damping:

    >>> import numpy as np
    >>> from analysis import ModalModel, fit_lsfd, synthesize
    >>> from analysis.modal import pole_from_fz
    >>> model = ModalModel(pole_from_fz([40.0, 95.0], [0.01, 0.02]), [[[-20j, 50j]], [[30j, 25j]]],
    ...                    quantity="receptance")
    >>> frf = synthesize(model, np.arange(1.0, 200.0, 0.25))
    >>> res = fit_lsfd(frf, pole_from_fz([41.0, 94.0], [0.015, 0.015]), method="lm")
    >>> res.success, res.message
    (True, 'converged: S at round-off level')
    >>> np.round(res.freq_hz, 6), np.round(res.damping, 6)          # Hz, ratio
    (array([40., 95.]), array([0.01, 0.02]))
    """
    if not isinstance(frf, FRFSet):
        raise TypeError(f"frf must be an analysis.frf.FRFSet; got {type(frf).__name__}")
    method = str(method).lower()
    if method not in METHODS:
        raise ValueError(f"method {method!r} is not one of {METHODS}")
    if residual_form not in RESIDUAL_FORMS:
        raise ValueError(f"residual_form {residual_form!r} is not one of {RESIDUAL_FORMS}")
    if int(max_iter) < 1:
        raise ValueError(f"max_iter must be >= 1; got {max_iter}")
    if not (ftol >= 0 and xtol >= 0):
        raise ValueError(f"ftol and xtol must be >= 0; got ftol={ftol}, xtol={xtol}")
    if sdtol is not None and not sdtol >= 0:
        raise ValueError(f"sdtol must be >= 0 (or None); got {sdtol}")
    if mu0 is not None and not mu0 > 0:
        raise ValueError(f"mu0 must be > 0 (or None for the default); got {mu0}")
    lam0 = _check_poles(initial_poles)
    full_weights = weights
    if band is not None:
        lo, hi = float(band[0]), float(band[1])
        if not lo < hi:
            raise ValueError(f"band must be (lo_hz, hi_hz) with lo < hi; got {band}")
        if weights is not None and np.ndim(weights) == 1:
            sel = (frf.freq_hz >= lo) & (frf.freq_hz <= hi)
            if np.shape(weights)[0] != frf.freq_hz.size:
                raise ValueError(f"per-line weights must have the FRF's {frf.freq_hz.size} lines before the band")
            full_weights = np.asarray(weights)[sel]
        frf = frf.band(lo, hi)
    if np.any(frf.freq_hz <= 0) and residual_form != "none":
        raise ValueError(
            "the band includes f <= 0 Hz where the residual terms are undefined; start the band above 0 Hz"
        )
    if not np.all(np.isfinite(frf.H)):
        raise ValueError("the FRFs contain NaN or infinite values; restrict the band or drop those FRFs")
    n_out, n_ref, N = frf.H.shape
    line_w, frf_w = _check_weights(full_weights, n_out, n_ref, N)
    bounds: tuple | None = _freq_bounds(lam0, freq_window_hz)
    if damping_window is not None:
        F = float(damping_window)
        if not F > 1.0:
            raise ValueError(f"damping_window must be a factor > 1; got {damping_window!r}")
        if bounds is None:
            bounds = (np.full(lam0.size, 1e-6) * lam0.imag, np.full(lam0.size, np.inf))
        sigma0 = -lam0.real
        bounds = (bounds[0], bounds[1], -F * sigma0, -sigma0 / F)
    outcome, prob = _run(frf, lam0, method, residual_form, line_w, frf_w, int(max_iter), ftol, xtol, mu0, bounds,
                         sdtol)
    sub = None
    if per_frf:
        sub = []
        for o in range(n_out):
            for r in range(n_ref):
                coh = None if frf.coherence is None else frf.coherence[o:o + 1, r:r + 1]
                one = replace(frf, H=frf.H[o:o + 1, r:r + 1], outputs=(frf.outputs[o],),
                              references=(frf.references[r],), coherence=coh)
                oc, pb = _run(one, lam0, method, residual_form, line_w, None, int(max_iter), ftol, xtol, mu0,
                              bounds, sdtol)
                sub.append(_result(one, pb, oc, method, residual_form, correct_exp_window, lam0, None))
    return _result(frf, prob, outcome, method, residual_form, correct_exp_window, lam0, sub)


@limits_blas_threads
def lsfd_at_poles(
    frf: FRFSet,
    poles: np.ndarray,
    *,
    band: tuple[float, float] | None = None,
    residual_form: str = "physical",
    weights: np.ndarray | None = None,
    correct_exp_window: bool = True,
    method: str = "lm",
    message: str = STOPS["fixed_poles"][1],
) -> LSFDResult:
    """The LSFD result at fixed ``poles`` (raw, rad/s, as seen in the data): residues and residual
    terms by linear least squares over all FRFs, the weighted S, and the poles' standard deviations
    from the Jacobian of the whole set, as :func:`fit_lsfd` reports them at its optimum. For poles
    found on a compressed problem (:mod:`analysis.compression`): one projection of the whole set
    instead of an iteration over it. ``status`` is :attr:`Status.FIXED_POLES` (a success) when the
    basis has full rank, else :attr:`Status.COLLAPSED`. ``method`` names the iteration that found
    the poles (kept in the result); the other parameters as for :func:`fit_lsfd`."""
    if not isinstance(frf, FRFSet):
        raise TypeError(f"frf must be an analysis.frf.FRFSet; got {type(frf).__name__}")
    if residual_form not in RESIDUAL_FORMS:
        raise ValueError(f"residual_form {residual_form!r} is not one of {RESIDUAL_FORMS}")
    lam0 = _check_poles(poles)
    f = frf.freq_hz
    lo, hi = (float(f[0]), float(f[-1])) if band is None else (float(band[0]), float(band[1]))
    i0, i1 = int(np.searchsorted(f, lo, side="left")), int(np.searchsorted(f, hi, side="right"))
    if i1 - i0 < 2:
        raise ValueError(f"band {lo:g}:{hi:g} Hz holds {max(i1 - i0, 0)} lines; data span {f[0]:.4g}..{f[-1]:.4g} Hz")
    H = frf.H[..., i0:i1]   # a view: no copy of a large set
    if not np.all(np.isfinite(H)):
        raise ValueError("the FRFs contain NaN or infinite values; restrict the band or drop those FRFs")
    n_out, n_ref, N = H.shape
    line_w, frf_w = _check_weights(weights, n_out, n_ref, N)
    prob = ProjectedProblem(frf.omega[i0:i1], H.reshape(n_out * n_ref, N), frf.quantity, residual_form, line_w, frf_w)
    theta = poles_to_theta(lam0)
    ev = prob.evaluate(theta, fast=prob.prefers_gram(lam0.size))
    status, text = (STOPS["fixed_poles"][0], message) if ev.rank_ok else stop("fixed_rank")
    oc = NLSOutcome(theta, ev, [float(ev.S)], 0, 1, status, text)
    return _result(frf, prob, oc, str(method), residual_form, correct_exp_window, lam0, None, band_hz=(f[i0], f[i1 - 1]))


def _freq_bounds(lam0: np.ndarray, freq_window_hz: float | np.ndarray | None
                 ) -> tuple[np.ndarray, np.ndarray] | None:
    """(lo, hi) bounds (rad/s) of each pole's damped frequency, or None."""
    if freq_window_hz is None:
        return None
    w = np.broadcast_to(np.asarray(freq_window_hz, dtype=float), lam0.shape) if np.ndim(freq_window_hz) == 0 \
        else np.asarray(freq_window_hz, dtype=float)
    if w.shape != lam0.shape or not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise ValueError(f"freq_window_hz must be a positive number or {lam0.size} positive numbers (Hz); "
                         f"got {freq_window_hz!r}")
    half = 2 * np.pi * w
    return np.maximum(lam0.imag - half, 1e-6 * lam0.imag), lam0.imag + half


def _run(frf: FRFSet, lam0: np.ndarray, method: str, residual_form: str, line_w: np.ndarray | None,
         frf_w: np.ndarray | None, max_iter: int, ftol: float, xtol: float, mu0: float | None,
         bounds: tuple | None = None, sdtol: float | None = None) -> tuple[NLSOutcome, ProjectedProblem]:
    n_out, n_ref, N = frf.H.shape
    prob = ProjectedProblem(frf.omega, frf.H.reshape(n_out * n_ref, N), frf.quantity, residual_form, line_w, frf_w)
    m = lam0.size
    dof = prob.dof(m)
    if dof <= 0:
        raise ValueError(
            f"{N} lines are too few for {m} modes with residual form {residual_form!r}: "
            f"{2 * N * n_out * n_ref} real equations for {2 * m + n_out * n_ref * prob.n_linear(m)} parameters; "
            "widen the band or use fewer modes"
        )
    theta0 = poles_to_theta(lam0)
    if method == "gn":
        oc = run_gn(prob, theta0, max_iter=max_iter, ftol=ftol, xtol=xtol, bounds=bounds, sdtol=sdtol)
    else:
        oc = run_lm(prob, theta0, max_iter=max_iter, ftol=ftol, xtol=xtol, mu0=mu0, bounds=bounds, sdtol=sdtol)
    if oc.status == Status.MAX_ITER:
        warnings.warn(
            stop("max_iter_warning", method=method, max_iter=max_iter, S=oc.evaluation.S)[1],
            LSFDConvergenceWarning,
            stacklevel=3,
        )
    log.debug("LSFD %s: status %d after %d iterations: %s", method, oc.status, oc.iterations, oc.message)
    return oc, prob


def _result(frf: FRFSet, prob: ProjectedProblem, oc: NLSOutcome, method: str, residual_form: str,
            correct_exp_window: bool, lam0: np.ndarray, sub: list[LSFDResult] | None,
            band_hz: tuple[float, float] | None = None) -> LSFDResult:
    """The result of a fit of ``frf`` (the lines fitted; or the whole set with ``band_hz`` the lines'
    first and last frequency)."""
    n_out, n_ref, _ = frf.H.shape
    m = lam0.size
    ev = oc.evaluation
    poles_raw = theta_to_poles(oc.theta)
    shift = window_pole_shift(frf.exp_window_tau_s) if correct_exp_window else 0.0
    poles = poles_raw + shift
    n_frf = n_out * n_ref
    dof = prob.dof(m)
    real_var = ev.S / dof
    if ev.rank_ok:
        R, T = prob.linear_parameters(ev)
        JtJ, _ = prob.normal_equations(ev)
        finite = np.all(np.isfinite(JtJ)) and np.isfinite(real_var)
        cov = covariance_from_normal(JtJ, real_var) if finite else np.full((2 * m, 2 * m), np.nan)
    else:
        R = np.full((n_frf, m), np.nan + 0j)
        T = np.full((n_frf, prob.n_res), np.nan + 0j)
        cov = np.full((2 * m, 2 * m), np.nan)
    residues = R.reshape(n_out, n_ref, m)
    ur = T[:, 0].reshape(n_out, n_ref) if prob.n_res else None
    lr = T[:, 1].reshape(n_out, n_ref) if prob.n_res else None
    if np.all(np.isfinite(residues)):
        psi, L, ratio = rank_one_split(residues)
    else:
        psi, L, ratio = None, None, np.full(m, np.nan)
    meta = {"fit": "lsfd", "method": method, "status": oc.status, "rank_one_ratio": ratio,
            "exp_window_shift_rad_s": shift}
    model = ModalModel(poles=poles, residues=residues, quantity=frf.quantity, residual_form=residual_form,
                       upper_residual=ur, lower_residual=lr, outputs=frf.outputs, references=frf.references,
                       meta=meta)
    if np.all(np.isfinite(cov)):
        f_std, z_std = fz_std(poles, cov)
    else:
        f_std = z_std = np.full(m, np.nan)
    return LSFDResult(
        poles=poles,
        poles_raw=poles_raw,
        freq_hz=natural_freq_hz(poles),
        damping=damping_ratio(poles),
        damped_freq_hz=damped_freq_hz(poles),
        freq_hz_std=f_std,
        damping_std=z_std,
        model=model,
        mode_shapes=psi,
        participation=L,
        sse=float(ev.S),
        history=[float(s) for s in oc.history],
        iterations=int(oc.iterations),
        nfev=int(oc.nfev),
        status=int(oc.status),
        message=oc.message,
        success=bool(oc.status > 0),
        method=method,
        band=(float(frf.freq_hz[0]), float(frf.freq_hz[-1])) if band_hz is None else
        (float(band_hz[0]), float(band_hz[1])),
        noise_var=float(2.0 * real_var),
        cov_poles=cov,
        per_frf=sub,
        initial_poles=lam0.copy(),
    )


def sorted_by_frequency(result: LSFDResult) -> LSFDResult:
    """The same result with its modes in order of natural frequency (poles, residues, shapes,
    participation, standard deviations, the pole covariance and the initial poles permuted
    alike), so that "mode k" means the same mode in every table, file and plot."""
    order = np.argsort(np.asarray(result.freq_hz, dtype=float), kind="stable")
    if np.array_equal(order, np.arange(order.size)):
        return result
    o2 = np.stack([2 * order, 2 * order + 1], axis=1).ravel()
    model = replace(result.model, poles=np.asarray(result.model.poles)[order],
                    residues=np.asarray(result.model.residues)[..., order])
    meta = dict(model.meta)
    if isinstance(meta.get("rank_one_ratio"), np.ndarray) and meta["rank_one_ratio"].size == order.size:
        meta["rank_one_ratio"] = meta["rank_one_ratio"][order]
    model = replace(model, meta=meta)
    cov = np.asarray(result.cov_poles)
    return replace(
        result, poles=result.poles[order], poles_raw=result.poles_raw[order], freq_hz=result.freq_hz[order],
        damping=result.damping[order], damped_freq_hz=result.damped_freq_hz[order],
        freq_hz_std=result.freq_hz_std[order], damping_std=result.damping_std[order], model=model,
        mode_shapes=None if result.mode_shapes is None else result.mode_shapes[:, order],
        participation=None if result.participation is None else result.participation[order],
        cov_poles=cov[np.ix_(o2, o2)] if cov.shape == (o2.size, o2.size) else cov,
        initial_poles=None if result.initial_poles is None else np.asarray(result.initial_poles)[order]
        if np.asarray(result.initial_poles).size == order.size else result.initial_poles,
    )

