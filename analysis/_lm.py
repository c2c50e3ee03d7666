"""Levenberg-Marquardt iteration (the paper's eq. (9)) on the poles of a :class:`ProjectedProblem`.

Step: ``(J^T J + mu D^2) d = -J^T r`` with Marquardt/More scaling ``D = sqrt(diag J^T J)``
(kept as the running maximum over iterations), i.e. in the scaled variables ``x = D d``
``(M + mu I) x = -D^-1 J^T r`` where ``diag M = 1``: ``mu`` is *relative to the diagonal of
J^T J* and the floor/ceiling below are relative to it too.

mu update (Nielsen 1999, as in Madsen, Nielsen & Tingleff, "Methods for non-linear least
squares problems", 2004):

* gain ratio ``rho = (S - S_new) / (L(0) - L(d))`` with the linear model's predicted decrease
  ``L(0) - L(d) = x^T (mu x - D^-1 J^T r)`` (for ``S = r^T r``);
* accepted when ``S_new < S`` and ``rho > 0``: ``mu <- mu * max(1/3, 1 - (2 rho - 1)^3)``,
  ``nu <- 2``;
* rejected otherwise (a step that increases S is never taken): ``mu <- mu * nu``,
  ``nu <- 2 nu``. Steps that would make a pole unstable (``Re >= 0``), give it a non-positive
  damped frequency, or make the basis rank deficient (poles collapsing) are rejected the
  same way.

Safeguards: ``mu`` never falls below ``MU_MIN = 1e-12`` (no pure GN on a singular M); when
``mu`` exceeds ``MU_MAX = 1e10`` no decrease can be found and the iteration stops with
status ``NO_PROGRESS`` (or ``UNSTABLE``/``COLLAPSED`` when that was why steps failed).
Default initial ``mu0 = 1e-3``. Each attempted step counts as an iteration; the history holds
S after each. Stopping rules as in :mod:`analysis._gn` (``ftol``/``xtol`` tested on accepted
steps; a rejected step below ``xtol`` with ``mu <= 1`` also counts as converged; at every new
point the Gauss-Newton predicted decrease ``g^T (J^T J)^-1 g <= max(ftol, 1e-13) S`` counts as
converged with status ``FTOL``).
"""
from __future__ import annotations

import numpy as np

from ._gn import (
    SWITCH_TO_PRECISE,
    check_poles,
    convergence_verdict,
    freeze_active,
    pred_tolerance,
    project_to_bounds,
    relative_step,
    start_iteration,
    stationary_stop,
    theta_box,
)
from ._lsfd_kernels import Evaluation, NLSOutcome, ProjectedProblem, Status, solve_scaled
from .fit_messages import stop

__all__ = ["run_lm", "MU_MIN", "MU_MAX", "MU0_DEFAULT"]

MU_MIN = 1e-12
MU_MAX = 1e10
MU0_DEFAULT = 1e-3


def _finite(ev: Evaluation, JtJ: np.ndarray, g: np.ndarray) -> bool:
    """Whether S and the normal equations at ``ev`` are finite."""
    return bool(np.isfinite(ev.S) and np.all(np.isfinite(JtJ)) and np.all(np.isfinite(g)))


def _evaluate_trial(problem: ProjectedProblem, trial: np.ndarray, fast: bool) -> tuple[Evaluation | None, str, int]:
    """The evaluation at a trial point (None when a pole would be unstable), the reason it cannot be
    taken ("" when it can) and the status that reason stands for."""
    reason = check_poles(trial)
    if reason:
        return None, reason, Status.UNSTABLE
    new = problem.evaluate(trial, fast=fast)
    if not new.rank_ok:
        status, text = stop("would_collapse", rcond=new.rcond)
        return new, text, status
    return new, "", Status.NO_PROGRESS


def _accepted(new: Evaluation | None, ev: Evaluation, pred: float) -> bool:
    """Whether a trial evaluation ``new`` is taken: full rank, S decreased, positive predicted decrease."""
    return new is not None and new.rank_ok and new.S < ev.S and pred > 0


def _rejected(reason: str, step: float, xtol: float, fast: bool, mu: float, nu: float, fail_status: int,
              fail_reason: str) -> tuple[tuple[int, str] | None, float, float]:
    """After a rejected step (``reason``: why it could not be taken, "" when S did not decrease):
    ``(verdict or None, mu, nu)``. A step below ``xtol`` with ``mu <= 1`` is convergence; a tiny
    step of a fast evaluation is re-checked precisely (an empty verdict message); otherwise mu grows,
    and past ``MU_MAX`` the iteration gives up (with the last ``fail_status``/``fail_reason``)."""
    if not reason and step <= xtol and mu <= 1.0:
        return stop("xtol_no_decrease", step=step), mu, nu
    if fast and not reason and step <= SWITCH_TO_PRECISE:
        return (Status.NO_PROGRESS, ""), mu, nu   # re-evaluated precisely at the top of the loop
    mu, nu = mu * nu, nu * 2.0
    if mu <= MU_MAX:
        return None, mu, nu
    status, msg = stop("no_progress")
    return ((fail_status, msg + ": " + fail_reason) if fail_reason else (status, msg)), mu, nu


def run_lm(problem: ProjectedProblem, theta0: np.ndarray, *, max_iter: int, ftol: float, xtol: float,
           mu0: float | None = None, bounds: tuple | None = None, sdtol: float | None = None) -> NLSOutcome:
    """Levenberg-Marquardt from ``theta0`` (see the module docstring); never raises on non-convergence.

    ``bounds`` (lo, hi), each (m,) rad/s: every trial step is projected so that each pole's damped
    frequency stays in its trust region (:func:`analysis._gn.project_to_bounds`). ``sdtol``: also
    converged when the step still to go is below ``sdtol`` standard deviations of the poles
    (:func:`analysis._gn.pred_tolerance`).

    Big problems start with fast evaluations and switch to precise ones when the progress
    falls below ``SWITCH_TO_PRECISE`` or before any verdict (convergence or failure); an evaluation
    that is precise already (a fast request the problem answered precisely) is not repeated.
    """
    theta, fast, ev, history, floor, early = start_iteration(problem, theta0)
    nfev = 1
    if early is not None:
        return early
    box = theta_box(bounds, theta.size)
    mu = MU0_DEFAULT if mu0 is None else float(mu0)
    mu = min(max(mu, MU_MIN), MU_MAX)
    nu = 2.0
    JtJ, g = freeze_active(theta, *problem.normal_equations(ev), box)
    D = np.sqrt(np.diag(JtJ))
    D[D == 0] = 1.0
    fail_status, fail_reason = Status.NO_PROGRESS, ""
    verdict = None
    check_pred = True
    pred_tol, dof = pred_tolerance(problem, theta.size // 2, ftol, sdtol)

    for it in range(1, max_iter + 1):
        if verdict is not None:
            if not fast:
                return NLSOutcome(theta, ev, history, it - 1, nfev, *verdict)
            # confirm the verdict with precise evaluations
            fast, verdict = False, None
            if not ev.precise:
                ev = problem.evaluate(theta)
                nfev += 1
            JtJ, g = freeze_active(theta, *problem.normal_equations(ev), box)
            check_pred = True
            mu = min(mu, 1.0)
            nu = 2.0
        if not _finite(ev, JtJ, g):
            return NLSOutcome(theta, ev, history, it - 1, nfev, *stop("non_finite", method="LM"))
        if check_pred:
            # Gauss-Newton predicted decrease at a new point: a stationary point to round-off?
            check_pred = False
            d_gn, _ = solve_scaled(JtJ, g, D)
            pred_gn = -float(g @ d_gn)
            if 0.0 <= pred_gn <= pred_tol * ev.S:
                stationary = stationary_stop(pred_gn, ev.S, dof, ftol, sdtol)
                if not fast:
                    return NLSOutcome(theta, ev, history, it - 1, nfev, *stationary)
                history.append(ev.S)
                verdict = stationary
                continue
        d, x = solve_scaled(JtJ, g, D, mu)
        pred = float(x @ (mu * x - g / D))
        trial = project_to_bounds(theta + d, box)
        step = relative_step(theta, trial - theta)
        new, reason, why_status = _evaluate_trial(problem, trial, fast)
        if reason:
            fail_status = why_status
        nfev += int(new is not None)
        if _accepted(new, ev, pred):
            assert new is not None
            rho = (ev.S - new.S) / pred
            rel = (ev.S - new.S) / ev.S
            theta, ev = trial, new
            history.append(ev.S)
            mu = max(mu * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), MU_MIN)
            nu = 2.0
            fail_status, fail_reason = Status.NO_PROGRESS, ""
            verdict = convergence_verdict(ev.S, floor, step, xtol, rel, ftol)
            if verdict is None and fast and min(rel, step) <= SWITCH_TO_PRECISE:
                fast = False
                if not ev.precise:
                    ev = problem.evaluate(theta)
                    nfev += 1
            if verdict is None:
                JtJ, g = freeze_active(theta, *problem.normal_equations(ev), box)
                D = np.maximum(D, np.sqrt(np.diag(JtJ)))
                check_pred = True
            continue
        # rejected step
        history.append(ev.S)
        fail_reason = reason or fail_reason
        verdict, mu, nu = _rejected(reason, step, xtol, fast, mu, nu, fail_status, fail_reason)
    if verdict is not None and fast and not ev.precise:
        ev = problem.evaluate(theta)
        nfev += 1
    if verdict is not None and ev.rank_ok and verdict[1]:
        return NLSOutcome(theta, ev, history, max_iter, nfev, *verdict)
    return NLSOutcome(theta, ev, history, max_iter, nfev, *stop("max_iter", method="LM", max_iter=max_iter))
