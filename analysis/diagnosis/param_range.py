"""The values of a fitted parameter that fit the measured modes alike: a profile over it, its refinements refitted.

A block's mass and its rotary inertia both lower the modes that move its node; next to a support the node
barely turns apart from translating, and the modes' frequencies and shapes hardly tell a heavier block of less
inertia from a lighter one of more. The fitted mass is then one point of a valley: the range is what the data
say. For the parameter ``name`` of a fitted cause (the mass of ``added_mass``) the profile

    chi2_p(v) = min over the other parameters of chi2(name = v, ...)

holds ``name`` at ``v`` and refits every parameter that ``requires`` it at once (the rotary inertia: its
factor about every axis and each axis' own) with the fit's other free parameters (the choice - the node -
held; each refit starts from the refit at the nearest value tried, with the simulation's exact derivatives
when it has them). The range is the values around the profile's least chi2 within
``within`` of it (:attr:`analysis.diagnosis.rule.DecisionRule.range_chi2`: one standard deviation of one
parameter). The profile walks out from the fitted value in steps of :data:`STEP` (relative) until chi2 rises
above the bound or the parameter's search range ends, and each edge is refined by bisection to :data:`EDGE_TOL`.

A block named beside a second cause (a loose support, a soft joint) has its range from the pair's profile
(:func:`pair_ranges`): at each mass its refinements and every free parameter of the other cause are refitted
with it, so the range says what the data allow with the other change free to take up what it can.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from .physical import (
    CauseSpec,
    MeasuredModes,
    PhysicalFit,
    PhysicalSimulation,
    _fit_continuous,
    modes_jac,
    residuals,
)
from .physical_pairs import PairFit, changes_of

__all__ = ["supported_range", "supported_ranges", "pair_ranges", "refinements_of", "parameters_text", "value_text",
           "RANGE", "STEP", "EDGE_TOL"]

#: a parameter's range is reported beside it as ``<name>_range``: ``[lo, hi]`` in its unit
RANGE = "_range"

#: relative step of the profile's walk out from the fitted value (a log step of the parameter)
STEP = 1.4
#: relative precision of the range's edges (bisection of the last step)
EDGE_TOL = 0.02


def refinements_of(cause: CauseSpec, name: str) -> tuple[str, ...]:
    """The parameters of ``cause`` that ``require`` ``name`` (a mass's rotary inertia)."""
    return tuple(s.name for s in cause.params if s.requires == name)


def supported_range(sim: PhysicalSimulation, cause: CauseSpec, params: Mapping, free: Sequence[str],
                    mm: MeasuredModes, fmax: float, name: str, within: float) -> tuple[float, float]:
    """``(lo, hi)`` of the parameter ``name`` (its unit) whose profile (module docstring) lies within ``within``
    (chi2) of its least value, around the fit ``params`` (free parameters ``free``) of ``cause``; an end of the
    parameter's search range when the profile stays within up to there."""
    specs = {s.name: s for s in cause.params}
    spec = specs[name]
    # every refinement of the parameter free at once, with the fit's other free parameters
    free_rest = tuple(dict.fromkeys([*(n for n in free if n != name), *refinements_of(cause, name)]))
    held = {k: v for k, v in params.items() if k != name}
    #: the refitted parameters at each value tried: a refit starts from those of the nearest value tried
    fitted: dict[float, dict] = {}
    seen: dict[float, float] = {}
    rest = [specs[n] for n in free_rest]
    allsel = np.ones(mm.freq_hz.size, bool)

    def profile(x: float) -> float:
        """chi2_p at the log (or plain) value ``x`` of the parameter, kept."""
        if x not in seen:
            fixed = {k: v for k, v in held.items() if k not in free_rest}
            fixed[name] = spec.from_x(x)
            start = (fitted[min(fitted, key=lambda y: abs(y - x))] if fitted
                     else {n: held.get(n, specs[n].start()) for n in free_rest})
            if rest:
                p, seen[x] = _fit_continuous(sim, cause, rest, fixed, mm, allsel, fmax, start=start)
                fitted[x] = {n: p[n] for n in free_rest}
            else:
                seen[x] = float(np.sum(residuals(mm, *sim.modes(cause.name, fixed, fmax)) ** 2))
        return seen[x]

    a, b = spec.x_bounds
    x0 = spec.to_x(float(params[name]))
    h = float(np.log(STEP)) if spec.log else (STEP - 1.0) * max(abs(x0), 1e-12)
    profile(x0)
    for direction, end in ((-1.0, a), (1.0, b)):
        x = x0
        while (x - end) * direction < 0 and seen[x] <= min(seen.values()) + within:
            x = float(np.clip(x + direction * h, a, b))
            profile(x)
    xs = np.array(sorted(seen))
    cs = np.array([seen[x] for x in xs])
    least = float(cs.min())
    i = int(np.argmin(cs))
    inside = cs <= least + within
    lo_i = i
    while lo_i > 0 and inside[lo_i - 1]:
        lo_i -= 1
    hi_i = i
    while hi_i < xs.size - 1 and inside[hi_i + 1]:
        hi_i += 1
    tol = float(np.log1p(EDGE_TOL)) if spec.log else EDGE_TOL * max(abs(x0), 1e-12)

    def edge(x_in: float, x_out: float) -> float:
        """The edge between a value inside and one outside, by bisection."""
        while abs(x_out - x_in) > tol:
            mid = 0.5 * (x_in + x_out)
            if profile(mid) <= least + within:
                x_in = mid
            else:
                x_out = mid
        return x_in

    lo = edge(float(xs[lo_i]), float(xs[lo_i - 1])) if lo_i > 0 else float(xs[lo_i])
    hi = edge(float(xs[hi_i]), float(xs[hi_i + 1])) if hi_i < xs.size - 1 else float(xs[hi_i])
    return spec.from_x(lo), spec.from_x(hi)


def supported_ranges(sim: PhysicalSimulation, cause: CauseSpec, fit: PhysicalFit, mm: MeasuredModes, fmax: float,
                     within: float) -> dict[str, list[float]]:
    """``{name + RANGE: [lo, hi]}`` (:func:`supported_range`) of each free parameter of ``fit`` that a refinement
    ``requires`` (the mass of ``added_mass``); empty for a cause without refinements."""
    return {f"{n}{RANGE}": [float(v) for v in supported_range(sim, cause, fit.params, fit.free, mm, fmax, n, within)]
            for n in fit.free if refinements_of(cause, n)}


class _Joined:
    """Several causes at once as one cause for :func:`supported_range`: the parameter ``name`` of the ``i``-th
    cause is ``"i.name"`` (its ``requires`` alike), its modes (and their derivatives) are the simulation's with
    every cause's change applied (``modes_of``)."""

    def __init__(self, sim: PhysicalSimulation, specs: Sequence[CauseSpec]) -> None:
        self.sim, self.names = sim, [s.name for s in specs]
        self.spec = CauseSpec("+".join(self.names), tuple(
            replace(p, name=f"{i}.{p.name}", requires=None if p.requires is None else f"{i}.{p.requires}")
            for i, s in enumerate(specs) for p in s.params))

    def joined(self, params: Sequence[Mapping]) -> dict:
        """The causes' parameters (choices included) as the joined cause's."""
        return {f"{i}.{k}": v for i, p in enumerate(params) for k, v in p.items()}

    def split(self, params: Mapping) -> list[tuple[str, dict]]:
        """The joined cause's parameters as the causes' changes ``[(cause, params)]``."""
        out: list[dict] = [{} for _ in self.names]
        for k, v in params.items():
            i, name = k.split(".", 1)
            out[int(i)][name] = v
        return list(zip(self.names, out))

    def modes(self, cause: str | None, params: Mapping, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """The simulation's modes (natural frequencies in Hz, shapes at the measured points) up to
        ``max_freq_hz`` (Hz) with every cause's change of the joined ``params`` applied; ``cause`` is unused (the
        joined cause is the only one)."""
        return changes_of(self.sim, self.split(params), max_freq_hz)

    def modes_jac_of(self, changes: Sequence[tuple[str, Mapping]], max_freq_hz: float,
                     wrt: Sequence[tuple[int, str]]) -> tuple | None:
        """The simulation's modes of the joined change with their derivatives by the joined parameters ``wrt``
        (None when it has none)."""
        ((_, params),) = changes
        moved = [(int(i), name) for i, name in (n.split(".", 1) for _, n in wrt)]
        return modes_jac(self.sim, self.split(params), max_freq_hz, moved)


def pair_ranges(sim: PhysicalSimulation, specs: Sequence[CauseSpec], pair: PairFit, mm: MeasuredModes, fmax: float,
                within: float) -> list[dict[str, list[float]]]:
    """Per cause of the refined ``pair`` (of the causes ``specs``), ``{name + RANGE: [lo, hi]}`` of each of its free
    parameters that a refinement ``requires`` (the mass of ``added_mass``): :func:`supported_range` of the pair as
    one cause, every other free parameter of both causes (and the parameter's refinements) refitted at each value,
    the modes solved up to ``fmax`` (Hz), ``within`` the chi2 above the profile's least (dimensionless); empty dicts
    when no cause has one."""
    out: list[dict[str, list[float]]] = [{} for _ in specs]
    wanted = [(i, n) for i, (s, free) in enumerate(zip(specs, pair.free)) for n in free if refinements_of(s, n)]
    if not wanted:
        return out
    joined = _Joined(sim, specs)
    free = [f"{i}.{n}" for i, names in enumerate(pair.free) for n in names]
    params = joined.joined(pair.params)
    for i, n in wanted:
        lo, hi = supported_range(joined, joined.spec, params, free, mm, fmax, f"{i}.{n}", within)  # type: ignore[arg-type]
        out[i][f"{n}{RANGE}"] = [float(lo), float(hi)]
    return out


def _unit(name: str) -> str:
    """The unit a parameter's name ends with, as shown after its value (" kg", " Hz", " s"; "" for a factor)."""
    return " kg" if name.endswith("_kg") else " Hz" if name.endswith("_hz") else " s" if name.endswith("_s") else ""


def value_text(name: str, v: object) -> str:
    """A parameter as shown: masses in kg, frequencies in Hz, times in s, 4 digits; the rest as it is."""
    return f"{v:.4g}{_unit(name)}" if isinstance(v, float) else str(v)


def parameters_text(params: Mapping) -> str:
    """A cause's parameters in words, ``name = value``, a value with a range (``<name>_range``, the values that fit
    the data alike) followed by it: ``mass_kg = 1.806 kg (0.05-2.6 kg fit the data alike)``; lists and dicts (a
    gain per channel) left out."""
    out = []
    for k, v in params.items():
        if isinstance(v, (list, tuple, dict)):
            continue
        text = f"{k} = {value_text(k, v)}"
        span = params.get(f"{k}{RANGE}")
        if isinstance(v, float) and isinstance(span, (list, tuple)) and len(span) == 2:
            text += f" ({float(span[0]):.2g}-{float(span[1]):.2g}{_unit(k)} fit the data alike)"
        out.append(text)
    return ", ".join(out)
