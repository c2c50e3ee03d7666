"""The pair search spends no solve on an answer it does not use or already has.

Noise-free modes of the FE frame with two cracks at the test's points (as tests/test_diagnosis_pair_search.py).
A split pair's lower bound over both factors (its cells' corners) is solved only when the search asks whether the
pair could still win, and then the same as when it was made with the pair; a fit's start is solved once, however
often it is asked between other points (:meth:`ResidualsWithJacobian.hold`).
"""
from __future__ import annotations

import numpy as np
from shared_frames import frame_variants
from test_diagnosis_pair_search import FMAX, _band_modes, _Counted, _specs
from test_diagnosis_physical import OUTS, REFS

from analysis.diagnosis.physical import PhysicalFit, _cause_residuals
from analysis.diagnosis.physical_pairs import SPLIT_POWERS, split_choice

CRACKS = [("element_stiffness", {"element": "top:2", "factor": 0.8}),
          ("element_stiffness", {"element": "right:5", "factor": 0.9})]


def test_a_split_pairs_bound_is_solved_only_when_asked_and_is_the_same() -> None:
    """Two cracks (top:2 x 0.8, right:5 x 0.9), the element fitted alone at top:2 x 0.3: the pairs of elements of one
    member are made with their grid only (3 x 3 points each); asked whether one could come below a chi2, its cells'
    corners are solved then, and each pair's answer is the one of a search that solves every bound with its pair."""
    fv = frame_variants(None, OUTS, REFS)
    spec = _specs(fv)["element_stiffness"]
    mm = _band_modes(fv, CRACKS)
    fit = PhysicalFit("element_stiffness", {"element": "top:2", "factor": 0.3}, ("factor",), np.inf)
    counted = _Counted(fv)
    pairs = split_choice(counted, spec, fit, mm, FMAX)       # type: ignore[arg-type]
    grid = len(SPLIT_POWERS) ** 2
    assert len(pairs) > 1 and counted.asked == grid * len(pairs)
    targets = (0.0, 1.0, 10.0, 1e9)
    answers = [pairs[0][0].below(t) for t in targets]
    # the 4 x 4 cells' other 16 corners, then at most 12 splits per question, 2 new corners each
    assert grid * len(pairs) < counted.asked <= grid * len(pairs) + 16 + len(targets) * 12 * 2
    again = split_choice(fv, spec, fit, mm, FMAX)
    assert [(a.params, b.params) for _, a, b in again] == [(a.params, b.params) for _, a, b in pairs]
    assert [again[0][0].below(t) for t in targets] == answers
    assert answers[0] is False and answers[-1] is True


def test_a_fits_start_held_is_solved_once_between_other_points() -> None:
    """The element's factor at top:2 on the cracks' modes: its start held, asked again after another point (as least
    squares asks it when the Newton descent leaves the fit to it), gives the same residuals and Jacobian without a
    solve; a point not held is solved again."""
    fv = frame_variants(None, OUTS, REFS)
    spec = _specs(fv)["element_stiffness"]
    mm = _band_modes(fv, CRACKS)
    counted = _Counted(fv)
    free = [s for s in spec.params if s.name == "factor"]

    def full(x: np.ndarray) -> dict:
        return {"element": "top:2", "factor": free[0].from_x(float(x[0]))}

    rj = _cause_residuals(counted, spec, free, full, mm, np.ones(mm.freq_hz.size, bool), FMAX)  # type: ignore[arg-type]
    x0, x1 = np.array([free[0].to_x(0.5)]), np.array([free[0].to_x(0.7)])
    rj.hold(x0)
    r0, J0 = np.array(rj.fun(x0)), np.array(rj.jac(x0))
    assert counted.asked == 1
    rj.fun(x1)
    rj.jac(x1)
    assert counted.asked == 2
    assert np.array_equal(rj.fun(x0), r0) and np.array_equal(rj.jac(x0), J0)
    assert counted.asked == 2
    rj.fun(x1)
    assert counted.asked == 3


def test_a_split_pair_that_cannot_come_below_the_target_is_left_out_before_its_grid() -> None:
    """The two cracks of the first test, every two elements paired (``across``): given the chi2 a pair must come below
    when the pairs are made, a pair whose bound over both factors' whole range (one cell, or 2 x 2 cells) is not below
    it is left out before its grid is solved; those kept are the pairs of the search without it whose bound could
    come below it, in the same order with the same points, and each has the same bound."""
    fv = frame_variants(None, OUTS, REFS)
    spec = _specs(fv)["element_stiffness"]
    mm = _band_modes(fv, CRACKS)
    fit = PhysicalFit("element_stiffness", {"element": "top:2", "factor": 0.3}, ("factor",), np.inf)
    every = split_choice(fv, spec, fit, mm, FMAX, across=True)
    target = 1.0
    counted = _Counted(fv)
    kept = split_choice(counted, spec, fit, mm, FMAX, across=True, below=target)    # type: ignore[arg-type]
    grid = len(SPLIT_POWERS) ** 2
    assert 0 < len(kept) < len(every)
    # the coarse cells' 9 corners for every pair, the rest of the grid for those kept (one grid point is a corner):
    # far fewer than the grid and the 16 further corners of the cells the search would solve for every pair
    assert counted.asked <= 9 * len(every) + (grid - 1) * len(kept) < (grid + 16) * len(every)
    answers = {repr((a.params, b.params)): bound.below(target) for bound, a, b in every}
    got = [(a.params, b.params) for _, a, b in kept]
    assert got == [(a.params, b.params) for _, a, b in every if (a.params, b.params) in got]
    assert all(not could for pair, could in answers.items() if pair not in set(map(repr, got)))
    assert [bound.below(target) for bound, _, _ in kept] == [answers[repr(pair)] for pair in got]
    assert any(bound.below(target) for bound, _, _ in kept)
