"""The fleet's scatter in a flagged unit's diagnosis: its global cause is every stiffness of the unit scaled alike.

Manufacturing scatter (a few percent of modulus, density, joint and support stiffness) moves every natural
frequency of a unit by nearly one factor: in a fleet of the simulated frame with 2 % scatter the good units'
frequencies spread by about 0.8 % (standard deviation), and beyond each unit's common shift
(:func:`analysis.batch.fleet.pair_modes`) by less than 0.08 % per mode: a unit's scatter is one factor common
to its natural frequencies, which a global cause of the diagnosis takes up beside the unit's defect. The FE
model's global cause ``stiffness_shift`` scales the material's Young's modulus only (the joint and support
springs unchanged), which moves the modes unevenly (on the default frame, a 1 % shift moves its first modes
by up to 0.06 % apart), and its pairs with a local cause are solved in the reduced space of the local cause's
parts and every spring's.

:class:`ScatterSimulation` is the SIM for a fleet's flagged unit: the same simulation and causes, but its
``stiffness_shift`` scales every stiffness of the frame (members and springs) by ``stiffness_factor``, i.e.
every natural frequency by its square root with the mode shapes unchanged: exactly what a common factor of the
fleet's scatter is. The other causes act on the scaled frame as on the nominal one, and a local cause with the
global one is the local cause's own answer (its reduced space, kept by the simulation) scaled exactly. The
global cause is always tried as a second cause on top of a first (``scatter_cause``): a defect's cause fitted
alone takes up part of the unit's scatter where it can (a crack's factor a little lower), so the global cause on
top of it seems to add little, while the two refined together fit the unit to its noise.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from functools import lru_cache
from typing import Any

import numpy as np

__all__ = ["GLOBAL_CAUSE", "LIMIT_STEPS_PER_OCTAVE", "ScatterSimulation", "for_fleet", "solve_limit_hz"]

#: the cause that scales the whole frame in a fleet diagnosis (its parameter ``stiffness_factor``)
GLOBAL_CAUSE = "stiffness_shift"
_DESCRIPTION = ("every stiffness of the unit scaled alike (members and the joint and support springs): every natural "
                "frequency by the square root of the factor, the mode shapes unchanged - a fleet's manufacturing scatter")

Changes = Sequence[tuple[str, Mapping]]

#: Steps per octave of the frequencies a fleet's frame is solved up to (:func:`solve_limit_hz`; 19 % apart): the
#: bands of a fleet's units (1.5 times their highest measured mode) differ by more than the scatter moves a mode, by a
#: mode more or less determined, and a finer grid left every unit its own questions.
LIMIT_STEPS_PER_OCTAVE = 4


@lru_cache(maxsize=4096)
def solve_limit_hz(max_freq_hz: float) -> float:
    """The frequency (Hz) the fleet's frame is solved up to for modes below ``max_freq_hz``: the next step of a log
    grid (:data:`LIMIT_STEPS_PER_OCTAVE`) at or above it. Each flagged unit asks for modes up to its own band (1.5
    times its highest measured mode, which the fleet's scatter moves by about a percent) and, with the global cause,
    up to that band over the frequency factor; solved up to the grid's step and cut at the band, a candidate
    asked by every unit (a screen's grid point) or at nearby factors is one question, kept by the simulation."""
    return float(2.0 ** (np.ceil(np.log2(float(max_freq_hz)) * LIMIT_STEPS_PER_OCTAVE) / LIMIT_STEPS_PER_OCTAVE))


def _below(f_hz: Any, top_hz: float) -> int:
    """How many of the ascending natural frequencies ``f_hz`` (Hz) lie below ``top_hz``: the modes a frame solved up
    to :func:`solve_limit_hz` keeps for the band asked."""
    return int(np.count_nonzero(np.asarray(f_hz) < top_hz))


def _split(changes: Changes) -> tuple[float, list[tuple[str, Mapping]]]:
    """The stiffness factor (-) of the global cause among ``changes`` (1 without it) and the other changes."""
    k = 1.0
    rest = []
    for cause, params in changes:
        if cause == GLOBAL_CAUSE:
            k *= float(params.get("stiffness_factor", 1.0))
        else:
            rest.append((cause, params))
    return k, rest


class ScatterSimulation:
    """A physical simulation (the protocol of :class:`analysis.diagnosis.physical.PhysicalSimulation`) whose
    global cause :data:`GLOBAL_CAUSE` scales every stiffness (module docstring); the other causes, their answers
    and the simulation's other attributes are the wrapped simulation's. ``stiffness_factor``: the global cause's
    factor applied before every candidate's (:meth:`on_top`). A method it cannot answer exactly for the scaled
    frame is not offered (a first pass's bounds); the modes' derivatives (``modes_jac_of``) and a frame with
    changes applied (``on_top``) are offered when the wrapped simulation has them. A model with residual terms is
    refused."""

    #: the cause a unit's scatter takes: tried as a second cause on top of every first
    #: (:func:`analysis.diagnosis.physical_verdict._seconds`)
    scatter_cause = GLOBAL_CAUSE

    def __init__(self, sim: Any, stiffness_factor: float = 1.0) -> None:
        self.simulation = sim
        self.stiffness_factor = float(stiffness_factor)

    def causes(self) -> tuple:
        return tuple(replace(c, description=_DESCRIPTION) if c.name == GLOBAL_CAUSE else c
                     for c in self.simulation.causes())

    def _scale(self, changes: Changes) -> tuple[float, list[tuple[str, Mapping]]]:
        """The frequency factor (-) of ``changes`` on this frame (its own global factor included) and the other
        changes."""
        k, rest = _split(changes)
        return float(np.sqrt(self.stiffness_factor * k)), rest

    def _solved(self, solve: Callable[[list, float], tuple[np.ndarray, np.ndarray]], changes: Changes,
                max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        s, rest = self._scale(changes)
        top = max_freq_hz / s
        f, P = solve(rest, solve_limit_hz(top))
        n = _below(f, top)
        return np.asarray(f)[:n] * s, np.asarray(P)[:, :n]

    def _modes(self, rest: list, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        if not rest:
            return self.simulation.modes(None, {}, max_freq_hz)
        if len(rest) == 1:
            return self.simulation.modes(rest[0][0], rest[0][1], max_freq_hz)
        return self.simulation.modes_of(rest, max_freq_hz)

    def modes(self, cause: str | None, params: Mapping, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """Natural frequencies (Hz) up to ``max_freq_hz`` and shape products of the frame changed by ``cause``."""
        return self._solved(self._modes, [] if cause is None else [(cause, params)], max_freq_hz)

    def modes_of(self, changes: Changes, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`modes` of the frame changed by every ``(cause, params)`` of ``changes``."""
        return self._solved(self._modes, changes, max_freq_hz)

    def _modes_jac_of(self, changes: Changes, max_freq_hz: float, wrt: Sequence[tuple[int, str]]
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """:meth:`modes_of` with the derivatives of the natural frequencies (Hz per unit) and of the shape
        products with respect to the parameters ``wrt`` (``(i, name)`` of ``changes[i]``), as the wrapped
        simulation's ``modes_jac_of``. With ``s`` the frequency factor of the global causes (their stiffness factors
        ``k_i`` multiplied): ``f = s f_rest``, so ``df/dp = s df_rest/dp`` for a parameter of another cause and
        ``df/dk_i = f / (2 k_i)``; the shapes do not move with ``s``. None when the wrapped simulation gives no
        derivatives for the other changes."""
        s, rest = self._scale(changes)
        top = max_freq_hz / s
        at = [j for j, (c, _) in enumerate(changes) if c != GLOBAL_CAUSE]       # changes[at[r]] is rest[r]
        theirs = [(at.index(i), name) for i, name in wrt if changes[i][0] != GLOBAL_CAUSE]
        if theirs:
            got = self.simulation.modes_jac_of(rest, solve_limit_hz(top), theirs)
            if got is None:
                return None
            f0, P, df0, dP0 = got
        else:
            f0, P = self._modes(rest, solve_limit_hz(top))
            df0, dP0 = np.zeros((np.size(f0), 0)), np.zeros((*np.shape(P), 0))
        n = _below(f0, top)
        f0, P, df0, dP0 = np.asarray(f0)[:n], np.asarray(P)[:, :n], np.asarray(df0)[:n], np.asarray(dP0)[:, :n]
        f = f0 * s
        if len(theirs) == len(wrt):               # no parameter of a global cause: the wrapped derivatives, scaled
            return f, P, s * df0, dP0
        df = np.zeros((f.size, len(wrt)))
        dP = np.zeros((*np.shape(P), len(wrt)))
        r = 0
        for j, (i, name) in enumerate(wrt):
            cause, params = changes[i]
            if cause == GLOBAL_CAUSE:
                if name == "stiffness_factor":
                    df[:, j] = f / (2.0 * float(params.get("stiffness_factor", 1.0)))
                continue
            df[:, j] = s * np.asarray(df0)[:, r]
            dP[:, :, j] = np.asarray(dP0)[:, :, r]
            r += 1
        return f, P, df, dP

    def _on_top(self, first: Changes) -> ScatterSimulation:
        """This frame with the changes ``first`` applied as its nominal (``modes_of(changes)`` is this frame's
        ``modes_of(first + changes)``): the global cause's factor carried here, the other changes applied by the
        wrapped simulation's ``on_top`` (its bases built on the changed frame)."""
        k, rest = _split(first)
        return ScatterSimulation(self.simulation.on_top(rest) if rest else self.simulation, self.stiffness_factor * k)

    def model(self, cause: str | None, params: Mapping) -> Any:
        """The pole-residue model of the frame changed by ``cause``."""
        return self.model_of([] if cause is None else [(cause, params)])

    def model_of(self, changes: Changes) -> Any:
        """:meth:`model` of the frame changed by every ``(cause, params)`` of ``changes``."""
        s, rest = self._scale(changes)
        sim = self.simulation
        model = (sim.model(None, {}) if not rest else sim.model(*rest[0]) if len(rest) == 1 else sim.model_of(rest))
        return model if s == 1.0 else scaled_model(model, s)

    def __getattr__(self, name: str) -> Any:
        sim = self.__dict__.get("simulation")
        if sim is None:
            raise AttributeError(name)
        attr = getattr(sim, name)              # AttributeError when the simulation has none
        if name == "exact_modes_of":
            return lambda changes, max_freq_hz: self._solved(attr, changes, max_freq_hz)
        if name == "modes_jac_of":
            return self._modes_jac_of
        if name == "on_top":
            return self._on_top
        if name == "at_points":
            return lambda outputs, references: ScatterSimulation(attr(outputs, references), self.stiffness_factor)
        if callable(attr) and name not in ("points", "refined_model", "converged_below_hz"):
            raise AttributeError(f"{name}: not offered by a fleet's simulation")
        return attr


def scaled_model(model: Any, factor: float) -> Any:
    """``model`` (a :class:`~analysis.modal.ModalModel` of mass-normalised modes) of the frame with every
    stiffness times ``factor**2``: its poles times ``factor`` (damping ratios kept) and its residues as that
    frame's (a receptance residue ``phi phi / (2 j omega_d)`` over the factor, times ``lambda^p`` in the form of
    power p). A model with residual terms is refused (ValueError)."""
    from ..frf import QUANTITY_POWER

    if model.upper_residual is not None or model.lower_residual is not None:
        raise ValueError("a simulation model with residual terms cannot be scaled: give its modes only")
    p = QUANTITY_POWER[model.quantity]
    return replace(model, poles=np.asarray(model.poles) * factor, residues=np.asarray(model.residues) * factor ** (p - 1))


def for_fleet(sim: Any) -> Any:
    """``sim`` as a fleet's flagged unit is diagnosed against (:class:`ScatterSimulation`); ``sim`` itself when
    it is not a physical model (an FRF file's path) or has no :data:`GLOBAL_CAUSE`."""
    if not all(hasattr(sim, a) for a in ("causes", "modes", "model")):
        return sim
    if GLOBAL_CAUSE not in [c.name for c in sim.causes()]:
        return sim
    return ScatterSimulation(sim)
