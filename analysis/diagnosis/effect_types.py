"""What every effect of the catalogue shares: the entry type, the fitting context, the error."""
from __future__ import annotations

import copy
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from ..errors import EffectError
from ..frf import FRFSet, convert_quantity
from ..modal import ModalModel, pole_from_fz

__all__ = ["Effect", "EffectError", "FitContext", "ParamRange", "check_positive", "fit_scalar", "mode_residuals",
           "shapes_at_references", "applied", "named", "split", "stage_entry"]


# --------------------------------------------------------------------------- the two shapes of an effect
# An effect is *applied* as one flat dict ``{"effect": name, **parameters}`` (what :func:`predict` and the
# simulator take) and *named* as ``{"effect": name, "parameters": {...}}`` (what a diagnosis reports: its
# causes, ``named``, ``combined``). These four functions are the only conversions between them.


def applied(cause: Mapping) -> dict:
    """The applied form ``{"effect": name, **parameters}`` of a named cause (any dict with ``effect`` and
    ``parameters``)."""
    return {"effect": cause["effect"], **cause["parameters"]}


def split(spec: Mapping) -> tuple[str, dict]:
    """(name, parameters) of an applied effect ``{"effect": name, **parameters}``."""
    return spec["effect"], {k: v for k, v in spec.items() if k != "effect"}


def named(cause: Mapping) -> dict:
    """The named form ``{"effect", "parameters"}`` of a cause (any dict with those keys, and more)."""
    return {"effect": cause["effect"], "parameters": cause["parameters"]}


def stage_entry(cause: Mapping, error_after_db: float | None = None) -> dict:
    """A cause as a stage of ``Diagnosis.combined``: its named form, held-out gain and the FRF error after it
    (dB; default the cause's own ``error_after_db``)."""
    return {**named(cause), "gain_db": cause["gain_db"],
            "error_after_db": cause["error_after_db"] if error_after_db is None else error_after_db}


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
    #: fits already made in this context (:meth:`remembered`), not part of its value
    _memo: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def remembered(self, key: tuple, fit: Callable[[], dict]) -> dict:
        """``fit()`` made once per context and ``key`` (e.g. an effect's name and the lines' bytes: one effect's
        fit on the same lines asked by two effects); each caller gets its own copy of the parameters."""
        if key not in self._memo:
            self._memo[key] = fit()
        return copy.deepcopy(self._memo[key])

    def effects(self, spec: Mapping) -> list:
        """The effects already accepted (``prior``) followed by ``spec``."""
        return [dict(e) for e in self.prior] + [dict(spec)]

    def cost(self, H: np.ndarray, lines: np.ndarray) -> float:
        """Weighted squared error ``sum w |H_meas - H|^2`` over the boolean mask ``lines``."""
        e = self.measured.H[..., lines] - H[..., lines]
        return float(np.sum(self.weights[..., lines] * (e.real ** 2 + e.imag ** 2)))


@dataclass(frozen=True)
class ParamRange:
    """The physical range of a fitted parameter: ``lo``..``hi`` in the parameter's unit, or, with
    ``band_relative``, ``band_lo * lo``..``band_hi * hi`` (Hz) of the analysed band. ``rtol``: a value within
    this relative distance of an end is at the edge (the fit stopped there). A dict parameter (a gain per
    channel) is at the edge when any of its values' magnitudes is. ``label``: the parameter in words."""

    name: str
    lo: float
    hi: float
    label: str
    rtol: float = 1e-3
    band_relative: bool = False

    def bounds(self, band_hz: tuple[float, float] | None) -> tuple[float, float] | None:
        """(lo, hi) in the parameter's unit; None for a band-relative range without a band."""
        if not self.band_relative:
            return self.lo, self.hi
        return None if band_hz is None else (band_hz[0] * self.lo, band_hz[1] * self.hi)

    def at_edge(self, params: Mapping, band_hz: tuple[float, float] | None = None) -> bool:
        """Does the fitted ``params[name]`` stop at an end of the range?"""
        b = self.bounds(band_hz)
        if b is None or self.name not in params:
            return False
        v = params[self.name]
        vals = np.abs(np.asarray(list(v.values()), float)) if isinstance(v, Mapping) else np.asarray([v], float)
        lo, hi = b
        return bool(vals.size and (np.any(vals >= hi * (1 - self.rtol)) or np.any(vals <= lo * (1 + self.rtol))))


#: The levels of the diagnosis' rows: an FRF-level effect of the catalogue (fitted to the FRFs' lines), a
#: physical cause (the FE model changed, fitted to the modes), a time-data effect (the hits).
LEVELS = ("frf", "physical", "time")


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
    ranges : the physical ranges of its fitted parameters (:class:`ParamRange`); a fit that stops at an
        edge is not evidence of the effect (the ``range_edge`` veto).
    level : "frf" for the catalogue (:data:`LEVELS`).
    moves_every_mode : the effect moves every mode alike, those far outside the band too (a stiffness
        scaling, a mass at every sensor): its coarse cost thins the lines instead of fixing far modes.
    covered_by_physical : the effect is the FRF-level form of a physical cause of the same name: with an FE
        model, ``"always"`` not tried (the physical cause covers it), ``"when_fitted"`` not tried when the
        physical stage fitted its causes, ``""`` tried as usual.
    on_top_of_physical : tried on top of a physical cause that explains the modes (not an effect that moves
        modes: with an FE model the modes' pairing shows it).
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
    ranges: tuple[ParamRange, ...] = ()
    level: str = "frf"
    moves_every_mode: bool = False
    covered_by_physical: str = ""
    on_top_of_physical: bool = True

    def at_range_edge(self, params: Mapping, band_hz: tuple[float, float] | None = None) -> str:
        """The label of the first fitted parameter at an edge of its range (:attr:`ranges`), "" if none."""
        return next((r.label for r in self.ranges if r.at_edge(params, band_hz)), "")


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


def _mode_kernels(ctx: FitContext, freq_hz: float, zeta: float, lines: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Measured-quantity response of a unit real and a unit imaginary residue (model units) on ``lines``."""
    f = ctx.measured.freq_hz[lines]
    jw = 2j * np.pi * f
    lam = complex(pole_from_fz(freq_hz, zeta))
    k1 = 1 / (jw - lam)
    k2 = 1 / (jw - np.conj(lam))
    conv = convert_quantity(np.ones_like(f, dtype=complex), f, ctx.base.quantity, ctx.measured.quantity)
    return (k1 + k2) * conv, (1j * k1 - 1j * k2) * conv


def mode_residuals(ctx: FitContext, lines: np.ndarray, fz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted residual vector and best residues (variable projection: the residues of each FRF are
    linear, solved in closed form) of one mode ``fz`` = (f Hz, zeta) added to the simulation ``ctx.sim``
    on ``lines``; residues shape (n_out, n_ref, 2), [re, im] in model units (the ``missing_mode`` effect's
    fit, and the local resonator's starts)."""
    a, b = _mode_kernels(ctx, fz[0], fz[1], lines)
    E = ctx.measured.H[..., lines] - ctx.sim.H[..., lines]
    W = ctx.weights[..., lines]
    # normal equations per FRF: [[aa, ab], [ab, bb]] x = [ae, be] (real inner products, weighted)
    aa = np.sum(W * np.abs(a) ** 2, axis=-1)
    bb = np.sum(W * np.abs(b) ** 2, axis=-1)
    ab = np.sum(W * np.real(np.conj(a) * b), axis=-1)
    ae = np.sum(W * np.real(np.conj(a) * E), axis=-1)
    be = np.sum(W * np.real(np.conj(b) * E), axis=-1)
    det = aa * bb - ab ** 2
    det = np.where(det == 0, 1e-300, det)
    x1 = (bb * ae - ab * be) / det
    x2 = (aa * be - ab * ae) / det
    r = (E - x1[..., None] * a - x2[..., None] * b) * np.sqrt(W)
    return np.concatenate([r.real.ravel(), r.imag.ravel()]), np.stack([x1, x2], axis=-1)
