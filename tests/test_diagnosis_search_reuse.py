"""The pair search asks some fits again: each is made once per measured modes and simulation.

A pair refined on all modes before its variants are widened is refined again, then cross-validated, by the
next stage; a first cause is refitted on top of the same second cause by two stages; a least-squares fit has
two equal starts (a nested variant's fit with its other parameters at their nominal). Each is a function of
its start, so the second time the answer made the first time is taken: the same answer without a new
least-squares call. Noise-free modes of the FE frame (a 1.2 kg mass at top:3 with the supports x 0.28).
"""
from __future__ import annotations

import numpy as np
import pytest
from test_diagnosis_pair_search import _mass_beside_supports
from test_diagnosis_physical import OUTS, REFS, _noise_free_modes

from analysis.diagnosis import physical, physical_pairs
from analysis.diagnosis.physical import PhysicalFit, _fit_continuous, _nominal
from analysis.diagnosis.physical_pairs import fit_pair, refit_on_top
from simulator.physical import FrameVariants

FMAX = 700.0


class _Calls:
    """The least-squares fits a module makes, counted: its calls of ``least_chi2`` (a fit from one start) and the
    folds :class:`~analysis.diagnosis.physical.FoldStart` fits without it."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, module) -> None:
        self.n = 0
        inner = module.least_chi2
        minimum = physical.FoldStart.minimum

        def counted(*args, **kwargs):
            self.n += 1
            return inner(*args, **kwargs)

        def fold(start, k):
            got = minimum(start, k)
            self.n += got is not None
            return got

        monkeypatch.setattr(module, "least_chi2", counted)
        monkeypatch.setattr(physical.FoldStart, "minimum", fold)


def test_a_pair_refined_again_from_the_same_start_takes_the_kept_minimum_and_folds(monkeypatch) -> None:
    """Refined on all modes alone (as before its variants are widened), then refined and cross-validated: only the
    folds are new least squares; asked a third time, with or without a target for the folds, none is."""
    fv, specs, fits, mm = _mass_beside_supports()
    calls = _Calls(monkeypatch, physical_pairs)
    alone = fit_pair(fv, specs, fits, mm, FMAX, folds=False)
    assert calls.n == 1 and alone.cv_per_mode.size == 0
    full = fit_pair(fv, specs, fits, mm, FMAX)
    K = mm.freq_hz.size
    assert calls.n == 1 + K and full.cv_per_mode.size == K
    assert full.chi2 == alone.chi2 and full.params == alone.params
    again = fit_pair(fv, specs, fits, mm, FMAX, folds_below=1.01 * full.chi2_cv)
    stopped = fit_pair(fv, specs, fits, mm, FMAX, folds_below=0.5 * (full.chi2 + full.chi2_cv))
    assert calls.n == 1 + K
    np.testing.assert_array_equal(again.cv_per_mode, full.cv_per_mode)
    assert stopped.cv_per_mode.size == 0 and stopped.chi2 == full.chi2
    # another start is another fit
    moved = [fits[0], PhysicalFit("added_mass", {"point": "top:5", "mass_kg": 1.1}, ("mass_kg",), np.inf)]
    fit_pair(fv, specs, moved, mm, FMAX, folds=False)
    assert calls.n == 2 + K


def test_a_pairs_folds_stopped_early_are_continued_when_asked_for_more(monkeypatch) -> None:
    """Folds stopped at a low target, then asked with none: the folds made are taken, the rest made; the held-out
    chi2 is the one of a pair cross-validated in one go (on fresh modes)."""
    fv, specs, fits, mm = _mass_beside_supports()
    fresh = _mass_beside_supports()[3]
    whole = fit_pair(fv, specs, fits, fresh, FMAX)
    calls = _Calls(monkeypatch, physical_pairs)
    stopped = fit_pair(fv, specs, fits, mm, FMAX, folds_below=0.5 * (whole.chi2 + whole.chi2_cv))
    made = calls.n
    assert stopped.cv_per_mode.size == 0 and 1 < made < 1 + mm.freq_hz.size
    full = fit_pair(fv, specs, fits, mm, FMAX)
    assert calls.n == 1 + mm.freq_hz.size
    np.testing.assert_array_equal(full.cv_per_mode, whole.cv_per_mode)


def test_a_cause_refitted_on_top_of_the_same_change_again_is_not_fitted_again(monkeypatch) -> None:
    """The mass refitted over every node on top of the supports' fit, asked again by another stage: the same fit
    (its node, parameters and ranked options) without a least-squares call; on top of another change it is fitted."""
    fv, specs, fits, mm = _mass_beside_supports()
    calls = _Calls(monkeypatch, physical)
    first = refit_on_top(fv, specs[1], fits[1], fits[0], mm, FMAX)
    made = calls.n
    assert made > 0
    again = refit_on_top(fv, specs[1], fits[1], fits[0], mm, FMAX)
    assert calls.n == made
    assert again.params == first.params and again.chi2 == first.chi2 and again.ranked == first.ranked
    again.params["mass_kg"] = -1.0                    # a caller's copy: the kept fit is not changed through it
    assert refit_on_top(fv, specs[1], fits[1], fits[0], mm, FMAX).params == first.params
    other = PhysicalFit("support_stiffness", {**fits[0].params, "factor_rotational": 0.3}, fits[0].free, np.inf)
    refit_on_top(fv, specs[1], fits[1], other, mm, FMAX)
    assert calls.n > made


def test_a_start_equal_to_an_earlier_one_is_not_fitted_again(monkeypatch) -> None:
    """A nested variant's fit that left the parameter at its nominal starts where the nominal start does: the fit
    with it is the fit without it, with no more least-squares calls."""
    fv = FrameVariants(None, OUTS, REFS)
    spec = {c.name: c for c in fv.causes()}["support_stiffness"]
    mm = _noise_free_modes(fv, [("support_stiffness", {"support": "all", "factor_translational": 1.0,
                                                       "factor_rotational": 0.3})])
    sel = np.ones(mm.freq_hz.size, bool)
    specs = [s for s in spec.params if s.name == "factor_rotational"]
    fixed = {**{k: v for k, v in _nominal(spec).items() if k != "factor_rotational"}, "support": "all"}
    calls = _Calls(monkeypatch, physical)
    plain = _fit_continuous(fv, spec, specs, fixed, mm, sel, FMAX)
    alone = calls.n
    nested = _fit_continuous(fv, spec, specs, fixed, mm, sel, FMAX, also=[{**fixed, "factor_rotational": 1.0}])
    assert calls.n == 2 * alone
    assert nested == plain and plain[0]["factor_rotational"] == pytest.approx(0.3, rel=1e-3)


@pytest.mark.parametrize("node", ["top:3", "left:5"])
def test_a_search_asked_for_its_best_fit_alone_fits_fewer_options_for_the_same_fit(monkeypatch, node) -> None:
    """A mass's node searched when only the best fit is of use (a cause fitted on top of another, ranked by its best):
    the options of the screen's first few whose bound is above the best fit so far are not fitted; the best fit is
    the one of the search that fits them (its node, parameters and chi2)."""
    fv = FrameVariants(None, OUTS, REFS)
    spec = {c.name: c for c in fv.causes()}["added_mass"]
    mm = _noise_free_modes(fv, [("added_mass", {"point": node, "mass_kg": 5.0, "inertia_factor": 6.0})])
    sel = np.ones(mm.freq_hz.size, bool)
    calls = _Calls(monkeypatch, physical)
    p, chi2, ranked = physical.fit_cause(fv, spec, ("mass_kg",), mm, sel, FMAX)
    every = calls.n
    q, chi2_best, fitted = physical.fit_cause(fv, spec, ("mass_kg",), mm, sel, FMAX, best_only=True)
    assert (q, chi2_best) == (p, chi2)
    assert {o for _, o, _ in fitted} < {o for _, o, _ in ranked}
    assert calls.n - every < every
