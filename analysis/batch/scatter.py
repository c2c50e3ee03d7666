"""The fleet's scatter in a flagged unit's diagnosis: the SIM seen at the unit's common frequency factor.

Manufacturing scatter (a few percent of modulus, density, joint and support stiffness) moves every natural
frequency of a unit by nearly one factor: in a fleet of the simulated frame with 2 % scatter the good units'
frequencies spread by about 0.8 % (standard deviation), and beyond each unit's common shift
(:func:`analysis.batch.fleet.pair_modes`) by less than 0.08 % per mode. The diagnosis compares a unit with
the SIM to the model form's accuracy (0.2 %, :data:`analysis.diagnosis.physical.FREQ_FLOOR`); a unit's
scatter is then a discrepancy of its own, beside the defect: a global cause is needed to explain it, and where
the FE model's global causes do not reproduce one common factor exactly (its modulus does not scale the joint
and support springs), a 1-2 % change of a member or an element stands in for it.

The batch knows the scatter: the good (not flagged) units show it. :func:`unit_frequency_factors` gives each
unit's common factor against the SIM's modes (the median frequency ratio of its paired modes: a defect at one
place moves a minority of them, not the median), limited to the range the good units span (their median
+- :data:`SCATTER_LIMIT` robust standard deviations): a unit off beyond the fleet's scatter keeps the excess to be
diagnosed. :class:`ScaledSimulation` is the SIM with every natural frequency times that factor (its stiffness
times the factor squared: the same mode shapes), against which the flagged unit is diagnosed, so that what is
named is what differs beyond the fleet's scatter.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from .fleet import FleetResult, pair_modes, robust_center_spread
from .unit_modes import UnitModes

__all__ = ["SCATTER_LIMIT", "MIN_GOOD_UNITS", "MIN_NORMAL_MODES", "normal_centre", "unit_frequency_factors",
           "modes_below", "ScaledSimulation", "scaled"]

#: a unit's common factor is limited to the good units' median +- this many robust standard deviations (-)
SCATTER_LIMIT = 3.0
#: good units (count) needed to tell the fleet's scatter; fewer: every factor is 1 (the SIM as it is)
MIN_GOOD_UNITS = 5
#: modes (count) a unit's normal group needs for its common factor to be told from its defect's shifts
MIN_NORMAL_MODES = 5


def modes_below(modes: UnitModes, top_hz: float) -> UnitModes:
    """The modes of ``modes`` below ``top_hz`` (Hz): a simulation's where its mesh has converged."""
    keep = np.asarray(modes.freq_hz) < top_hz
    return replace(modes, freq_hz=modes.freq_hz[keep], damping=modes.damping[keep], freq_std_hz=modes.freq_std_hz[keep],
                   damping_std=modes.damping_std[keep], shapes=modes.shapes[:, keep])


def normal_centre(shift: np.ndarray, spread: np.ndarray) -> tuple[float, int]:
    """The centre (-) of the largest group of a unit's modes whose shifts beyond its common shift
    (``shift``, ln ratio per fleet mode, NaN: not judged) agree within :data:`SCATTER_LIMIT` times the fleet's
    spread of each (``spread``, -): the weighted mean of that group, and its size. The modes a defect moved fall
    outside the group; those the scatter alone moved agree with one another to the fleet's spread. (0, 0) when
    no mode is judged."""
    ok = np.flatnonzero(np.isfinite(shift) & np.isfinite(spread) & (spread > 0))
    best: tuple[tuple[int, float], float] = ((0, 0.0), 0.0)
    for j in ok:
        inside = ok[np.abs(shift[ok] - shift[j]) <= SCATTER_LIMIT * (spread[ok] + spread[j])]
        w = 1.0 / spread[inside] ** 2
        centre = float(np.sum(w * shift[inside]) / np.sum(w))
        key = (int(inside.size), -float(np.sum(w * (shift[inside] - centre) ** 2)))
        if key > best[0]:
            best = (key, centre)
    return best[1], best[0][0]


def unit_frequency_factors(sim: UnitModes, reference: UnitModes, fleet: FleetResult, tol: float = 0.05) -> list[float]:
    """Each unit's common frequency factor (-) against the SIM's modes ``sim``, in the order of ``fleet.units``:
    the reference's common shift against the SIM (the median ``ln(f_ref / f_sim)`` over their paired modes,
    :func:`~analysis.batch.fleet.pair_modes` within ``tol``) plus the unit's own against the reference, taken
    over the modes the fleet finds normal in it (:func:`normal_centre` of its shifts beyond its common shift, at
    least :data:`MIN_NORMAL_MODES` of them; fewer: the unit is left at the SIM's frequencies, factor 1), limited
    to the good (not flagged) units' span (median +- :data:`SCATTER_LIMIT` x 1.4826 MAD). Every factor is 1 when
    fewer than :data:`MIN_GOOD_UNITS` good units have one or the reference pairs no SIM mode."""
    n = len(fleet.units)
    c_ref = pair_modes(sim, reference, tol).common_shift
    spread = np.array([m.shift_spread_pct for m in fleet.modes], float) / 100.0
    judged = np.array([m.assessed for m in fleet.modes], bool)
    shifts = np.full(n, np.nan)
    for i, u in enumerate(fleet.units):
        if u.status != "ok" or not np.isfinite(u.common_shift_pct) or u.shift_pct.size != spread.size:
            continue
        centre, size = normal_centre(np.where(judged, u.shift_pct / 100.0, np.nan), spread)
        if size >= MIN_NORMAL_MODES:
            shifts[i] = c_ref + u.common_shift_pct / 100.0 + centre
    good = np.isfinite(shifts) & np.array([u.status == "ok" and not u.flagged for u in fleet.units], bool)
    if not np.isfinite(c_ref) or int(good.sum()) < MIN_GOOD_UNITS:
        return [1.0] * n
    med, spread_c = robust_center_spread(shifts[good])
    lo, hi = med - SCATTER_LIMIT * spread_c, med + SCATTER_LIMIT * spread_c
    return [float(np.exp(np.clip(s, lo, hi))) if np.isfinite(s) else 1.0 for s in shifts]


def _modes_scaled(factor: float, solve: Callable[..., tuple[np.ndarray, np.ndarray]]
                  ) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """``solve(x, max_freq_hz)`` (frequencies in Hz, shape products) of the scaled simulation."""
    def modes(x: Any, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        f, P = solve(x, max_freq_hz / factor)
        return np.asarray(f) * factor, P
    return modes


class ScaledSimulation:
    """A physical simulation (the protocol of :class:`analysis.diagnosis.physical.PhysicalSimulation`) with
    every natural frequency times ``factor`` (-): all its stiffness times ``factor**2``, the mass and the mode
    shapes unchanged. Its causes are the simulation's, acting on the scaled frame; a method it cannot scale
    exactly is not offered (a model with residual terms is refused)."""

    #: methods with a cause and its parameters, or a list of changes, then ``max_freq_hz``: frequencies scaled
    _MODES = ("modes_of", "exact_modes_of")

    def __init__(self, sim: Any, factor: float) -> None:
        if not (np.isfinite(factor) and factor > 0):
            raise ValueError(f"frequency factor {factor!r}: give a finite number > 0")
        self.simulation = sim
        self.factor = float(factor)

    def causes(self) -> Any:
        return self.simulation.causes()

    def modes(self, cause: str | None, params: Mapping, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """Natural frequencies (Hz) up to ``max_freq_hz`` and shape products of ``cause`` on the scaled frame."""
        f, P = self.simulation.modes(cause, params, max_freq_hz / self.factor)
        return np.asarray(f) * self.factor, P

    def model(self, cause: str | None, params: Mapping) -> Any:
        """The simulation's pole-residue model of ``cause`` on the scaled frame."""
        return self._scaled_model(self.simulation.model(cause, params))

    def _scaled_model(self, model: Any) -> Any:
        """``model`` with its poles times the factor (damping ratios kept) and its residues as the stiffer
        frame's: a receptance residue ``phi phi / (2 j omega_d)`` over the factor, times ``lambda^p`` in the
        form of power p."""
        from ..frf import QUANTITY_POWER

        if model.upper_residual is not None or model.lower_residual is not None:
            raise ValueError("a simulation model with residual terms cannot be scaled: give its modes only")
        p = QUANTITY_POWER[model.quantity]
        return replace(model, poles=np.asarray(model.poles) * self.factor,
                       residues=np.asarray(model.residues) * self.factor ** (p - 1))

    def __getattr__(self, name: str) -> Any:
        sim = self.__dict__.get("simulation")
        if sim is None:
            raise AttributeError(name)
        attr = getattr(sim, name)              # AttributeError when the simulation has none
        if name in self._MODES:
            return _modes_scaled(self.factor, attr)
        if name == "model_of":
            return lambda changes: self._scaled_model(attr(changes))
        if name == "refined_model":
            return lambda *a, **k: self._scaled_model(attr(*a, **k))
        if name == "converged_below_hz":
            return lambda *a, **k: float(attr(*a, **k)) * self.factor
        if name == "at_points":
            return lambda outputs, references: ScaledSimulation(attr(outputs, references), self.factor)
        if callable(attr) and name not in ("points",):
            raise AttributeError(f"{name}: not offered by a scaled simulation")
        return attr


def scaled(sim: Any, factor: float) -> Any:
    """``sim`` seen at ``factor`` (:class:`ScaledSimulation`); ``sim`` itself for a factor of 1 or a
    simulation that is not a physical model (an FRF file's path)."""
    if factor == 1.0 or not all(hasattr(sim, a) for a in ("causes", "modes", "model")):
        return sim
    return ScaledSimulation(sim, factor)
