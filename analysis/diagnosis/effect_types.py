"""What every effect of the catalogue shares: the entry type, the fitting context, the error."""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from ..errors import EffectError
from ..frf import FRFSet
from ..modal import ModalModel

__all__ = ["Effect", "EffectError", "FitContext", "check_positive", "fit_scalar", "shapes_at_references"]


# --------------------------------------------------------------------------- containers
@dataclass(frozen=True)
class FitContext:
    """What every fitter needs: the measured FRFs, the base model, the line weights and the
    base prediction (synthesised once).

    measured : FRFSet of the measurement (the band to analyse).
    base : the simulation as a :class:`ModalModel` (any quantity; converted to the measured one).
    weights : (n_out, n_ref, n_freq) float >= 0, per-line weights of the squared error.
    sim : FRFSet, the base prediction at the measured lines, in the measured quantity (with ``prior``).
    prior : effects already accepted (a second diagnosis stage fits a further effect on top of them).
    """

    measured: FRFSet
    base: ModalModel
    weights: np.ndarray
    sim: FRFSet
    prior: tuple = ()

    def effects(self, spec: Mapping) -> list:
        """The effects already accepted (``prior``) followed by ``spec``."""
        return [dict(e) for e in self.prior] + [dict(spec)]

    def cost(self, H: np.ndarray, lines: np.ndarray) -> float:
        """Weighted squared error ``sum w |H_meas - H|^2`` over the boolean mask ``lines``."""
        e = self.measured.H[..., lines] - H[..., lines]
        return float(np.sum(self.weights[..., lines] * (e.real ** 2 + e.imag ** 2)))


@dataclass(frozen=True)
class Effect:
    """One catalogue entry: ``apply(container, params) -> container`` and ``fit(ctx, lines) -> params``.

    kind : "modal" (apply takes/returns a ModalModel) or "frf" (an FRFSet).
    primary : name of the parameter a test checks (the effect's physical size).
    needs : meta keys the base model must carry for the effect to be fitted (e.g. shapes).
    applies : optional ``applies(ctx) -> str``, why the effect cannot act on the measured band ("" when
        it can; mains lines need a mains harmonic in the band): a non-empty reason skips the effect.
    advice : what to do when the effect is named (the report's first sentence).
    held_out : optional ``held_out(ctx) -> (before, after) or None``, the effect's own cross-validation
        when interleaved lines cannot test it (single lines at the mains harmonics:
        :func:`analysis.diagnosis.mains.held_out_mains_hum`); None: the default folds.
    """

    name: str
    kind: str
    apply: Callable
    fit: Callable
    primary: str
    description: str
    needs: tuple = ()
    applies: Callable | None = None
    held_out: Callable | None = None
    advice: str = ""


# --------------------------------------------------------------------------- helpers
#: how the diagnosis's ``skipped`` begins the reason of an effect that cannot act on the measured band
#: (:attr:`Effect.applies`)
NOT_APPLICABLE = "not applicable"


def check_positive(name: str, value: Any, what: str) -> float:
    v = float(value)
    if not np.isfinite(v) or v <= 0:
        raise EffectError(f"{what}: parameter {name} must be a positive number, got {value!r}")
    return v


def fit_scalar(cost: Callable[[float], float], grid: np.ndarray) -> float:
    """Minimise a 1-D cost: best grid point, then bounded Brent between its neighbours."""
    vals = np.array([cost(x) for x in grid])
    i = int(np.nanargmin(vals))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    if hi <= lo:
        return float(grid[i])
    res = minimize_scalar(cost, bounds=(lo, hi), method="bounded", options={"xatol": 1e-6 * max(abs(hi), 1e-12)})
    return float(res.x) if res.fun <= vals[i] else float(grid[i])

def driving_point(model: ModalModel) -> tuple[int, int] | None:
    """(output, reference) indices of the model's first driving point (an output with the label of a
    reference: same node and direction); None without one."""
    refs = list(model.references)
    return next(((i, refs.index(o)) for i, o in enumerate(model.outputs) if o in refs), None)


def shapes_at_references(model: ModalModel, phi: np.ndarray) -> np.ndarray | None:
    """Mass-normalised shapes at the references, (n_ref, n_modes): ``meta["reference_shapes"]``, else the
    outputs' rows for references that are outputs; None when a reference has none."""
    given = model.meta.get("reference_shapes")
    if given is not None:
        return np.asarray(given, float)
    outs = list(model.outputs)
    if not all(r in outs for r in model.references):
        return None
    return phi[[outs.index(r) for r in model.references]]
