"""Gauss-Newton iteration (the paper's eq. (7)) on the poles of a :class:`ProjectedProblem`.

Each iteration solves the normal equations ``J^T J d = -J^T r`` (Kaufman's variable-projection
Jacobian, column-scaled by ``D = sqrt(diag J^T J)``) and takes the full step. A step that
increases S is not taken: the iteration stops with status ``S_INCREASED`` (the paper: "if
the sum of square errors increases ... the method is not convergent"), keeping the best
poles. Steps that push a pole to ``Re >= 0`` or ``Im <= 0`` stop with ``UNSTABLE``; a
rank-deficient basis (poles collapsed onto each other) stops with ``COLLAPSED``.

Stopping rules (shared with LM, :mod:`analysis._lm`):

* ``FTOL``: ``(S_old - S_new) <= ftol * S_old`` on an accepted step, or the decrease
  predicted by the Gauss-Newton model, ``-g^T d = g^T (J^T J)^-1 g``, is at most
  ``max(ftol, 1e-13) * S`` (a stationary point to within round-off; tested before each step);
* ``XTOL``: ``max_r |d lambda_r| / |lambda_r| <= xtol``;
* ``ROUNDOFF``: ``S <= (1000 eps)^2 ||y||^2`` (noise-free data fitted to round-off);
* ``MAX_ITER``: iteration cap reached (the caller warns).
"""
from __future__ import annotations

import numpy as np

from ._lsfd_kernels import Evaluation, NLSOutcome, ProjectedProblem, solve_scaled, theta_to_poles
from .fit_messages import stop

__all__ = ["run_gn", "check_poles", "relative_step", "roundoff_floor", "theta_box", "project_to_bounds", "freeze_active",
           "pred_tolerance", "stationary_stop", "SWITCH_TO_PRECISE", "PRED_FLOOR"]


def roundoff_floor(problem: ProjectedProblem) -> float:
    """S below which the fit is at round-off level: ``(1000 eps)^2 ||y||^2``."""
    return (1e3 * np.finfo(float).eps) ** 2 * problem.y_norm2


def check_poles(theta: np.ndarray) -> str:
    """Empty string when every pole is stable with positive damped frequency, else a reason."""
    t = np.asarray(theta, dtype=float)
    if t[0::2].max() < 0 and t[1::2].min() > 0 and np.isfinite(t).all():   # the common case, in few passes
        return ""
    lam = theta_to_poles(theta)
    bad = np.flatnonzero(lam.real >= 0)
    if bad.size:
        return f"pole {int(bad[0]) + 1} would become unstable (Re lambda = {lam[bad[0]].real:.4g} rad/s >= 0)"
    bad = np.flatnonzero(lam.imag <= 0)
    if bad.size:
        return f"pole {int(bad[0]) + 1} would reach zero or negative damped frequency"
    if not np.all(np.isfinite(lam)):
        return "poles became non-finite"
    return ""


def theta_box(bounds: tuple | None, n: int) -> tuple[np.ndarray, np.ndarray] | None:
    """(lo, hi) over the whole ``theta`` (n values) from ``bounds``: ``(lo_im, hi_im)`` bounds the
    damped frequencies only; ``(lo_im, hi_im, lo_re, hi_re)`` also the real parts (decay rates).
    None without bounds. The solvers make it once per run."""
    if bounds is None:
        return None
    lo, hi = np.full(n, -np.inf), np.full(n, np.inf)
    lo[1::2], hi[1::2] = bounds[0], bounds[1]
    if len(bounds) == 4:
        lo[0::2], hi[0::2] = bounds[2], bounds[3]
    return lo, hi


def project_to_bounds(theta: np.ndarray, box: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
    """Clip every pole's damped frequency ``Im lambda_r`` (rad/s) into its frequency trust region,
    and with four bounds its real part too (the damping trust region); ``box`` from
    :func:`theta_box`; None returns ``theta`` unchanged (a copy)."""
    t = np.array(theta, dtype=float)
    if box is not None:
        t = np.clip(t, box[0], box[1])
    return t


def freeze_active(theta: np.ndarray, JtJ: np.ndarray, g: np.ndarray,
                  box: tuple[np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray]:
    """Normal equations with the *active* bound coordinates frozen: a damped frequency sitting on
    its bound whose gradient pushes it outwards gets a decoupled unit row/column and zero
    gradient, so the step leaves it where it is and the convergence tests (predicted decrease,
    relative step) see only the free parameters. ``g`` is the gradient ``J^T r`` (the step is
    ``-(J^T J)^-1 g``); ``box`` from :func:`theta_box`. Without bounds the inputs are returned unchanged."""
    if box is None:
        return JtJ, g
    t = np.asarray(theta, dtype=float)
    lo, hi = box
    tol = 1e-12 * np.maximum(np.abs(t), 1.0)
    active = ((t <= lo + tol) & (g > 0)) | ((t >= hi - tol) & (g < 0))
    if not np.any(active):
        return JtJ, g
    idx = np.flatnonzero(active)
    A = np.array(JtJ, dtype=float, copy=True)
    b = np.array(g, dtype=float, copy=True)
    A[idx, :] = 0.0
    A[:, idx] = 0.0
    A[idx, idx] = np.maximum(np.diag(JtJ)[idx], 1e-300)
    b[idx] = 0.0
    return A, b


def relative_step(theta: np.ndarray, d: np.ndarray) -> float:
    """``max_r |d lambda_r| / |lambda_r|``."""
    lam = theta_to_poles(theta)
    dl = theta_to_poles(d)
    return float(np.max(np.abs(dl) / np.abs(lam)))


#: predicted relative decreases of S below this are at round-off level (converged whatever ftol)
PRED_FLOOR = 1e-13

#: relative progress (of S, or of the poles) below which fast evaluations give way to precise ones
SWITCH_TO_PRECISE = 1e-6


def pred_tolerance(problem: ProjectedProblem, n_modes: int, ftol: float, sdtol: float | None) -> tuple[float, int]:
    """``(tol, dof)`` of the predicted-decrease test: the iteration has converged when the decrease
    of S the Gauss-Newton model predicts, ``pred = g^T (J^T J)^-1 g``, is at most ``tol S``.

    ``tol = max(ftol, PRED_FLOOR)``; with ``sdtol`` also ``sdtol^2 / dof``: with the residual variance
    ``S / dof`` the poles' covariance is ``(S / dof) (J^T J)^-1``, so ``pred / (S / dof)`` is the squared
    length of the step still to go measured in standard deviations (Mahalanobis), and the test stops
    once that step is below ``sdtol`` standard deviations (``dof`` from
    :meth:`ProjectedProblem.dof`; the rule is off when ``dof <= 0``)."""
    tol = max(ftol, PRED_FLOOR)
    dof = problem.dof(n_modes)
    if sdtol and dof > 0:
        tol = max(tol, float(sdtol) ** 2 / dof)
    return tol, dof


def stationary_stop(pred: float, S: float, dof: int, ftol: float, sdtol: float | None) -> tuple[int, str]:
    """``(status, message)`` of a verdict of the predicted-decrease test (:func:`pred_tolerance`)."""
    if sdtol and dof > 0 and pred <= float(sdtol) ** 2 * S / dof and pred > max(ftol, PRED_FLOOR) * S:
        return stop("stationary_sd", sd=float(np.sqrt(max(pred, 0.0) * dof / S)))
    return stop("stationary", pred_rel=pred / S)


def convergence_verdict(S: float, floor: float, step: float, xtol: float, rel: float,
                        ftol: float) -> tuple[int, str] | None:
    """The stopping rules after an accepted step: ``(status, message)`` or None to go on.

    S at the round-off floor, relative step <= xtol, or relative decrease of S <= ftol.
    """
    if S <= floor:
        return stop("roundoff")
    if step <= xtol:
        return stop("xtol", step=step)
    if rel <= ftol:
        return stop("ftol", rel=rel)
    return None


def start_iteration(problem: ProjectedProblem, theta0: np.ndarray
                    ) -> tuple[np.ndarray, bool, Evaluation, list[float], float, NLSOutcome | None]:
    """The common start of GN and LM: copy ``theta0``, evaluate once (fast where its cost model says it
    pays, :meth:`ProjectedProblem.prefers_gram`).

    Returns ``(theta, fast, ev, history, floor, early)``; ``early`` is an :class:`NLSOutcome`
    when the start already decides the result (rank-deficient basis, fit at round-off level).
    """
    theta = np.array(theta0, dtype=float)
    fast = problem.prefers_gram(theta.size // 2)
    ev = problem.evaluate(theta, fast=fast)
    history = [ev.S]
    floor = roundoff_floor(problem)
    early: NLSOutcome | None = None
    if not ev.rank_ok:
        early = NLSOutcome(theta, ev, history, 0, 1, *stop("initial_rank", rcond=ev.rcond))
    elif ev.S <= floor:
        early = NLSOutcome(theta, ev, history, 0, 1, *stop("initial_roundoff"))
    return theta, fast, ev, history, floor, early


def run_gn(problem: ProjectedProblem, theta0: np.ndarray, *, max_iter: int, ftol: float, xtol: float,
           bounds: tuple | None = None, sdtol: float | None = None) -> NLSOutcome:
    """Gauss-Newton from ``theta0`` (see the module docstring); never raises on non-convergence.

    ``bounds`` (lo, hi), each (m,) rad/s: every step is projected so that each pole's damped
    frequency stays in its trust region (see :func:`project_to_bounds`). ``sdtol``: also converged
    when the step still to go is below ``sdtol`` standard deviations of the poles (:func:`pred_tolerance`).

    Big problems start with fast evaluations and switch to precise ones when the progress
    falls below ``SWITCH_TO_PRECISE`` or before any verdict (convergence or failure); an evaluation
    that is precise already (a fast request the problem answered precisely) is not repeated.
    """
    theta, fast, ev, history, floor, early = start_iteration(problem, theta0)
    nfev = 1
    if early is not None:
        return early
    verdict = None
    pred_tol, dof = pred_tolerance(problem, theta.size // 2, ftol, sdtol)
    box = theta_box(bounds, theta.size)
    for it in range(1, max_iter + 1):
        if verdict is not None and fast:
            # re-check the verdict with precise evaluations
            fast = False
            verdict = None
            if not ev.precise:
                ev = problem.evaluate(theta)
                nfev += 1
            if not ev.rank_ok:
                return NLSOutcome(theta, ev, history, it - 1, nfev, *stop("collapsed", method="GN", rcond=ev.rcond))
        elif verdict is not None:
            return NLSOutcome(theta, ev, history, it - 1, nfev, *verdict)
        JtJ, g = freeze_active(theta, *problem.normal_equations(ev), box)
        if not (np.isfinite(ev.S) and np.all(np.isfinite(JtJ)) and np.all(np.isfinite(g))):
            return NLSOutcome(theta, ev, history, it - 1, nfev, *stop("non_finite", method="GN"))
        D = np.sqrt(np.diag(JtJ))
        D[D == 0] = 1.0
        d, _ = solve_scaled(JtJ, g, D)
        pred = -float(g @ d)
        if 0.0 <= pred <= pred_tol * ev.S:
            if fast:
                # confirmed with a precise evaluation at the loop top
                verdict = stationary_stop(pred, ev.S, dof, ftol, sdtol)
                history.append(ev.S)
                continue
            return NLSOutcome(theta, ev, history, it - 1, nfev, *stationary_stop(pred, ev.S, dof, ftol, sdtol))
        trial = project_to_bounds(theta + d, box)
        d = trial - theta
        step = relative_step(theta, d)
        reason = check_poles(trial)
        if reason:
            history.append(ev.S)
            verdict = stop("unstable", method="GN", reason=reason)
            continue
        new = problem.evaluate(trial, fast=fast)
        nfev += 1
        if not new.rank_ok:
            history.append(ev.S)
            verdict = stop("collapsed", method="GN", rcond=new.rcond)
            continue
        if new.S > ev.S:
            history.append(ev.S)
            if step <= xtol:
                verdict = stop("xtol_at_floor", step=step)
            else:
                verdict = stop("s_increased", S=ev.S, S_new=new.S, iteration=it)
            continue
        rel = (ev.S - new.S) / ev.S if ev.S > 0 else 0.0
        theta, ev = trial, new
        history.append(ev.S)
        verdict = convergence_verdict(ev.S, floor, step, xtol, rel, ftol)
        if verdict is None and fast and (rel <= SWITCH_TO_PRECISE or step <= SWITCH_TO_PRECISE):
            fast = False
            if not ev.precise:
                ev = problem.evaluate(theta)
                nfev += 1
    if verdict is not None and not fast:
        return NLSOutcome(theta, ev, history, max_iter, nfev, *verdict)
    if verdict is not None:
        # verdict reached on the last iteration with fast evaluations: confirm S precisely
        if not ev.precise:
            ev = problem.evaluate(theta)
            nfev += 1
        if ev.rank_ok:
            return NLSOutcome(theta, ev, history, max_iter, nfev, *verdict)
    return NLSOutcome(theta, ev, history, max_iter, nfev, *stop("max_iter", method="GN", max_iter=max_iter))
