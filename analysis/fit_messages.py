"""What the fitter says when it stops, in one table: every way the LSFD solvers (:mod:`analysis._gn`,
:mod:`analysis._lm`, :func:`analysis.lsfd.lsfd_at_poles`) end, with its status code
(:class:`analysis._lsfd_kernels.Status`, ``> 0`` is success) and its message, and the automatic fit's
verdict (:class:`analysis.fit_result.FitResult`: "converged", "not converged", "implausible").

A return point names its row and fills in the figures: ``stop("xtol", step=1e-9)`` is
``(Status.XTOL, "converged: relative step 1e-09 <= xtol")``. Units: S in the FRFs' units squared,
steps relative to the poles' size, ``rcond`` the reciprocal condition number of the basis.

>>> from analysis.fit_messages import stop
>>> stop("max_iter", method="LM", max_iter=50)
(0, 'LM reached max_iter=50 without meeting ftol/xtol')
>>> stop("collapsed", method="GN", rcond=1e-17)[1]
'GN stopped: poles collapsed (basis rcond 1e-17)'
"""
from __future__ import annotations

from ._lsfd_kernels import Status

__all__ = ["STOPS", "VERDICTS", "stop", "verdict_message"]

#: every stop of the solvers by status (> 0: converged): name -> message template
_STOPS_BY_STATUS: dict[int, dict[str, str]] = {
    Status.FTOL: {"stationary": "converged: predicted decrease of S {pred_rel:.2g} S <= ftol",
                  "stationary_sd": "converged: the step still to go is {sd:.2g} standard deviations of the poles "
                                   "<= sdtol",
                  "ftol": "converged: relative change of S {rel:.2g} <= ftol"},
    Status.XTOL: {"xtol": "converged: relative step {step:.2g} <= xtol",
                  "xtol_at_floor": "converged: relative step {step:.2g} <= xtol (S at its floor)",
                  "xtol_no_decrease": "converged: relative step {step:.2g} <= xtol (no further decrease of S)"},
    Status.ROUNDOFF: {"roundoff": "converged: S at round-off level",
                      "initial_roundoff": "initial fit already at round-off level"},
    Status.FIXED_POLES: {"fixed_poles": "poles given; residues solved at them",
                         "compressed": "poles from the principal response functions ({inner}); residues of every "
                                       "FRF solved at them"},
    # stopped without converging
    Status.MAX_ITER: {"max_iter": "{method} reached max_iter={max_iter} without meeting ftol/xtol",
                      "max_iter_warning": "LSFD ({method}) stopped at max_iter={max_iter} before converging "
                                          "(S = {S:.6g}); raise max_iter, loosen ftol/xtol or improve the initial "
                                          "poles"},
    Status.S_INCREASED: {"s_increased": "GN step increased S from {S:.6g} to {S_new:.6g} at iteration {iteration}; "
                                        "the method is not converging from these initial poles (try method='lm' or "
                                        "better poles)"},
    Status.UNSTABLE: {"unstable": "{method} stopped: {reason}"},
    Status.COLLAPSED: {"initial_rank": "initial poles give a rank-deficient basis (rcond {rcond:.2g})",
                       "collapsed": "{method} stopped: poles collapsed (basis rcond {rcond:.2g})",
                       "would_collapse": "poles would collapse (basis rcond {rcond:.2g})",
                       "non_finite": "{method} stopped: the fit became non-finite (poles nearly coincide or the "
                                     "basis is ill-conditioned); drop near-duplicate initial poles",
                       "fixed_rank": "the poles' basis is rank deficient"},
    Status.NO_PROGRESS: {"no_progress": "LM could not decrease S (mu reached its ceiling)"},
}

#: every stop of the solvers: name -> (status, message template)
STOPS: dict[str, tuple[int, str]] = {name: (status, template) for status, rows in _STOPS_BY_STATUS.items()
                                     for name, template in rows.items()}

#: the automatic fit's verdict (FitResult.status) -> its message template
VERDICTS: dict[str, str] = {
    "converged": "converged ({lsfd}); {n_modes} mode(s) in {lo:.5g}..{hi:.5g} Hz",
    "not converged": "the LSFD did not converge: {lsfd}",
    "implausible": "the fit converged but is not physically sensible: {problems}",
}


def stop(name: str, **values: object) -> tuple[int, str]:
    """``(status, message)`` of the stop ``name`` of :data:`STOPS` with its figures filled in."""
    status, template = STOPS[name]
    return status, template.format(**values)


def verdict_message(status: str, **values: object) -> str:
    """The message of the automatic fit's verdict ``status`` (:data:`VERDICTS`) with its figures."""
    return VERDICTS[status].format(**values)
