"""The fit of the local resonator (:mod:`.resonator`, the ``local_resonator`` row of the effects
registry): where to start and how to refine.

A strongly coupled resonator has local minima where its coupling pulls the wrong neighbouring modes,
so the search starts from two kinds of points (a weakly coupled extra mode's first-order coupling, and
the resonator attached at each output, its mass screened) at the frequencies of the extra mode that
``missing_mode`` finds and between neighbouring modes, refines the best few of each kind a few steps,
and the best of those to convergence, with the residuals' exact Jacobian (:func:`_resonator_jacobian`).

The simulation is extended through the catalogue it is handed (:class:`Catalogue`: the registry's
``predict`` and ``lookup``), so this module does not import the registry that lists it.
"""
from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from typing import NamedTuple, Protocol

import numpy as np
from scipy.optimize import least_squares

from ..frf import QUANTITY_POWER, FRFSet
from ..modal import ModalModel
from .effect_types import Effect, EffectError, FitContext, mode_residuals, shapes_at_references, split
from .mass_frf import FRF_MASSES_KEY
from .processing import synthesis_derivative
from .resonator import local_resonator_derivative

__all__ = ["Catalogue", "search_resonator", "RESONATOR_BEYOND_BAND", "RESONATOR_SCREEN_RATIOS", "RESONATOR_REFINED",
           "RESONATOR_BETWEEN", "RESONATOR_SHORT", "RESONATOR_CONTINUED"]

log = logging.getLogger(__name__)

#: An applied effect ``{"effect": name, **parameters}`` -> (its registry row, its parameters).
Lookup = Callable[[Mapping], tuple[Effect, dict]]


class Predict(Protocol):
    def __call__(self, base: ModalModel, freq_hz: np.ndarray, quantity: str, effects: Sequence[Mapping] = (),
                 ) -> FRFSet: ...


class Synthesised(Protocol):
    def __call__(self, model: ModalModel, freq_hz: np.ndarray, quantity: str, corr: FRFSet | None,
                 poles: np.ndarray | None = None, residues: np.ndarray | None = None) -> np.ndarray: ...


class Catalogue(NamedTuple):
    """What the search needs of the effects registry: ``predict`` (the simulation extended by effects,
    :func:`analysis.diagnosis.effects.predict`), ``lookup`` (an applied effect's row and parameters) and
    ``synthesised`` (the FRFs of a model's variants at once with its fixed FRF term, what ``predict`` gives
    each without FRF effects)."""

    predict: Predict
    lookup: Lookup
    synthesised: Synthesised


def _initial_coupling(ctx: FitContext, fit: dict, wn: np.ndarray, phi: np.ndarray) -> np.ndarray | None:
    """First-order coupling from an extra mode's fitted residues (``missing_mode``'s): its shape at the
    outputs ``psi_o = sum_r phi_or g_r w_a^2 / (w_r^2 - w_a^2)``, solved for g with the smallest norm."""
    ref = shapes_at_references(ctx.base, phi)
    outs = list(ctx.base.outputs)
    if ref is None or not all(r in outs for r in ctx.base.references):
        return None
    wa = 2 * np.pi * fit["freq_hz"]
    lam = complex(-fit["zeta"] * wa, wa * np.sqrt(1 - fit["zeta"] ** 2))
    R = np.asarray(fit["residue"], float)
    Rc = (R[..., 0] + 1j * R[..., 1]) / lam ** QUANTITY_POWER[ctx.base.quantity]
    dp = outs.index(ctx.base.references[0])
    col = np.real(2j * lam.imag * Rc[:, 0])             # psi_o psi_dp
    if not col[dp] > 0:
        return None
    psi = col / np.sqrt(col[dp])
    A = phi * (wa ** 2 / (wn ** 2 - wa ** 2))[None, :]
    g = np.linalg.lstsq(A, psi, rcond=None)[0]
    return np.asarray(g, float)


#: mass ratios ``m max_r phi_pr^2`` (the resonator's mass over the modal mass of the mode it moves most) of a
#: resonator attached at an output, screened as starting points of the fit
RESONATOR_SCREEN_RATIOS = (0.003, 0.01, 0.03, 0.1)
#: starts refined of each kind (first-order extra mode, attached at an output)
RESONATOR_REFINED = 2
#: the start frequencies between two neighbouring modes a < b: a (b/a)^t
RESONATOR_BETWEEN = (0.25, 0.5, 0.75)
#: evaluations of every start's first refinement, and how many of the best go on to convergence
RESONATOR_SHORT = 15
RESONATOR_CONTINUED = 2
#: how far beyond the band's ends the resonator's own frequency may lie (a factor): its own mode is what tells
#: a resonator from a mass on the structure, so it stays in the band (a fit stopped at the band's end is not
#: evidence of a resonator, :func:`analysis.diagnosis.verdict`)
RESONATOR_BEYOND_BAND = 1.0


def _attached_coupling(phi: np.ndarray, point: int, ratio: float) -> np.ndarray:
    """The coupling ``sqrt(m) phi_p`` of a resonator attached at output ``point`` whose mass is ``ratio`` times
    the modal mass of the mode it moves most there (mass-normalised shapes ``phi``, outputs x modes)."""
    load = float(np.max(phi[point] ** 2))
    return np.sqrt(ratio / load) * phi[point]


def _frf_factor(ctx: FitContext, freq_hz: np.ndarray, lookup: Lookup) -> np.ndarray | None:
    """The FRF effects accepted before (``ctx.prior``'s of kind ``"frf"``) as a factor per line, ``F(H) = G H + B``
    ((n_out, n_ref, n_freq) G at ``freq_hz``); None when they are not of that form (then a derivative through
    them is not a product)."""
    frf_effects = [(eff, params) for eff, params in map(lookup, ctx.prior) if eff.kind == "frf"]
    n_out, n_ref = ctx.base.residues.shape[:2]

    def through(H: np.ndarray) -> np.ndarray:
        frf = FRFSet(freq_hz=freq_hz, H=H, quantity=ctx.measured.quantity, outputs=ctx.base.outputs,
                     references=ctx.base.references)
        for eff, params in frf_effects:
            frf = eff.apply(frf, params)
        return np.asarray(frf.H, complex)

    shape = (n_out, n_ref, freq_hz.size)
    added = through(np.zeros(shape, complex))
    gain = through(np.ones(shape, complex)) - added
    probe = np.exp(2j * np.pi * np.arange(gain.size) / 7.3).reshape(shape)
    if not np.allclose(through(probe) - added, gain * probe, rtol=1e-9, atol=1e-12 * float(np.max(np.abs(gain)))):
        return None
    return gain


def _resonator_jacobian(ctx: FitContext, freq_hz: np.ndarray, sw: np.ndarray, n_free: int,
                        spec: Callable[[np.ndarray], dict], lookup: Lookup) -> Callable[[np.ndarray], np.ndarray] | str:
    """The Jacobian of :func:`fit_local_resonator`'s residual vector ``[Re e, Im e]``, ``e = (H_meas - H(x)) sqrt(w)``,
    in ``x = (frequency_hz, log zeta, coupling_1 .. coupling_n_free)``, exact: the resonated model's poles and
    residues by :func:`.resonator.local_resonator_derivative`, the synthesis by :func:`synthesis_derivative`, the
    FRF effects accepted before as their factor per line (:func:`_frf_factor`; the fixed FRF term and the
    residual terms do not move). Finite differences (``"2-point"``) when those FRF effects are not a factor, or
    when a mass before it is added to an FRF-file simulation's FRFs (:mod:`.mass_frf`), which the resonator's
    modes then move."""
    gain = _frf_factor(ctx, freq_hz, lookup)
    if gain is None:
        return "2-point"
    model = ctx.base
    for e in ctx.prior:                                 # the modal effects before the resonator, once
        eff, params = lookup(e)
        if eff.kind == "modal":
            model = eff.apply(model, params)
    if model.meta.get(FRF_MASSES_KEY):
        return "2-point"                                # a mass added to the FRFs after them (:mod:`.mass_frf`)
    scale = (gain * sw)[..., None]

    def jac(x: np.ndarray) -> np.ndarray:
        _, params = split(spec(x))
        moved, dpoles, dresidues = local_resonator_derivative(model, params)
        dH = synthesis_derivative(moved, freq_hz, ctx.measured.quantity, dpoles, dresidues)[..., :n_free + 2]
        dH[..., 1] *= params["zeta"]                    # x_1 = log zeta
        dH = (dH * scale).reshape(-1, n_free + 2)
        return -np.concatenate([dH.real, dH.imag])
    return jac


def _start_costs(ctx: FitContext, f: np.ndarray, Hm: np.ndarray, sw: np.ndarray, spec: Callable[[np.ndarray], dict],
                 cost: Callable[[np.ndarray], float], catalogue: Catalogue) -> Callable[[list], list[float]]:
    """The costs of several starts (``cost`` of each, the weighted squared error on the lines ``f``): the
    resonated models of all of them synthesised at once (``catalogue.synthesised``) on the model with the modal
    effects accepted before; one by one (``cost``) when FRF effects were accepted before or a mass is added to
    an FRF-file simulation's FRFs (:mod:`.mass_frf`), which act on each prediction."""
    model = ctx.base
    for e in ctx.prior:
        eff, params = catalogue.lookup(e)
        if eff.kind != "modal":
            return lambda xs: [cost(x) for x in xs]
        model = eff.apply(model, params)
    if model.meta.get(FRF_MASSES_KEY):
        return lambda xs: [cost(x) for x in xs]
    resonator = catalogue.lookup({"effect": "local_resonator"})[0]

    def costs(xs: list) -> list[float]:
        moved = [resonator.apply(model, split(spec(x))[1]) for x in xs]
        H = catalogue.synthesised(moved[0], f, ctx.measured.quantity, ctx.base.meta.get("frf_correction"),
                                  np.stack([m.poles for m in moved]), np.stack([m.residues for m in moved]))
        out = []
        for Hx in H:
            e = (Hm - Hx) * sw
            out.append(float(np.sum(e.real ** 2) + np.sum(e.imag ** 2)))
        return out
    return costs


def search_resonator(ctx: FitContext, lines: np.ndarray, catalogue: Catalogue) -> dict:
    """The resonator's frequency, damping and coupling to every mode by least squares on ``lines``, the
    simulation extended through ``catalogue`` (its ``predict`` and ``lookup``).

    A strongly coupled resonator has local minima where its coupling pulls the wrong neighbouring modes, so
    the fit is started from two kinds of points, at the frequencies of the extra modes ``missing_mode``
    finds at the largest residuals and between each pair of in-band modes: the first-order coupling of the
    extra mode's shape at the outputs (:func:`_initial_coupling`, right for a weakly coupled resonator), and
    the resonator attached at each output (coupling ``sqrt(m) phi_p``, the driving point's shapes, its mass
    screened on :data:`RESONATOR_SCREEN_RATIOS`; the physics of a strongly coupled one, shifts of every mode
    included). The :data:`RESONATOR_REFINED` best starts of each kind are refined with the coupling to every
    mode free (trust-region least squares with the residuals' exact Jacobian, :func:`_resonator_jacobian`);
    the smallest cost wins. A pseudo-mode above the band (``meta["above_band_modes"]``, the last
    modes; :mod:`.above_band`) is not coupled: its shape is known at the outputs only as a tail, so it stays
    the fixed term it was fitted as."""
    if not all(r in ctx.base.outputs for r in ctx.base.references):
        # the resonator's own mode is told from the structure's by its shape at the driving point (the
        # first-order start); without one the many starts below would search blind
        raise EffectError("local_resonator: the test has no driving point (the hammer's point is not among the "
                          "outputs) to tell the resonator's mode from the structure's; measure it to try one")
    n_all = ctx.base.poles.size
    n_real = n_all - int(ctx.base.meta.get("above_band_modes", 0))
    phi = np.asarray(ctx.base.meta["output_shapes"], float)[:, :n_real]
    wn = np.abs(np.asarray(ctx.base.poles, complex))[:n_real]
    f = ctx.measured.freq_hz[lines]
    Hm, sw = ctx.measured.H[..., lines], np.sqrt(ctx.weights[..., lines])
    lo, hi = f[0] / RESONATOR_BEYOND_BAND, f[-1] * RESONATOR_BEYOND_BAND

    def spec(x: np.ndarray) -> dict:
        return {"effect": "local_resonator", "frequency_hz": float(x[0]), "zeta": float(np.exp(x[1])),
                "coupling": [float(v) for v in x[2:]] + [0.0] * (n_all - n_real)}

    def resid(x: np.ndarray) -> np.ndarray:
        e = (Hm - catalogue.predict(ctx.base, f, ctx.measured.quantity, ctx.effects(spec(x))).H) * sw
        return np.concatenate([e.real.ravel(), e.imag.ravel()])

    def cost(x: np.ndarray) -> float:
        return float(np.sum(resid(x) ** 2))

    costs = _start_costs(ctx, f, Hm, sw, spec, cost, catalogue)

    jac = _resonator_jacobian(ctx, f, sw, n_real, spec, catalogue.lookup)
    mm = catalogue.lookup({"effect": "missing_mode"})[0].fit(ctx, lines)
    inband = np.sort(wn[(wn >= 2 * np.pi * lo) & (wn <= 2 * np.pi * hi)]) / (2 * np.pi)
    # the extra mode's frequency and points between each pair of in-band modes (on a log scale)
    between = [float(a * (b / a) ** t) for a, b in zip(inband[:-1], inband[1:]) for t in RESONATOR_BETWEEN]
    first, attached = [], []
    points = [p for p in range(phi.shape[0]) if np.max(phi[p] ** 2) > 0]
    for fc in [mm["freq_hz"]] + between:
        if not lo < fc < hi:
            continue
        zc, Rc = min(((float(np.sum(r ** 2)), z, R) for z in (0.005, 0.01, 0.02, 0.05)
                      for r, R in [mode_residuals(ctx, lines, np.array([fc, z]))]), key=lambda t: t[0])[1:]
        g0 = _initial_coupling(ctx, {"freq_hz": fc, "zeta": zc, "residue": Rc}, wn, phi)
        if g0 is not None:
            x0 = np.concatenate([[fc, np.log(zc)], np.clip(g0, -0.5, 0.5)])
            first.append((cost(x0), x0))
        tied = [np.concatenate([[fc, np.log(zc)], np.clip(_attached_coupling(phi, p, ratio), -0.5, 0.5)])
                for p in points for ratio in RESONATOR_SCREEN_RATIOS]
        if tied:                                        # the best attachment at this frequency
            attached.append(min(zip(costs(tied), tied), key=lambda t: t[0]))
    if not first and not attached:
        raise EffectError("local_resonator: no extra mode in the band and no output with a mode shape to start from")
    starts = [x0 for kind in (first, attached) for _, x0 in sorted(kind, key=lambda t: t[0])[:RESONATOR_REFINED]]
    df = ctx.measured.line_spacing_hz
    bounds = ([lo, np.log(1e-4)] + [-1.0] * wn.size, [hi, np.log(0.3)] + [1.0] * wn.size)

    def refine(x0: np.ndarray, nfev: int) -> tuple[float, np.ndarray]:
        res = least_squares(resid, x0, jac=jac, bounds=bounds, x_scale=[df, 0.3] + [0.01] * wn.size,
                            method="trf", max_nfev=nfev)
        log.debug("local_resonator: from %.1f Hz to %.1f Hz, cost %.4g (%d evaluations)", x0[0], res.x[0],
                  float(np.sum(res.fun ** 2)), res.nfev)
        return float(np.sum(res.fun ** 2)), res.x

    # every start a few steps, then the best ones to convergence
    short = sorted((refine(x0, RESONATOR_SHORT) for x0 in starts), key=lambda t: t[0])
    best: tuple[float, np.ndarray] | None = None
    for _, x1 in short[:RESONATOR_CONTINUED]:
        c, x = refine(x1, 60)
        if best is None or c < best[0]:
            best = (c, x)
    assert best is not None
    _, out = split(spec(best[1]))
    g = np.asarray(out["coupling"])
    out["mass_ratio"] = float(np.max(g ** 2))
    return out
