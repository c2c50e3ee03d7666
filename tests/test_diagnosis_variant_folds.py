"""A cause's nested variants are cross-validated best first.

:func:`analysis.diagnosis.physical._best_of` picks, of a cause's fitted variants, the one with the least held-out
chi2. Each variant's held-out chi2 is bounded from below by its folds done plus each remaining mode's chi2 at its
fit on all modes; the next fold is always the one of the variant with the least bound. The answer is the variant
(and its held-out chi2 per mode) that cross-validating every variant in full would choose, and a variant with a
low chi2 on all modes that predicts the held-out modes badly stops its folds early.

The folds here are a table (the fit of a fold and the residuals are stand-ins), so the order of the folds and
what each variant costs are seen exactly.
"""
from __future__ import annotations

import numpy as np
import pytest

from analysis.diagnosis import physical
from analysis.diagnosis.physical import CauseSpec, MeasuredModes, ParamSpec, PhysicalFit

K = 4


class _Table:
    """Per variant (its free parameters): each mode's chi2 at its fit on all modes (``least``) and held out."""

    def __init__(self, least: dict, held: dict) -> None:
        self.least, self.held = least, held
        self.folds: list[tuple] = []

    def modes(self, cause: str | None, params: dict, max_freq_hz: float) -> tuple:
        return params["tag"], None

    def residuals(self, mm: MeasuredModes, f: tuple, P: None) -> np.ndarray:
        r = np.zeros((K, 2))
        if f[0] == "full":
            r[:, 0] = np.sqrt(self.least[f[1]])
        else:
            _, free, k = f
            r[k, 0] = np.sqrt(self.held[free][k])
        return r

    def fit_cause(self, sim: object, cause: CauseSpec, free: tuple, mm: MeasuredModes, sel: np.ndarray,
                  fmax: float, options: object = None, start: object = None) -> tuple[dict, float, list]:
        k = int(np.flatnonzero(~sel)[0])
        self.folds.append((tuple(free), k))
        return {"tag": ("fold", tuple(free), k)}, 0.0, []


def _run(monkeypatch: pytest.MonkeyPatch, table: _Table, bar: float = np.inf, could_pass: object = None
         ) -> PhysicalFit | None:
    monkeypatch.setattr(physical, "residuals", table.residuals)
    monkeypatch.setattr(physical, "fit_cause", table.fit_cause)
    cause = CauseSpec("toy", (ParamSpec("a", 0.1, 10.0), ParamSpec("b", 0.1, 10.0)))
    mm = MeasuredModes(freq_hz=np.arange(1.0, K + 1.0), freq_std_hz=np.full(K, 0.01),
                       shapes=np.ones((1, K), complex))
    fits = [PhysicalFit(cause="toy", params={"tag": ("full", free), "a": 1.0, "b": 1.0}, free=free, chi2=float(np.sum(table.least[free])))
            for free in table.least]
    return physical._best_of(table, cause, mm, 100.0, fits, bar, could_pass)  # type: ignore[arg-type]


def test_a_variant_that_fits_all_modes_best_but_predicts_them_worst_stops_its_folds_early(monkeypatch) -> None:
    """Two parameters: chi2 10 on all modes, 120 held out; one: 20 and 24. The one-parameter variant is chosen with
    its own held-out chi2, and the two-parameter one stops after its first fold (its bound 30 + 3 x 2.5 is then
    above the other's 24); cross-validated in turn, by their chi2 on all modes, it made all 4 folds."""
    table = _Table({("a", "b"): np.full(K, 2.5), ("a",): np.full(K, 5.0)},
                   {("a", "b"): np.full(K, 30.0), ("a",): np.full(K, 6.0)})
    best = _run(monkeypatch, table)
    assert best is not None and best.free == ("a",)
    assert best.chi2_cv == pytest.approx(24.0) and np.allclose(best.cv_per_mode, 6.0)
    assert [k for free, k in table.folds if free == ("a", "b")] == [0]
    assert [k for free, k in table.folds if free == ("a",)] == list(range(K))


def test_no_variant_below_the_bar_is_none_with_few_folds(monkeypatch) -> None:
    """Every variant's held-out chi2 above ``bar`` (a refinement that must beat the current variant): none, and
    no variant cross-validated past the fold that lifts its bound above the bar."""
    table = _Table({("a", "b"): np.full(K, 2.5), ("a",): np.full(K, 5.0)},
                   {("a", "b"): np.full(K, 30.0), ("a",): np.full(K, 6.0)})
    assert _run(monkeypatch, table, bar=21.0) is None
    assert len(table.folds) <= 3


@pytest.mark.parametrize("seed", range(20))
def test_the_variant_chosen_is_the_one_every_variant_cross_validated_in_full_chooses(monkeypatch, seed) -> None:
    """Random tables (held-out chi2 at least the mode's chi2 at the fit on all modes): the same variant and held-out
    chi2 per mode as the least of every variant's full cross-validation, and no more folds than that costs."""
    rng = np.random.default_rng(seed)
    frees = [("a",), ("b",), ("a", "b")]
    least = {f: rng.uniform(0.0, 20.0, K) for f in frees}
    held = {f: least[f] + rng.exponential(rng.uniform(1.0, 40.0), K) for f in frees}
    table = _Table(least, held)
    best = _run(monkeypatch, table)
    totals = {f: float(np.sum(held[f])) for f in frees}
    want = min(frees, key=lambda f: totals[f])
    assert best is not None and best.free == want
    assert np.allclose(best.cv_per_mode, held[want], rtol=1e-12, atol=0.0)     # the residuals' square roots squared
    assert best.chi2_cv == pytest.approx(totals[want], rel=1e-12)
    assert len(table.folds) <= K * len(frees)
    assert len(set(table.folds)) == len(table.folds)        # no fold made twice


@pytest.mark.parametrize("seed", range(20))
def test_refinements_that_cannot_gain_enough_stop_their_folds_with_the_same_outcome(monkeypatch, seed) -> None:
    """Refinements of a current variant (its held-out chi2 per mode ``current``): the one chosen is kept only when it
    gains the rule's dB over the current one (:func:`analysis.diagnosis.physical.refinement_gain_db`). Asked to stop
    when no refinement can (:func:`analysis.diagnosis.physical.refinement_gain_bound`), the cross-validation keeps the
    same refinement where it is kept, stops where it would not be, and never makes more folds."""
    from analysis.diagnosis.physical import refinement_gain_bound, refinement_gain_db
    from analysis.diagnosis.rule import DEFAULT_RULE

    rng = np.random.default_rng(seed)
    frees = [("a",), ("b",), ("a", "b")]
    least = {f: rng.uniform(0.0, 20.0, K) for f in frees}
    held = {f: least[f] + rng.exponential(rng.uniform(1.0, 40.0), K) for f in frees}
    current = rng.uniform(5.0, 60.0, K)
    full = _Table(least, held)
    chosen = _run(monkeypatch, full)
    kept = chosen is not None and refinement_gain_db(current, chosen.cv_per_mode) >= DEFAULT_RULE.physical_min_gain_db
    table = _Table(least, held)
    got = _run(monkeypatch, table, could_pass=lambda done, rest: refinement_gain_bound(current, done, rest)
               >= DEFAULT_RULE.physical_min_gain_db)
    if kept:
        assert got is not None and chosen is not None and got.free == chosen.free
        assert np.array_equal(got.cv_per_mode, chosen.cv_per_mode)
    else:
        assert got is None or refinement_gain_db(current, got.cv_per_mode) < DEFAULT_RULE.physical_min_gain_db
    assert len(table.folds) <= len(full.folds)


def test_refinements_far_from_the_gain_make_no_fold(monkeypatch) -> None:
    """Refinements whose chi2 on all modes is already above half the current held-out chi2 (3 dB) cannot gain it:
    none, without a fold."""
    from analysis.diagnosis.physical import refinement_gain_bound

    table = _Table({("a", "b"): np.full(K, 2.5), ("a",): np.full(K, 5.0)},
                   {("a", "b"): np.full(K, 30.0), ("a",): np.full(K, 6.0)})
    current = np.full(K, 4.0)                      # 16 held out: a refinement must come to 8, its bound is 10
    assert _run(monkeypatch, table, could_pass=lambda done, rest: refinement_gain_bound(current, done, rest) >= 3.0) is None
    assert table.folds == []
