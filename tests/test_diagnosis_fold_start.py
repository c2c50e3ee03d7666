"""Leave-one-mode-out folds from the fit on all modes, and fits by Newton steps.

:class:`analysis.diagnosis.physical.FoldStart` keeps a fit's residuals and Jacobian on all modes; each fold's first
step from there is the grouped-deletion formula of least squares (exact for residuals linear in the parameters),
the rest :func:`analysis.diagnosis.physical.descend`'s Newton steps; where those do not converge inside the box the
fold is left to least squares. :func:`analysis.diagnosis.physical.least_chi2` fits the same way from a start
(with at most two parameters).
Checked on a linear problem against the formula, and on the FE frame against the least squares the folds stood in
for, with and without a choice, and where the start lies in a parameter's edge band (the fallback).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares
from test_diagnosis_physical import OUTS, REFS, _noise_free_modes

from analysis.diagnosis import physical
from analysis.diagnosis.physical import FoldStart, ParamSpec, descend, fit_cause, least_chi2
from simulator.physical import FrameVariants

FMAX = 700.0


class _Linear:
    """Residuals ``A x - b`` (two per mode) with their Jacobian, as :class:`ResidualsWithJacobian` gives them; its
    evaluations counted."""

    analytic = True

    def __init__(self, A: np.ndarray, b: np.ndarray) -> None:
        self.A, self.b = A, b
        self.bounds = (np.full(A.shape[1], -50.0), np.full(A.shape[1], 50.0))
        self.calls = 0
        self._x: bytes | None = None

    def fun(self, x: np.ndarray) -> np.ndarray:
        if np.asarray(x, float).tobytes() != self._x:
            self.calls += 1
            self._x = np.asarray(x, float).tobytes()
        return self.A @ x - self.b

    def jac(self, x: np.ndarray) -> np.ndarray:
        self.fun(x)
        return self.A

    def options(self) -> dict:
        return {"jac": self.jac}

    def hold(self, x: np.ndarray) -> None:
        """Nothing to keep: the residuals cost no solve."""


def _specs(n: int) -> list[ParamSpec]:
    return [ParamSpec(f"p{i}", -50.0, 50.0, nominal=0.0, log=False) for i in range(n)]


def test_a_linear_folds_minimum_is_the_grouped_deletion_formula_in_one_step() -> None:
    """Residuals linear in two parameters: each fold's minimum is the formula's, ``r_k + J_k d = (I - H_kk)^-1 r_k``
    held out, reached with one evaluation after the one on all modes."""
    rng = np.random.default_rng(7)
    K = 6
    A, b = rng.normal(size=(2 * K, 2)), rng.normal(size=2 * K)
    rj = _Linear(A, b)
    x_all = np.linalg.lstsq(A, b, rcond=None)[0]
    start = FoldStart(rj, x_all, _specs(2))  # type: ignore[arg-type]
    r = A @ x_all - b
    H = A @ np.linalg.solve(A.T @ A, A.T)
    for k in range(K):
        rows = np.repeat(np.arange(K) != k, 2)
        before = rj.calls
        got = start.minimum(k)
        assert got is not None
        x, chi2, held = got
        x_fold = np.linalg.lstsq(A[rows], b[rows], rcond=None)[0]
        np.testing.assert_allclose(x, x_fold, rtol=1e-9, atol=1e-12)
        assert chi2 == pytest.approx(float(np.sum((A[rows] @ x_fold - b[rows]) ** 2)), rel=1e-9)
        Hkk = H[np.ix_(~rows, ~rows)]
        np.testing.assert_allclose(held, np.linalg.solve(np.eye(2) - Hkk, r[~rows]), rtol=1e-9, atol=1e-12)
        assert rj.calls - before == 1


def test_a_fold_started_in_an_edge_band_is_left_to_least_squares() -> None:
    """A fit on all modes at its range's edge (where the bounds decide): no fold from it by Newton steps."""
    rng = np.random.default_rng(8)
    A, b = rng.normal(size=(8, 1)), rng.normal(size=8)
    rj = _Linear(A, b)
    start = FoldStart(rj, np.array([49.9]), _specs(1))  # type: ignore[arg-type]
    assert start.minimum(0) is None


def test_a_descent_that_would_leave_the_box_is_left_to_least_squares() -> None:
    """The minimum beyond the upper bound: the descent gives up at its first step (out of the box), and
    :func:`least_chi2` gives what bounded least squares gives from the start."""
    A = np.array([[1.0], [2.0], [0.5], [1.5]])
    b = 80.0 * A[:, 0]                                   # unbounded minimum at x = 80, beyond the bound 50
    rj = _Linear(A, b)
    x0 = np.array([0.0])
    assert descend(rj, _specs(1), x0, rj.fun(x0), rj.jac(x0), None, 10) is None  # type: ignore[arg-type]
    x, chi2 = least_chi2(rj, _specs(1), x0, 30)  # type: ignore[arg-type]
    ref = least_squares(lambda y: A @ y - b, x0, bounds=rj.bounds, ftol=physical.FIT_TOL, xtol=physical.FIT_TOL)
    assert x[0] == pytest.approx(ref.x[0], abs=1e-6)
    assert chi2 == pytest.approx(2 * ref.cost, rel=1e-6)


@pytest.fixture(scope="module")
def frame() -> tuple:
    """The FE frame and noise-free modes of two changes, so one cause fitted alone leaves residuals in every fold."""
    fv = FrameVariants(None, OUTS, REFS)
    mm = _noise_free_modes(fv, [("support_stiffness", {"support": "left:0", "factor_translational": 0.3,
                                                       "factor_rotational": 0.3}),
                                ("added_mass", {"point": "top:3", "mass_kg": 1.5})])
    return fv, {c.name: c for c in fv.causes()}, mm


@pytest.mark.parametrize("name, free", [("support_stiffness", ("factor_translational",)),
                                        ("member_stiffness", ("factor",))])
def test_folds_from_the_fit_on_all_modes_hold_out_what_least_squares_holds_out(frame, name, free) -> None:
    """A cause with a choice (each fold searches the fit's best options again): every fold's held-out chi2 as least
    squares refitting it gives it (its tolerance), most of them without least squares."""
    fv, specs, mm = frame
    spec = specs[name]
    K = mm.freq_hz.size
    p, chi2, ranked = fit_cause(fv, spec, free, mm, np.ones(K, bool), FMAX)
    options = [o for _, o, _ in ranked[:physical.N_SCREEN_FOLD]]
    starts = {o: q for _, o, q in ranked}
    folds = physical._folds_of(fv, spec, free, mm, FMAX, options, starts)
    assert folds is not None
    fast = 0
    for k in range(K):
        quick = physical._held_out(fv, spec, free, mm, FMAX, options, starts, k, folds)
        exact = physical._held_out(fv, spec, free, mm, FMAX, options, starts, k)
        assert quick == pytest.approx(exact, rel=2e-3, abs=1e-3)
        fast += sum(folds.start(o).minimum(k) is not None for o in options)
    assert fast >= K                                    # the Newton steps converge in most folds here


def test_a_cause_without_a_choice_is_folded_from_its_fit(frame) -> None:
    """The global stiffness (no choice): each fold from the fit's residuals and Jacobian, as least squares."""
    fv, specs, mm = frame
    spec = specs["stiffness_shift"]
    K = mm.freq_hz.size
    free = ("stiffness_factor",)
    p, chi2, _ = fit_cause(fv, spec, free, mm, np.ones(K, bool), FMAX)
    folds = physical._folds_of(fv, spec, free, mm, FMAX, None, p)
    assert folds is not None and folds.options is None
    for k in range(K):
        assert folds.start(None).minimum(k) is not None
        quick = physical._held_out(fv, spec, free, mm, FMAX, None, p, k, folds)
        exact = physical._held_out(fv, spec, free, mm, FMAX, None, p, k)
        assert quick == pytest.approx(exact, rel=2e-3, abs=1e-3)


def test_a_fit_by_newton_steps_is_the_least_squares_fit_without_least_squares(frame, monkeypatch) -> None:
    """A support's two factors fitted at each option: the same parameters and chi2 as least squares alone gives
    (its tolerance), the fits inside the box made without a least-squares call."""
    fv, specs, mm = frame
    spec = specs["support_stiffness"]
    free = [s for s in spec.params]
    sel = np.ones(mm.freq_hz.size, bool)
    calls: list[int] = []
    inner = physical.least_squares

    def counted(*a, **k):
        calls.append(1)
        return inner(*a, **k)

    monkeypatch.setattr(physical, "least_squares", counted)
    quick = [physical._fit_continuous(fv, spec, free, {"support": o}, mm, sel, FMAX) for o in spec.options]
    newton = len(calls)
    monkeypatch.setattr(physical, "descend", lambda *a, **k: None)
    plain = [physical._fit_continuous(fv, spec, free, {"support": o}, mm, sel, FMAX) for o in spec.options]
    assert newton < len(calls) - newton
    for (p, c), (q, d) in zip(quick, plain):
        assert c == pytest.approx(d, rel=1e-5, abs=1e-6)
        for s in free:
            assert p[s.name] == pytest.approx(q[s.name], rel=1e-3)


def test_a_start_on_its_way_to_a_minimum_found_before_stops_there() -> None:
    """A second start whose Newton step lands on the minimum a first start reached: that minimum, with fewer
    evaluations than descending to it again."""
    A = np.array([[1.0], [2.0], [0.5]])
    b = np.array([1.0, 2.5, 0.2])

    class _Bent(_Linear):
        def fun(self, x: np.ndarray) -> np.ndarray:        # a little curvature of its own: several Newton steps
            return super().fun(x) + 0.05 * np.sin(x[0]) * np.ones(3)

        def jac(self, x: np.ndarray) -> np.ndarray:
            self.fun(x)
            return self.A + 0.05 * np.cos(x[0]) * np.ones((3, 1))

    rj = _Bent(A, b)
    x_a, chi2_a = least_chi2(rj, _specs(1), np.array([0.3]), 30)  # type: ignore[arg-type]
    x0 = np.array([-20.0])
    rj.calls = 0
    alone = least_chi2(rj, _specs(1), x0, 30)  # type: ignore[arg-type]
    again = rj.calls
    rj.calls = 0
    x_b, chi2_b = least_chi2(rj, _specs(1), x0, 30, [(x_a, chi2_a)])  # type: ignore[arg-type]
    assert rj.calls < again
    assert x_b[0] == x_a[0] and chi2_b == chi2_a
    assert alone[0][0] == pytest.approx(x_a[0], abs=1e-6)


def test_a_fit_of_three_parameters_is_left_to_least_squares(monkeypatch) -> None:
    """More parameters than :data:`DESCENT_PARAMETERS`: no Newton descent, least squares from the start."""
    rng = np.random.default_rng(10)
    A, b = rng.normal(size=(10, 3)), rng.normal(size=10)
    rj = _Linear(A, b)
    monkeypatch.setattr(physical, "descend", lambda *a, **k: pytest.fail("descended"))
    x, chi2 = least_chi2(rj, _specs(3), np.zeros(3), 90)  # type: ignore[arg-type]
    np.testing.assert_allclose(x, np.linalg.lstsq(A, b, rcond=None)[0], atol=1e-5)
