"""Two physical causes at once: forward selection of a second cause and its nested cross-validation.

A second cause is searched on top of the first (the first cause's change applied with its fitted
parameters, :class:`OnTop`): every other cause is fitted and cross-validated (leave one mode out) by
:func:`analysis.diagnosis.physical.physical_causes` as on the unchanged simulation. The best of them
and the first cause are then refined together (:func:`fit_pair`): both causes' continuous parameters
by least squares (the choices, a node or a member, kept), and the pair's held-out error is measured
with *both* causes refitted in each fold (nested: the first cause never sees the left-out mode either).
The first cause's choice (the node of a mass, a member) was made while the second change was in the data;
it is made again with the second cause applied (:func:`refit_on_top`) before the pair is refined, and
both choices once more where both causes are refined (:func:`rechoose`). A first cause that absorbed the
second change (a mass grown at the wrong node for softer supports) is refined with the second from each
of the options its own fit ranked (:func:`with_options`).
A cause with a choice may be the second cause of its own kind at another place (two loose supports, two
soft joints, two cracks): the second change of it searches only the options the first does not hold
(:func:`besides`). A cause with an option for every place at once (the supports' ``all``) is also fitted at
two of its places together, each with its own factors, from the first cause's fit (:func:`split_places`; a
cause of many options, a crack, split in two near its fit: :func:`split_choice`),
and a pair of it at every place and at one of two places is named as the two places (:func:`as_places`).
The pair is named by the same rule as one cause (significant, adequate), and only when it predicts the
held-out modes better than the first cause alone by at least ``physical_min_gain_db`` and removes at least
``quiet_chi2`` of their chi2 (:func:`analysis.diagnosis.physical_verdict._on_top_enough`).
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from itertools import combinations, product

import numpy as np

from ..modal import ModalModel
from .physical import (
    N_SCREEN,
    CauseSpec,
    FoldStart,
    MeasuredModes,
    PhysicalFit,
    PhysicalSimulation,
    ResidualsWithJacobian,
    _Chi2,
    _Screened,
    _tighten,
    dv_dx,
    fit_cause,
    held_out_reaches,
    kept_fit,
    least_chi2,
    modes_jac,
    residuals,
    variants,
)

__all__ = ["OnTop", "PairFit", "SplitBound", "as_places", "besides", "fit_pair", "held_open", "held_spec", "changes_of",
           "refit_on_top", "rechoose", "split_choice", "splits_in_two", "split_places", "splits", "with_options",
           "pair_starts", "widest", "widened", "at_one_place", "choice_freedom", "choice_penalty",
           "least_choice_freedom"]


def changes_of(sim: PhysicalSimulation, changes: Sequence[tuple[str, Mapping]], fmax: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """Modes of ``sim`` changed by every ``(cause, params)`` of ``changes`` at once (``modes_of``)."""
    return sim.modes_of(list(changes), fmax)


def besides(spec: CauseSpec, taken: Sequence[tuple[str, Mapping]]) -> CauseSpec | None:
    """``spec`` as a further change beside the changes ``taken`` ((cause, params) pairs): itself when none of
    them is this cause; with a choice, the same cause at the options none of them holds (a second loose
    support is another support); None when nothing is left (a cause without a choice, or every option
    taken: a further change of it would only refine the first)."""
    held = [p for c, p in taken if c == spec.name]
    if not held:
        return spec
    if spec.choice is None:
        return None
    used = {str(p.get(spec.choice)) for p in held}
    options = tuple(o for o in spec.options if str(o) not in used)
    return replace(spec, options=options) if options else None


def split_places(spec: CauseSpec, fit: PhysicalFit) -> list[tuple[PhysicalFit, PhysicalFit]]:
    """The cause of ``fit`` at two of its places at once, each with its own factors (two loose supports, two soft
    joints), as pairs to refine: every two places (:attr:`CauseSpec.places`; with ``fit`` at one place, that place
    and each other), both started at ``fit``'s parameters and with its free parameters (from ``fit`` at
    :attr:`CauseSpec.every` that is the same frame). Searched only as a second change on top of the first, the
    other place starts from its nominal while the first, fitted alone, sits between the two factors: what is
    left on top of it is too little to name. Empty for a cause without an option for every place."""
    if spec.every is None or spec.choice is None:
        return []
    own = fit.params.get(spec.choice)
    twos = [(a, b) for a, b in combinations(spec.places, 2) if own == spec.every or own in (a, b)]
    return [tuple(PhysicalFit(cause=fit.cause, params={**fit.params, spec.choice: at}, free=fit.free, chi2=np.inf)
                  for at in two) for two in twos]  # type: ignore[misc]


#: The grid of :func:`split_choice`: each factor at its range's lower end to these powers (a factor of 0.02..2:
#: 0.61, 0.38, 0.14), every two options of one member on it.
SPLIT_POWERS = (0.125, 0.25, 0.5)


def _member(option: str) -> str:
    """The member of an element option ``member:e``."""
    return str(option).rsplit(":", 1)[0]


def splits(spec: CauseSpec) -> bool:
    """Whether :func:`split_choice` searches ``spec`` as two changes of one member: an element's stiffness (a
    choice ``element`` among more than ``N_SCREEN`` options)."""
    return spec.choice == "element" and spec.every is None and len(spec.options) > N_SCREEN


class _SplitGrid:
    """The cause of ``fit`` at the two options ``at`` (its choice ``choice``), its factor ``name`` free at each: the
    simulation :class:`analysis.diagnosis.physical._Chi2` asks for the modes of the pair's two factors ``a``, ``b``."""

    def __init__(self, sim: PhysicalSimulation, fit: PhysicalFit, choice: str, name: str, at: tuple[str, str]) -> None:
        self.sim, self.fit, self.choice, self.name, self.at = sim, fit, choice, name, at

    def modes(self, cause: str | None, params: Mapping, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        two = [(self.fit.cause, {**self.fit.params, self.choice: o, self.name: params[k]}) for o, k in zip(self.at, "ab")]
        return changes_of(self.sim, two, max_freq_hz)


class SplitBound:
    """A lower bound of a split pair's chi2 on all modes over the whole range of both factors (monotone: the grid
    with the range's ends added, cut into cells whose corners bound the frequencies inside, :func:`_chi2_bound`),
    lifted on demand by splitting its lowest cells (:func:`analysis.diagnosis.physical._tighten`). ``make``: gives
    the screened cells when :meth:`below` is first asked (their corners are solved only for a pair the search
    reaches with a target its other tests leave open), in place of ``screened``."""

    def __init__(self, screened: _Screened | None, value: float = -np.inf,
                 make: Callable[[], _Screened] | None = None) -> None:
        self._s, self._value, self._make = screened, value, make

    def below(self, target: float) -> bool:
        """Whether the pair's chi2 on all modes could be below ``target`` (``value`` without cells: a pair refined on
        all modes, its chi2 there; -inf: none known)."""
        if self._make is not None:
            self._s, self._make = self._make(), None
        if self._s is None or self._s.at is None:
            return bool(self._value < target)
        if self._s.bound < target:
            _tighten(self._s.at, self._s, target)
        return bool(self._s.bound < target)


def _split_pairs(spec: CauseSpec, across: bool) -> list[tuple[str, str]]:
    """The two options of every pair :func:`split_choice` puts on its grid: two elements of one member (``across``:
    any two)."""
    return [(a, b) for a, b in combinations(spec.options, 2) if across or _member(a) == _member(b)]


def _cells_bound(at: _Chi2, axis: Sequence[float]) -> float:
    """The least lower bound of ``at``'s chi2 (:meth:`analysis.diagnosis.physical._Chi2.bound`) over the cells of the
    lattice ``axis`` x ``axis`` (search variables of both factors)."""
    return min(at.bound(box) for box in product(zip(axis[:-1], axis[1:]), repeat=2))


def splits_in_two(spec: CauseSpec, fit: PhysicalFit, across: bool = False) -> bool:
    """Whether :func:`split_choice` has pairs for ``fit`` of ``spec``: an element's stiffness (:func:`splits`) fitted
    with one free factor (log, nominal 1) and two options to pair. Known without a solve (a search counts the second
    causes it holds before it makes them)."""
    free = [s for s in spec.params if s.name in fit.free]
    return (splits(spec) and len(free) == 1 and free[0].log and free[0].nominal == 1.0
            and bool(_split_pairs(spec, across)))


def split_choice(sim: PhysicalSimulation, spec: CauseSpec, fit: PhysicalFit, mm: MeasuredModes, fmax: float,
                 across: bool = False, below: float = np.inf) -> list[tuple[SplitBound, PhysicalFit, PhysicalFit]]:
    """The change of ``fit`` as two of its kind on one member (two cracks in one column): an element's
    stiffness (a choice ``element`` among more than ``N_SCREEN`` options ``member:e``, factors: log, nominal 1)
    fitted alone stands for two such changes by one deeper change at one element, often neither of theirs, and a
    second element fitted on top of it explains too little. Pairs to refine: every two elements of one member on a
    grid of their factors (:data:`SPLIT_POWERS`), each at its best grid point, in the order of their least chi2
    there, each with a lower bound of its chi2 on all modes over the whole range of both factors
    (:class:`SplitBound`; none when the factor is not :attr:`ParamSpec.monotone`). The grid only orders the pairs;
    the bound says which could still beat a pair already judged. Two elements of different members are found as a
    second change on top of the first (:func:`besides`); ``across``: every two elements, of one member or not, are
    on the grid too (no single element is named, so the first element fitted alone may sit at neither crack).
    ``below``: only a pair whose chi2 on all modes could come below it is of use (the search's target when it makes
    the pairs; its targets only fall): a pair whose bound over the whole range of both factors is not below it, the
    range as one cell (its four corners, :func:`analysis.diagnosis.physical._chi2_bound`) or as 2 x 2 cells, is left
    out before its grid is solved (its finer cells lie inside those, so its bound could not be below it either; the
    other pairs keep their order, and the corners solved are among their cells'); none when ``below`` is not above 0.
    Returns ``[(bound, first, second)]``; empty for any other cause."""
    if not splits_in_two(spec, fit, across) or below <= 0.0:
        return []
    ps = next(s for s in spec.params if s.name in fit.free)
    name = ps.name
    levels = [ps.lo ** w for w in SPLIT_POWERS]
    two_spec = CauseSpec(f"two {spec.name}", (replace(ps, name="a"), replace(ps, name="b")))
    ends = [ps.to_x(v) for v in sorted({ps.lo, ps.hi, *levels})]
    cells = [tuple(box) for box in product(zip(ends[:-1], ends[1:]), repeat=2)]
    allsel = np.ones(mm.freq_hz.size, bool)
    # before the grid: the whole range as one cell, then as 2 x 2 cells (corners the cells solve anyway)
    coarse = [[ends[0], ends[-1]], [ends[0], ends[len(ends) // 2], ends[-1]]]
    ranked = []
    for a, b in _split_pairs(spec, across):
        at = _Chi2(_SplitGrid(sim, fit, str(spec.choice), name, (a, b)), two_spec,  # type: ignore[arg-type]
                   two_spec.params, {}, mm, allsel, fmax, "")
        if ps.monotone and below < np.inf and any(_cells_bound(at, axis) >= below for axis in coarse):
            continue                # no point of the range can come below ``below``: the pair cannot be of use
        c, fa, fb = min((at.at((ps.to_x(fa), ps.to_x(fb)))[0], fa, fb) for fa, fb in product(levels, levels))

        def screened(at: _Chi2 = at, c: float = c) -> _Screened:     # the cells' bounds, made when first asked
            bounded = [(at.bound(box), box) for box in cells]
            return _Screened(c, "", {}, min(t[0] for t in bounded), bounded, at)

        two = ({**fit.params, spec.choice: a, name: fa}, {**fit.params, spec.choice: b, name: fb})
        ranked.append((c, SplitBound(None, make=screened if ps.monotone else None), two))
    ranked.sort(key=lambda t: t[0])
    return [(bound, *(PhysicalFit(cause=fit.cause, params=p, free=fit.free, chi2=np.inf) for p in two))  # type: ignore[misc]
            for _, bound, two in ranked]


def held_spec(spec: CauseSpec, first: PhysicalFit) -> CauseSpec | None:
    """``spec`` as :func:`held_open` refines it beside ``first`` (at the options ``first`` does not hold,
    :func:`besides`), or None when it holds no pair there: a cause of many options (:func:`splits`) with one log
    factor. Known without a solve."""
    spec2 = besides(spec, [(first.cause, first.params)])
    if spec2 is None or not splits(spec2) or len(spec2.params) != 1 or not spec2.params[0].log:
        return None
    return spec2


def held_open(sim: PhysicalSimulation, specs: Sequence[CauseSpec], first: PhysicalFit, mm: MeasuredModes,
              fmax: float) -> list[tuple[float, PhysicalFit, PhysicalFit]]:
    """A second change of many options (an element's stiffness, :func:`splits`) beside ``first``, its choice held
    open: at every option of ``specs[1]`` the first does not hold (:func:`besides`), both refined together on all
    modes (no cross-validation) from the second's best point of a grid of its factor (:data:`SPLIT_POWERS`). A first
    cause fitted alone at its place (a support) absorbs part of the second change, so the second fitted on top of
    it finds its best option elsewhere (the crack's mirror element, a deeper crack beside the support); refined
    together at every option, both reach the change in the data. Returns ``[(chi2, first, second)]`` at every
    option, the lowest chi2 first; empty when the second is no such cause."""
    spec = held_spec(specs[1], first)
    if spec is None:
        return []
    ps = spec.params[0]
    levels = [ps.lo ** w for w in SPLIT_POWERS]
    out = []
    for option in spec.options:
        starts = [{spec.choice: option, ps.name: v} for v in levels]
        cost = [float(np.sum(residuals(mm, *changes_of(sim, [(first.cause, first.params), (spec.name, q)], fmax)) ** 2))
                for q in starts]
        b = PhysicalFit(cause=spec.name, params=starts[int(np.argmin(cost))], free=(ps.name,), chi2=np.inf)
        two = fit_pair(sim, [specs[0], spec], [first, b], mm, fmax, folds=False)
        out.append((two.chi2, replace(first, params=two.params[0], chi2=two.chi2),
                    replace(b, params=two.params[1], chi2=two.chi2)))
    out.sort(key=lambda t: t[0])
    return out


def as_places(specs: Sequence[CauseSpec], params: Sequence[Mapping]) -> tuple[dict, ...]:
    """A pair of one cause at every place (:attr:`CauseSpec.every`) and at one of exactly two places, as the same
    frame said place by place: that place with the product of the two factors, the other place with the
    factors of every place (the factors multiply). Any other pair: its parameters as they are."""
    out = tuple(dict(p) for p in params)
    spec = specs[0]
    if (len(specs) != 2 or specs[1].name != spec.name or spec.every is None or spec.choice is None
            or len(spec.places) != 2):
        return out
    at = [p.get(spec.choice) for p in out]
    if at.count(spec.every) != 1:
        return out
    i = at.index(spec.every)
    every, one = out[i], out[1 - i]
    other = next(o for o in spec.places if o != one[spec.choice])
    factors = [s.name for s in spec.params]
    both = {**one, **{k: float(one.get(k, 1.0)) * float(every.get(k, 1.0)) for k in factors}}
    rest = {**every, spec.choice: other}
    return (both, rest) if i == 1 else (rest, both)


class OnTop:
    """The simulation ``sim`` with the changes ``first`` applied: every cause is fitted on top of them (a
    cause already among them only at its other options, :func:`besides`)."""

    def __init__(self, sim: PhysicalSimulation, first: Sequence[tuple[str, Mapping]]) -> None:
        self.sim = sim
        self.first = [(c, dict(p)) for c, p in first]
        # the simulation with ``first`` as its nominal, when it offers one (``on_top``: the same modes, solved on
        # bases built on the changed frame), else ``sim`` with ``first`` prepended to every candidate
        on_top = getattr(sim, "on_top", None)
        self._top = on_top(self.first) if on_top is not None else None

    def causes(self) -> Sequence[CauseSpec]:
        return [s for s in (besides(c, self.first) for c in self.sim.causes()) if s is not None]

    def modes(self, cause: str | None, params: Mapping, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        return self.modes_of([] if cause is None else [(cause, params)], max_freq_hz)

    def model(self, cause: str | None, params: Mapping) -> ModalModel:
        more = [] if cause is None else [(cause, params)]
        return self.sim.model_of(self.first + more)

    def modes_of(self, changes: Sequence[tuple[str, Mapping]], max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        if self._top is not None:
            return changes_of(self._top, list(changes), max_freq_hz)
        return changes_of(self.sim, self.first + list(changes), max_freq_hz)

    def modes_jac_of(self, changes: Sequence[tuple[str, Mapping]], max_freq_hz: float,
                     wrt: Sequence[tuple[int, str]]) -> tuple | None:
        """``modes_jac`` of ``sim`` with the first changes applied (the parameters ``wrt`` of ``changes``)."""
        if self._top is not None:
            return modes_jac(self._top, list(changes), max_freq_hz, wrt)
        n = len(self.first)
        return modes_jac(self.sim, self.first + list(changes), max_freq_hz, [(n + i, name) for i, name in wrt])

    def model_of(self, changes: Sequence[tuple[str, Mapping]]) -> ModalModel:
        return self.sim.model_of(self.first + list(changes))


@dataclass
class PairFit:
    """Two causes fitted together: their parameters, chi2 on all modes, nested held-out chi2 per mode,
    parameters at the edge of their range."""

    causes: tuple
    params: tuple
    chi2: float
    cv_per_mode: np.ndarray = field(default_factory=lambda: np.zeros(0))
    at_edge: tuple = ()
    #: per cause, its choice's options searched with the other cause applied ([(chi2, option, params)], best
    #: first; empty for a cause without a choice or not searched again): :func:`rechoose`
    ranked: tuple = ()
    #: per cause, the names of its parameters refined (its free parameters; the choices kept)
    free: tuple = ()

    @property
    def changes(self) -> list[tuple[str, dict]]:
        return list(zip(self.causes, self.params))

    @property
    def chi2_cv(self) -> float:
        return float(np.sum(self.cv_per_mode))


@dataclass
class _Refined:
    """A pair refined on all modes (:func:`fit_pair`): the minimum ``x`` (its search variables), its modes' chi2 there
    (``least``), the held-out chi2 of the folds made so far from there (fold k leaves mode k out)."""

    x: np.ndarray
    least: np.ndarray
    folds: list
    #: the folds' common start at ``x`` (:class:`analysis.diagnosis.physical.FoldStart`), made by the first fold
    start: FoldStart | None = None
    #: the refinement's residuals on all modes (its last point's answers kept: the folds' start is made from there)
    rj: ResidualsWithJacobian | None = None


def _start(x0: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """A start for least squares strictly inside the bounds; a log-factor within rounding of its nominal
    (0) is set to it: the finite-difference step (``diff_step``) is relative to ``|x|``, so a start at
    1e-16 would get a step of 1e-19 (no derivative: the parameter never moves), at 0 an absolute one."""
    x0 = np.where(np.abs(x0) < 1e-9, 0.0, x0)
    return np.clip(x0, lo + 1e-6 * (hi - lo), hi - 1e-6 * (hi - lo))


def fit_pair(sim: PhysicalSimulation, specs: Sequence[CauseSpec], fits: Sequence[PhysicalFit], mm: MeasuredModes,
             fmax: float, folds: bool = True, folds_below: float = np.inf) -> PairFit:
    """Refine the two causes ``fits`` (their free parameters, choices kept) together on all modes, then
    leave each mode out with both refitted from there (nested cross-validation; ``folds`` False, or a held-out
    chi2 that cannot come below ``folds_below`` (:func:`held_out_reaches`, checked before each fold): the
    refinement alone, ``cv_per_mode`` empty). Each fit is :func:`analysis.diagnosis.physical.least_chi2`'s, the folds
    from the refined pair's residuals and Jacobian (:class:`analysis.diagnosis.physical.FoldStart`) where they
    converge."""
    free = [[s for s in spec.params if s.name in fit.free] for spec, fit in zip(specs, fits)]
    flat = [(i, s) for i, ss in enumerate(free) for s in ss]
    lo = np.array([s.x_bounds[0] for _, s in flat])
    hi = np.array([s.x_bounds[1] for _, s in flat])

    def params(x: np.ndarray) -> list[dict]:
        out = [dict(f.params) for f in fits]
        for (i, s), xi in zip(flat, x):
            out[i][s.name] = s.from_x(float(xi))
        return out

    def changes(x: np.ndarray) -> list[tuple[str, dict]]:
        return list(zip([f.cause for f in fits], params(x)))

    def resid(x: np.ndarray, sel: np.ndarray) -> np.ndarray:
        f, P = changes_of(sim, changes(x), fmax)
        return residuals(mm, f, P)[sel].ravel()

    def on(sel: np.ndarray) -> ResidualsWithJacobian:
        return ResidualsWithJacobian(sim, changes, lambda x: changes_of(sim, changes(x), fmax),
                                     [(i, s.name) for i, s in flat], lambda x: dv_dx([s for _, s in flat], x), mm, sel,
                                     fmax, (lo, hi))

    def solve(x0: np.ndarray, rj: ResidualsWithJacobian) -> np.ndarray:
        return least_chi2(rj, [s for _, s in flat], _start(x0, lo, hi), 20 * len(flat))[0]

    K = mm.freq_hz.size
    allsel = np.ones(K, bool)

    def refine() -> _Refined:
        rj = on(allsel)
        x = solve(np.array([s.to_x(float(fits[i].params[s.name])) for i, s in flat]), rj)
        return _Refined(x, np.sum(resid(x, allsel).reshape(K, -1) ** 2, axis=1), [], rj=rj)

    # the same pair from the same start refined before in this search (by another stage, or before its variants
    # were widened): its minimum and the folds made so far are taken from there (each fold starts at the minimum)
    made: _Refined = kept_fit(mm, sim, ("pair", fmax, *((f.cause, tuple(ss), repr(sorted(f.params.items())))
                                                         for f, ss in zip(fits, free))), refine)
    x, least = made.x, made.least
    chi2 = float(np.sum(least))
    cv = np.empty(K if folds and chi2 < folds_below else 0)
    for k in range(cv.size):
        if k == len(made.folds):
            sel = allsel.copy()
            sel[k] = False
            if made.start is None and getattr(sim, "modes_jac_of", None) is not None:
                made.start = FoldStart(made.rj or on(allsel), x, [s for _, s in flat])
            got = made.start.minimum(k) if made.start is not None else None
            held = got[2] if got is not None else resid(solve(x, on(sel)), ~sel)
            made.folds.append(float(np.sum(held ** 2)))
        cv[k] = made.folds[k]
        if held_out_reaches(cv[:k + 1], least[k + 1:], folds_below):
            cv = np.empty(0)            # its held-out chi2 cannot come below ``folds_below``: the folds stop
            break
    p = params(x)
    edge = tuple(f"{fits[i].cause}.{s.name}" for i, s in flat if s.at_edge(float(p[i][s.name])))
    return PairFit(causes=tuple(f.cause for f in fits), params=tuple(p), chi2=chi2, cv_per_mode=cv, at_edge=edge,
                   free=tuple(tuple(s.name for s in ss) for ss in free))


def refit_on_top(sim: PhysicalSimulation, spec: CauseSpec, fit: PhysicalFit, other: PhysicalFit, mm: MeasuredModes,
                 fmax: float, best_only: bool = False) -> PhysicalFit:
    """``fit`` (its cause and free parameters) fitted again on all modes with ``other``'s change applied:
    a choice (node, member, element) is searched over every option again, so a first cause whose choice
    was pulled aside by the second change in the data finds its place. ``fit`` itself when the cause has
    no choice (its parameters are refined with the pair anyway). ``best_only``: the caller takes its best option's
    fit alone, not the options ranked (:func:`analysis.diagnosis.physical.fit_cause`: the same fit, fewer options
    fitted)."""
    beside = besides(spec, [(other.cause, other.params)])
    if spec.choice is None or beside is None:
        return fit

    def refit() -> PhysicalFit:
        top = OnTop(sim, [(other.cause, other.params)])
        p, chi2, ranked = fit_cause(top, beside, fit.free, mm, np.ones(mm.freq_hz.size, bool), fmax,
                                    best_only=best_only)
        return PhysicalFit(cause=fit.cause, params=p, free=fit.free, chi2=chi2, ranked=ranked)

    # the same cause refitted on top of the same change by another stage of the search: the fit made then
    made: PhysicalFit = kept_fit(mm, sim, ("on top", fmax, other.cause, repr(sorted(other.params.items())), beside,
                                           tuple(fit.free), best_only), refit)
    return replace(made, params=dict(made.params), ranked=list(made.ranked))


def rechoose(sim: PhysicalSimulation, specs: Sequence[CauseSpec], fits: Sequence[PhysicalFit], pair: PairFit,
             mm: MeasuredModes, fmax: float) -> PairFit:
    """The refined ``pair`` (of ``fits``) with each cause's choice searched again over every option, the other
    cause applied with the pair's refined parameters: a choice made beside the other cause's first, rougher
    value (a mass's node next to the supports' softening fitted alone) is made again where both are refined.
    When a choice moves, the pair is refined (and cross-validated) again from there and kept if its chi2 on
    all modes is lower. The result carries the options searched (``ranked``): the data separate the
    chosen option from the next only by their chi2 difference."""
    new = [PhysicalFit(cause=f.cause, params=dict(p), free=f.free, chi2=pair.chi2) for f, p in zip(fits, pair.params)]
    ranked: list = [[] for _ in fits]
    moved = False
    for i, spec in enumerate(specs):
        if spec.choice is None:
            continue
        new[i] = refit_on_top(sim, spec, new[i], new[1 - i], mm, fmax)
        ranked[i] = new[i].ranked
        moved |= new[i].params[spec.choice] != pair.params[i][spec.choice]
    out = pair
    if moved:
        again = fit_pair(sim, specs, new, mm, fmax, folds=pair.cv_per_mode.size > 0)
        out = again if again.chi2 < pair.chi2 else pair
    out = _both_choices(sim, specs, fits, out, mm, fmax)
    return PairFit(causes=out.causes, params=out.params, chi2=out.chi2, cv_per_mode=out.cv_per_mode,
                   at_edge=out.at_edge, ranked=tuple(ranked), free=out.free)


def _both_choices(sim: PhysicalSimulation, specs: Sequence[CauseSpec], fits: Sequence[PhysicalFit], pair: PairFit,
                  mm: MeasuredModes, fmax: float) -> PairFit:
    """Two causes that each choose among a few options (at most ``N_SCREEN``: a support, a joint, or all of them):
    every two options refined together (no cross-validation), from the pair's parameters (a cause at another
    option with all its parameters free: the rotational springs alone stood in for every support). One choice made again
    with the other kept (:func:`rechoose`) stays where both sit at every place (each softer everywhere, where only
    one support and one joint are), for neither alone moved does better. The best, when its chi2 on all modes is
    lower, refined and cross-validated again; else ``pair``."""
    if len(specs) != 2 or any(s.choice is None or len(s.options) > N_SCREEN for s in specs):
        return pair
    own = tuple(p[s.choice] for s, p in zip(specs, pair.params))
    best: tuple[float, list[PhysicalFit]] = (pair.chi2, [])
    for at in product(specs[0].options, specs[1].options):
        if at == own or (specs[0].name == specs[1].name and at[0] == at[1]):
            continue
        start = [PhysicalFit(cause=f.cause, params={**p, s.choice: o}, chi2=np.inf,
                             free=f.free if o == p[s.choice] else max(variants(s), key=len, default=f.free))
                 for f, p, s, o in zip(fits, pair.params, specs, at)]
        two = fit_pair(sim, specs, start, mm, fmax, folds=False)
        if two.chi2 < best[0]:
            best = (two.chi2, [replace(f, params=p) for f, p in zip(start, two.params)])
    if not best[1]:
        return pair
    again = fit_pair(sim, specs, best[1], mm, fmax, folds=pair.cv_per_mode.size > 0)
    return again if again.chi2 < pair.chi2 else pair


def with_options(sim: PhysicalSimulation, specs: Sequence[CauseSpec], first: PhysicalFit, second: PhysicalFit,
                 mm: MeasuredModes, fmax: float) -> tuple[PhysicalFit, PhysicalFit, float]:
    """``first``'s choice held open among the options its own fit ranked (``first.ranked``): the pair
    (``first`` at each option, ``second``) refined together on all modes (every continuous parameter of
    both; no cross-validation). A first cause fitted alone absorbs the second change where it can (a
    mass grown at the wrong node for softer supports), so the second cause applied on top of it explains
    nothing; at the right option both are refined to the data. The parameters ``first`` set free were chosen
    at its own option; at another option it is also refined with all of them free (its largest variant): a
    support's rotational springs alone stood in for the supports at once, while the loose support elsewhere
    needs both. ``first`` is refined from its fit and from it with one parameter at a time at its nominal
    (:func:`pair_starts`). Returns ``first``
    at the best option (with the parameters set free there) and ``second``, both with the refined parameters,
    and the pair's chi2 there."""
    best: tuple[PhysicalFit, PhysicalFit, float] = (first, second, np.inf)
    spec = besides(specs[0], [(second.cause, second.params)])
    wide = widest(specs[0], first.free)
    own = first.params.get(specs[0].choice) if specs[0].choice else None
    for _, _, params in first.ranked or [(first.chi2, None, first.params)]:
        if spec is None or (spec.choice is not None and params.get(spec.choice) not in spec.options):
            continue                     # the second change's own place: one change, not two
        elsewhere = own is not None and params.get(specs[0].choice) != own
        for free in dict.fromkeys([first.free, wide] if elsewhere else [first.free]):
            start = dict(params)
            if free != first.free:       # its start at that option with every parameter free, the second applied
                start, _, _ = fit_cause(OnTop(sim, [(second.cause, second.params)]), specs[0], free, mm,
                                        np.ones(mm.freq_hz.size, bool), fmax, options=[params[specs[0].choice]])
            for begin in pair_starts(specs[0], start, free):
                a = PhysicalFit(cause=first.cause, params=begin, free=free, chi2=np.inf)
                two = fit_pair(sim, specs, [a, second], mm, fmax, folds=False)
                if two.chi2 < best[2]:
                    best = (PhysicalFit(cause=first.cause, params=two.params[0], free=free, chi2=two.chi2),
                            PhysicalFit(cause=second.cause, params=two.params[1], free=second.free, chi2=two.chi2),
                            two.chi2)
    return best


def pair_starts(spec: CauseSpec, params: Mapping, free: Sequence[str]) -> list[dict]:
    """Starts for refining a cause fitted alone (``params``) together with a second cause: its own fit, and, when
    it has more than one ``free`` parameter, its fit with each of them in turn at its own start
    (:meth:`ParamSpec.start`: the nominal). Fitted alone, a cause absorbs the other change where it can with one
    parameter: one joint's rotational springs driven towards the x100 edge (rigid) with its translational ones
    off their value stand in for a material a few per cent stiffer. There the rotational springs hardly move
    the modes (any spring far stiffer than the joint is rigid), so a refinement started there stays in that
    basin with the second cause at its nominal; from that parameter's nominal both reach the change in the
    data. The lower chi2 is kept (:func:`with_options`)."""
    starts = [dict(params)]
    if len(free) > 1:
        starts += [{**params, s.name: s.start()} for s in spec.params if s.name in free]
    return [q for k, q in enumerate(starts) if q not in starts[:k]]


def widest(spec: CauseSpec, free: Sequence[str]) -> tuple[str, ...]:
    """The largest nested variant of ``spec`` (:func:`variants`) that holds every parameter of ``free`` (a joint's
    translational factor alone -> both factors); ``free`` itself when none does (a refinement is free)."""
    return max((v for v in variants(spec) if set(free) <= set(v)), key=len, default=tuple(free))


def at_one_place(spec: CauseSpec, params: Mapping) -> bool:
    """Whether ``params`` put ``spec`` at one of its places (:attr:`CauseSpec.places`: one support, one joint), not at
    every place at once: a defect there loses all its springs together, so its variant chosen fitted alone (one spring
    free, the other change in the data) is widened beside a second cause (:func:`widened`). At every place at once the
    cause is the frame's own model of its springs; freed further beside another cause it lets the pair bend to a change
    neither holds (every support twice as stiff with a column's stiffness for two cracks in that column)."""
    return spec.every is not None and spec.choice is not None and params.get(spec.choice) != spec.every


#: The freedom of one continuous parameter in chi2 units: what it removes from the chi2 on all modes of data
#: that do not need it, on average (1), plus one standard deviation of that (the same 2 the pair search counts).
PARAMETER_CHI2 = 2.0


def choice_penalty(spec: CauseSpec) -> float:
    """What a cause's choice adds to a pair's score, in chi2 units: 2 ln(number of options) whatever the option (0
    without a choice), so pairs are compared like for like. What the pair chose, which its test against the first
    cause alone counts, depends on the option (:func:`choice_freedom`)."""
    return 2.0 * float(np.log(max(len(spec.options), 1))) if spec.choice else 0.0


def choice_freedom(spec: CauseSpec, params: Mapping) -> float:
    """What a cause's choice chose, in chi2 units, at the option ``params`` hold: for one place among its options,
    their :func:`choice_penalty`; 0 at :attr:`CauseSpec.every`, the cause at every place at once (all supports
    softened together), which is the cause as the frame's own model has it and chooses no place (0 without a
    choice). A second cause's test against its first cause alone counts it (no fold re-makes the choice)."""
    if not spec.choice or params.get(spec.choice) == spec.every:
        return 0.0
    return choice_penalty(spec)


def least_choice_freedom(spec: CauseSpec) -> float:
    """The least of :func:`choice_freedom` over ``spec``'s options: the bound a pair whose choice may still move
    (:func:`rechoose`) is held to."""
    return min((choice_freedom(spec, {spec.choice: o}) for o in spec.options), default=0.0) if spec.choice else 0.0


def widened(sim: PhysicalSimulation, specs: Sequence[CauseSpec], fits: Sequence[PhysicalFit], mm: MeasuredModes,
            fmax: float) -> list[PhysicalFit]:
    """The pair ``fits`` with each cause at one of its places (:func:`at_one_place`: a loose support, a soft joint) at
    its widest variant's parameters free (:func:`widest`), when refined together on
    all modes that lowers the pair's chi2 by more than :data:`PARAMETER_CHI2` per parameter added; else ``fits``.
    Each variant was chosen fitted with the other change in the data, not in the model: one soft joint fitted alone on
    its translational springs (its rotational ones at nominal) sits between two soft joints, and the other joint
    fitted on top of it on its rotational springs alone; held to those variants the pair explains little, refined
    with both factors of both joints free it reaches the data. Returned with the parameters of that wider refinement
    (the pair is refined and cross-validated from there)."""
    wide = [widest(s, f.free) if at_one_place(s, f.params) else tuple(f.free) for s, f in zip(specs, fits)]
    added = sum(len(w) - len(f.free) for w, f in zip(wide, fits))
    if added == 0:
        return list(fits)
    narrow = fit_pair(sim, specs, fits, mm, fmax, folds=False)
    wider = fit_pair(sim, specs, [replace(f, free=w) for f, w in zip(fits, wide)], mm, fmax, folds=False)
    if narrow.chi2 - wider.chi2 <= PARAMETER_CHI2 * added:
        return list(fits)
    return [replace(f, free=w, params=dict(p)) for f, w, p in zip(fits, wide, wider.params)]
