"""Physical causes: re-run the simulation with a parameterised change and fit its parameters.

The simulation is given as an object with the protocol :class:`PhysicalSimulation` (the frame's FE
model in :class:`simulator.physical.FrameVariants`); this module knows only its answers: natural
frequencies and shape products at the measured points for a cause and its parameters.

Data. The measured modes come from the automatic LSFD fit of the measurement
(:func:`analysis.pipeline.fit_auto`): natural frequencies ``f_k`` (Hz, the structure's: the
exponential window's damping is removed by the fit), their standard deviations ``s_k`` and the
residues ``R_k`` at the measured points (a vector over (output, reference)); the lowest ``MAX_MODES``
modes whose frequency the data determine (``s_k <= MAX_STD_FRACTION f_k``).

Residuals of a candidate (cause, parameters) with modes ``f_j``, shape products ``P_j``: measured and
candidate modes are paired one to one (``scipy.optimize.linear_sum_assignment`` on
``|ln(f_j / f_k)| / 0.1 + (1 - MAC(R_k, P_j))``) and each measured mode k gives

    r_f,k = (f_j - f_k) / (f_k sigma_k),   sigma_k = sqrt((s_k / f_k)^2 + FREQ_FLOOR^2)
    r_m,k = (1 - MAC(R_k, P_j)) / MAC_TOL

``FREQ_FLOOR`` (0.2 %) is the accuracy of the model form (mesh, beam theory) below which a
frequency difference is not a discrepancy; ``MAC_TOL`` (0.1) likewise for shapes. Each residual is
bounded smoothly, ``c tanh(r / c)`` with ``c = RESIDUAL_CAP`` (10), so one mode the fit could not
resolve (a close pair merged, a spurious peak) counts as one large error; ``chi2 = sum r^2``.

Fit. Continuous parameters by least squares on log-factors (bounded by the cause's search range), with the
residuals' exact Jacobian when the simulation gives the modes' derivatives (``modes_jac_of``:
:class:`ResidualsWithJacobian`; else forward differences): with at most two parameters by Newton steps with a
secant-corrected curvature where they converge inside the range (:func:`descend`), else (and with more parameters)
by :func:`scipy.optimize.least_squares` (:func:`least_chi2`), a log-factor that stops at an
edge where chi2 is flat within ``CHI2_RESOLUTION`` moved just inside (:func:`off_edges`);
a choice (the node of an added mass, the element of a crack) of more than
``N_SCREEN`` options by a screen that orders the work and a bound that keeps every option that could win:
each option on a grid of its parameters (the range's ends included), then fitted from its best grid point in
that order, the ``N_SCREEN`` best and every further option whose chi2 could still come below the best fit so
far. The bound: a parameter declared ``monotone`` (a mass or a stiffness added: each natural frequency moves
one way only) keeps every frequency inside a box of the grid between its values at the box's corners, so a
measured mode is at least as far from the candidate's modes as from those intervals (:func:`_chi2_bound`);
a box whose bound is below the best fit is halved (``TIGHTEN_SPLITS``) before the option is fitted instead.
A simulation with a ``first_pass`` (bounds of each option's mode count over a grid: a user's FE model of many
nodes) has every option's chi2 bounded from below over its whole range first (:func:`_first_pass`); the options
are then screened and fitted ``FIRST_PASS_BATCH`` at a time, lowest bound first, while a bound is below the best
fit so far. A choice of at most ``N_SCREEN`` options (one support or joint, or all of them) is not screened: every option
gets the full search of its parameters (from the nominal and from the best point of a grid), with its own
model. A cause with several parameters is also fitted with each subset alone (the others at their nominal
value, each variant started also from the fits of the variants it contains): nested models, the one that
predicts best (leave one mode out) wins. A refinement (a parameter that ``requires`` another: a mass's
rotary inertia, about every axis or one) is freed one at a time on top of the best variant, at the options
that variant fitted, and kept only when it predicts the held-out modes ``physical_min_gain_db`` better; one mode
that neither predicts when it is held out is left out of that comparison (:func:`refinement_gain_db`); the refined
variants' cross-validation stops as soon as none of them can gain that much (:func:`refinement_gain_bound`).

Cross-validation: leave one mode out. Each measured mode is predicted by the cause fitted to the
other modes (the choice searched again inside the fold among the ``N_SCREEN_FOLD`` best options of the
full fit, and the parameters refitted), so a cause that only bends to fit some modes predicts the
left-out mode badly. Each fold starts from the fit on all modes, its first step the grouped-deletion formula of
least squares made from that fit's residuals and Jacobian without a solve (:class:`FoldStart`).
``gain_db = 10 log10(chi2_base / chi2_cv)`` with ``chi2_base`` the nominal simulation's. A cause is
significant when ``gain_db >= physical_min_gain_db`` (a field of the one
:class:`analysis.diagnosis.rule.DecisionRule`, as the adequacy thresholds below).

Exactness: a simulation may solve candidates approximately (the FE frame by Rayleigh-Ritz reduction,
:mod:`simulator.ritz`); each cause's chosen fit is then evaluated on the full model
(``exact_modes_of``) and, when its chi2 there differs by more than ``FULL_MODEL_CHI2_TOL``, the cause
is fitted again on the full model.

Adequacy (before a name is given): the extended simulation's FRFs (after the measurement's own
processing) must bring the typical FRF error within ``none_margin_db`` of the noise or remove at
least ``adequate_fraction`` of the excess error in power, and its parameters must lie inside their
search range (not at an edge).
"""
from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from itertools import combinations, product
from typing import Any, Protocol

import numpy as np
from scipy.optimize import least_squares, linear_sum_assignment

from ..mac import MacReference
from ..modal import ModalModel
from ..progress import progress
from .rule import DEFAULT_RULE, DecisionRule, gain_db

log = logging.getLogger(__name__)

__all__ = ["ParamSpec", "CauseSpec", "PhysicalSimulation", "MeasuredModes", "PhysicalFit",
           "fit_cause", "held_out_reaches", "held_out_bound", "kept_fit", "variants", "physical_causes", "paired_well",
           "same_structure", "FREQ_FLOOR",
           "MAC_TOL", "N_SCREEN", "N_SCREEN_FOLD", "MAX_MODES",
           "LOST_MODE_CHI2", "MODE_CHI2_MAX", "lost_modes", "counted_modes", "refinement_gain_db", "refinement_gain_bound",
           "gain_db"]

FREQ_FLOOR = 0.002
MAC_TOL = 0.1
#: Residuals are bounded smoothly by this (``c tanh(r / c)``): one mode the fit could not resolve (a close
#: pair merged by the window's damping, a spurious peak) counts as a large error, not as all of them.
RESIDUAL_CAP = 10.0
#: A held-out mode with at least this chi2 is not predicted (its residuals near the cap: unpaired, or paired far off).
LOST_MODE_CHI2 = 0.5 * RESIDUAL_CAP ** 2
#: The most chi2 one mode can hold (its frequency and its shape residual, each at most the cap).
MODE_CHI2_MAX = 2.0 * RESIDUAL_CAP ** 2
N_SCREEN = 5
#: Options searched again inside each leave-one-mode-out fold (the best of the full fit).
N_SCREEN_FOLD = 3
#: The lowest modes used (the FE model's accuracy and the cost of the search both grow with the order).
MAX_MODES = 10
#: Modes whose frequency is not determined by the data (standard deviation above this fraction) are left out.
MAX_STD_FRACTION = 0.001
#: Modes pair when the frequency ratio is within this and their MAC at least PAIR_MIN_MAC.
PAIR_MAX_LOG_RATIO = 0.25
PAIR_MIN_MAC = 0.5
_EDGE = 0.01            # a parameter within 1 % of its (log) range from an edge is "at the edge"


@dataclass(frozen=True)
class ParamSpec:
    """A continuous parameter: search range ``lo..hi`` (log scale when ``log``), nominal value (the
    unchanged frame; None: the middle), unit; ``requires``: the parameter without which this one changes
    nothing (a mass's rotary inertia needs the mass): it is freed only together with that one."""

    name: str
    lo: float
    hi: float
    nominal: float | None = 1.0
    unit: str = ""
    log: bool = True
    requires: str | None = None
    #: the simulation's natural frequencies, each by its order, move one way only as this parameter grows (a
    #: mass or a stiffness added: Rayleigh's monotonicity): the frequencies at the corners of a box of such
    #: parameters bound every frequency inside it, so a choice's chi2 is bounded from below (:func:`_chi2_bound`)
    monotone: bool = False

    def to_x(self, v: float) -> float:
        return float(np.log(v)) if self.log else float(v)

    def from_x(self, x: float) -> float:
        return float(np.exp(x)) if self.log else float(x)

    @property
    def x_bounds(self) -> tuple[float, float]:
        return self.to_x(self.lo), self.to_x(self.hi)

    def start(self) -> float:
        """Starting value: the nominal when inside the range, else the geometric (or plain) middle."""
        if self.nominal is not None and self.lo < self.nominal < self.hi:
            return float(self.nominal)
        return float(np.sqrt(self.lo * self.hi)) if self.log else 0.5 * (self.lo + self.hi)

    def at_edge(self, v: float) -> bool:
        a, b = self.x_bounds
        x = self.to_x(max(v, self.lo) if self.log else v)
        return bool(x - a < _EDGE * (b - a) or b - x < _EDGE * (b - a))


@dataclass(frozen=True)
class CauseSpec:
    """A physical cause: its continuous parameters and, optionally, a choice (``"point"``: a node,
    ``"component"``: a member, ``"element"``: an element ``member:e``, ``"support"`` / ``"joint"``: one
    support or joint, or ``"all"``) among ``options``; what it
    is (``description``) and what to do when it is named (``advice``); its level is ``"physical"``
    (:data:`analysis.diagnosis.effect_types.LEVELS`)."""

    name: str
    params: tuple
    choice: str | None = None
    options: tuple = ()
    description: str = ""
    advice: str = ""
    level: str = "physical"
    #: the option that means every place at once (a support's ``"all"``), None when there is none: the cause at
    #: two of its other options is two changes of one kind (two loose supports), which
    #: :func:`analysis.diagnosis.physical_pairs.split_places` fits as a pair
    every: str | None = None

    @property
    def places(self) -> tuple:
        """The options that are one place each (every option but :attr:`every`)."""
        return tuple(o for o in self.options if o != self.every)

    def at_edge(self, params: Mapping, free: tuple) -> tuple[str, ...]:
        """The names of the free parameters whose fitted values ``params`` lie at an edge of their range."""
        return tuple(s.name for s in self.params if s.name in free and s.at_edge(float(params[s.name])))


class PhysicalSimulation(Protocol):
    """What the physical diagnosis needs of a simulation (see :class:`simulator.physical.FrameVariants`)."""

    def causes(self) -> Sequence[CauseSpec]: ...

    def modes(self, cause: str | None, params: Mapping, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]: ...

    def model(self, cause: str | None, params: Mapping) -> ModalModel: ...

    def modes_of(self, changes: Sequence[tuple[str, Mapping]], max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]: ...

    def model_of(self, changes: Sequence[tuple[str, Mapping]]) -> ModalModel: ...

    # ``modes_of`` / ``model_of``: several causes at once (a list of (cause, params)), for two causes.
    # optional: ``refined_model() -> ModalModel``, the same simulation on a finer mesh: what it removes
    # of the typical error is discretisation, added to the noise level (``noise_db["model_form"]``);
    # ``exact_modes_of(changes, max_freq_hz)``, when ``modes_of`` is an approximation (a reduced model):
    # each cause's chosen fit is checked with it (:func:`physical_causes`)


@dataclass(frozen=True)
class MeasuredModes:
    """Measured modes: natural frequencies (Hz), their standard deviations (Hz), residue vectors
    ``shapes`` (n_out * n_ref, n_modes) complex, C order over (output, reference); a zero column is a
    mode known by its frequency only (e.g. a paper's table), paired and compared by frequency."""

    freq_hz: np.ndarray
    freq_std_hz: np.ndarray
    shapes: np.ndarray

    @classmethod
    def from_model(cls, model: ModalModel, freq_std_hz: np.ndarray | None = None) -> MeasuredModes:
        f = np.asarray(model.freq_hz, float)
        std = np.zeros_like(f) if freq_std_hz is None else np.asarray(freq_std_hz, float)
        R = np.asarray(model.residues).reshape(-1, f.size)
        keep = np.flatnonzero((f > 0) & np.isfinite(std) & (std <= MAX_STD_FRACTION * f))
        keep = keep[np.argsort(f[keep])][:MAX_MODES]
        return cls(freq_hz=f[keep], freq_std_hz=std[keep], shapes=R[:, keep])

    def subset(self, keep: np.ndarray) -> MeasuredModes:
        """The modes selected by the mask or indices ``keep``."""
        return MeasuredModes(self.freq_hz[keep], self.freq_std_hz[keep], self.shapes[:, keep])

    @cached_property
    def sigma(self) -> np.ndarray:
        """Relative frequency uncertainty per mode (model-form floor included)."""
        return np.hypot(self.freq_std_hz / self.freq_hz, FREQ_FLOOR)

    @cached_property
    def _mac(self) -> MacReference:
        """The shapes held for MAC against every candidate (:func:`pair`)."""
        return MacReference(self.shapes)

    @cached_property
    def _no_shape(self) -> np.ndarray:
        """Mask of the modes known by their frequency only (a zero shape column)."""
        return ~np.any(self.shapes != 0, axis=0)

    @cached_property
    def _rows(self) -> np.ndarray:
        """The shapes' conjugates ``R_k^H`` as real rows (2, K, N): real parts, imaginary parts (:func:`_pairing`)."""
        a_h = self._mac.a_h
        return np.ascontiguousarray(np.stack([a_h.real, a_h.imag]))

    @cached_property
    def _f_sigma(self) -> np.ndarray:
        """``f_k sigma_k`` (Hz): a frequency residual's unit."""
        return self.freq_hz * self.sigma

    @cached_property
    def fits_made(self) -> dict:
        """The fits made on these modes so far, each under its simulation and its start (:func:`kept_fit`): the
        search's stages ask some of them again (a pair refined on all modes before its variants are widened, then
        refined and cross-validated; a first cause refitted on top of the same second cause by two stages)."""
        return {}


def pair(mm: MeasuredModes, f: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Candidate mode index paired with each measured mode (-1: none) and the MAC of the pair."""
    idx, macs, _ = _pairing(mm, f, P)
    return idx, macs


def _pairing(mm: MeasuredModes, f: np.ndarray, P: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray] | None]:
    """:func:`pair`'s answer and the products it is made of: the real and imaginary parts of ``R_k^H P_j`` (K, n) and
    the candidate shapes' energies ``|P_j|^2`` (n) (None without candidate modes). Real shape products (a model's
    real modes) are multiplied by the shapes' real and imaginary parts at once (:attr:`MeasuredModes._rows`)."""
    K = mm.freq_hz.size
    idx = np.empty(K, dtype=np.intp)
    idx.fill(-1)
    macs = np.zeros(K)
    if f.size == 0:
        return idx, macs, None
    if np.iscomplexobj(P):
        S = mm._mac.a_h @ P
        re, im = S.real, S.imag
        bb = np.sum(np.abs(P) ** 2, axis=0)
    else:
        X = mm._rows.reshape(2 * K, -1) @ P
        re, im = X[:K], X[K:]
        bb = np.einsum("ij,ij->j", P, P)
    num = re * re + im * im
    den = mm._mac.energy[:, None] * bb[None, :]
    if (den > 0).all():
        M = num / den
    else:
        with np.errstate(invalid="ignore", divide="ignore"):
            M = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
    M[mm._no_shape] = 1.0                            # modes measured without shapes pair by frequency
    C = np.abs(np.log(f[None, :] / mm.freq_hz[:, None])) / 0.1 + (1.0 - M)
    rows, cols = linear_sum_assignment(C)
    idx[rows] = cols
    macs[rows] = M[rows, cols]
    return idx, macs, (re, im, bb)


def kept_fit(mm: MeasuredModes, sim: Any, key: tuple, make: Any) -> Any:
    """The answer ``make()`` of the fit ``key`` on the simulation ``sim`` and the modes ``mm``, made once: asked again
    (by any stage of the search of these modes), the answer made the first time (:attr:`MeasuredModes.fits_made`).
    ``key`` holds everything the fit depends on besides ``sim`` and ``mm`` (its causes, their parameters and starts,
    the modes it is fitted on, the band); a fit is a function of these (the simulation's answers are functions of
    their arguments), so the kept answer is the one ``make()`` would give again."""
    got = mm.fits_made.get((id(sim), *key))
    if got is None or got[0] is not sim:       # (an id is reused only after its simulation is gone)
        got = mm.fits_made[(id(sim), *key)] = (sim, make())
    return got[1]


def residuals(mm: MeasuredModes, f: np.ndarray, P: np.ndarray) -> np.ndarray:
    """(K, 2) residuals ``(r_f, r_m)`` per measured mode (module docstring), each bounded smoothly by
    ``RESIDUAL_CAP`` (``c tanh(r / c)``); an unpaired mode gets the cap and MAC 0."""
    return RESIDUAL_CAP * np.tanh(_raw_residuals(mm, f, *pair(mm, f, P)) / RESIDUAL_CAP)


def _raw_residuals(mm: MeasuredModes, f: np.ndarray, idx: np.ndarray, macs: np.ndarray) -> np.ndarray:
    """(K, 2) residuals before the cap, given the pairing ``idx`` (-1: unpaired) and the MACs of :func:`pair`."""
    r = np.empty((mm.freq_hz.size, 2))
    ok = idx >= 0
    if ok.all():
        r[:, 0] = (f[idx] / mm.freq_hz - 1.0) / mm.sigma
    else:
        r[ok, 0] = (f[idx[ok]] / mm.freq_hz[ok] - 1.0) / mm.sigma[ok]
        r[~ok, 0] = RESIDUAL_CAP
    r[:, 1] = (1.0 - macs) / MAC_TOL
    return r


def residuals_jac(mm: MeasuredModes, f: np.ndarray, P: np.ndarray, df: np.ndarray, dP: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`residuals` (K, 2) and their derivatives (K, 2, n) given the candidate's derivatives ``df``
    (n_modes, n: Hz per unit) and ``dP`` (n_products, n_modes, n) with respect to n parameters, the pairing
    held (it changes only where the residuals jump). ``d r_f,k = df_j / (f_k sigma_k)``; with ``s = R_k^H P_j``,
    ``MAC = |s|^2 / (|R_k|^2 |P_j|^2)``: ``d MAC = 2 Re(conj(s) R_k^H dP_j) / (|R_k|^2 |P_j|^2) - 2 MAC
    (P_j . dP_j) / |P_j|^2`` (with real shape products ``P``, the real and imaginary parts of ``R_k^H dP_j`` at once);
    an unpaired mode's and a mode without shape's residuals are constant; the cap ``c tanh(r / c)`` multiplies them by
    ``1 - tanh^2(r / c)``."""
    idx, macs, products = _pairing(mm, f, P)
    raw = _raw_residuals(mm, f, idx, macs)
    K, n = mm.freq_hz.size, df.shape[1]
    J = np.zeros((K, 2, n))
    ok = idx >= 0
    if ok.all():
        J[:, 0] = df[idx] / mm._f_sigma[:, None]
    else:
        J[ok, 0] = df[idx[ok]] / mm._f_sigma[ok][:, None]
    shaped = np.flatnonzero(ok & ~mm._no_shape)
    if shaped.size and products is not None:
        re, im, bb = products
        j = idx[shaped]
        dPj = dP[:, j]                                            # (N, m, n)
        bbj, ea = bb[j], mm._mac.energy[shaped]
        good = (bbj > 0) & (ea > 0)
        # -d MAC / MAC_TOL = u . Re(R^H dP_j) + v . Im(R^H dP_j) + w P_j . dP_j (0 where a MAC is not defined)
        if good.all():
            scale = (-2.0 / MAC_TOL) / bbj
            uv = np.array([re[shaped, j], im[shaped, j]]) * (scale / ea)
        else:
            scale = np.where(good, -2.0 / MAC_TOL, 0.0) / np.where(good, bbj, 1.0)
            uv = np.array([re[shaped, j], im[shaped, j]]) * (scale / np.where(good, ea, 1.0))
        w = -scale * macs[shaped]
        if np.iscomplexobj(P) or np.iscomplexobj(dP):
            cross = np.einsum("mN,Nmn->mn", mm._mac.a_h[shaped], dPj)
            J[shaped, 1] = (uv[0][:, None] * cross.real + uv[1][:, None] * cross.imag
                            + w[:, None] * np.einsum("Nm,Nmn->mn", P[:, j], dPj))
        else:                                                     # all three terms in one product
            W = np.concatenate([mm._rows[:, shaped] * uv[:, :, None], (P[:, j] * w).T[None]])   # (3, m, N)
            J[shaped, 1] = np.einsum("smN,Nmn->mn", W, dPj)
    t = np.tanh(raw / RESIDUAL_CAP)
    return RESIDUAL_CAP * t, J * (1.0 - t * t)[:, :, None]


def modes_jac(sim: PhysicalSimulation, changes: Sequence[tuple[str, Mapping]], fmax: float,
              wrt: Sequence[tuple[int, str]]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The simulation's modes of ``changes`` with their derivatives with respect to the parameters ``wrt``
    (``(i, name)`` of ``changes[i]``), when it has them (``modes_jac_of``, as
    :meth:`simulator.physical.FrameVariants.modes_jac_of`); None: not for this candidate."""
    fn = getattr(sim, "modes_jac_of", None)
    return None if fn is None else fn(list(changes), fmax, list(wrt))


class ResidualsWithJacobian:
    """The residual vector of the candidates ``changes_at(x)`` on the measured modes ``sel`` and its Jacobian
    with respect to ``x`` (``dv_dx(x)``: the parameters' derivatives by ``x``, a log-factor's ``v``) for
    :func:`scipy.optimize.least_squares` (:meth:`options`): one solve per point (the last point's answers
    kept, for the optimizer asks the residuals and then the Jacobian at a point; and a point :meth:`hold` names,
    a fit's start, which least squares asks again when :func:`descend` leaves the fit to it from there).
    ``plain(x)``: the modes without derivatives. A simulation without derivatives (no ``modes_jac_of``) is
    differentiated by least_squares' own forward differences (``diff_step`` 1e-3), a candidate it gives none for
    (``modes_jac``: None) by the same differences here, inside ``bounds``."""

    def __init__(self, sim: PhysicalSimulation, changes_at: Any, plain: Any, wrt: Sequence[tuple[int, str]],
                 dv_dx: Any, mm: MeasuredModes, sel: np.ndarray, fmax: float,
                 bounds: tuple[np.ndarray, np.ndarray]) -> None:
        self.sim, self.changes_at, self.plain, self.wrt, self.dv_dx = sim, changes_at, plain, list(wrt), dv_dx
        self.mm, self.sel, self.fmax, self.bounds = mm, sel, fmax, bounds
        self._modes_jac = getattr(sim, "modes_jac_of", None)
        self.analytic = self._modes_jac is not None
        self._every = np.asarray(sel).dtype == bool and bool(np.all(sel))         # every mode: no selection to make
        self._x: bytes | None = None
        self._r = np.zeros(0)
        self._J: np.ndarray | None = None
        self._held: tuple[bytes, np.ndarray, np.ndarray | None] | None = None

    def options(self) -> dict:
        """least_squares' ``jac`` (and ``diff_step``) for this simulation."""
        return {"jac": self.jac} if self.analytic else {"jac": "2-point", "diff_step": 1e-3}

    def _plain(self, x: np.ndarray) -> np.ndarray:
        f, P = self.plain(x)
        r = residuals(self.mm, f, P)
        return r.ravel() if self._every else r[self.sel].ravel()

    def _at(self, x: np.ndarray) -> None:
        key = np.asarray(x, float).tobytes()
        if key == self._x:
            return
        if self._held is not None and key == self._held[0]:
            r, J = self._held[1], self._held[2]
            self._x, self._r, self._J = key, r.copy(), None if J is None else J.copy()
            return
        got = self._modes_jac(list(self.changes_at(x)), self.fmax, self.wrt) if self._modes_jac is not None else None
        if got is None:
            self._r, self._J = self._plain(x), None
        else:
            f, P, df, dP = got
            d = np.asarray(self.dv_dx(x), float)
            r, J = residuals_jac(self.mm, f, P, df * d, dP * d)
            if self._every:
                self._r, self._J = r.ravel(), J.reshape(-1, d.size)
            else:
                self._r, self._J = r[self.sel].ravel(), J[self.sel].reshape(-1, d.size)
        self._x = key

    def hold(self, x: np.ndarray) -> None:
        """Keep the answers at ``x`` (a fit's start) until another point is held: asked there again after other
        points, they are not solved again (a copy each time: the optimizer may scale what it is given)."""
        self._at(x)
        assert self._x is not None
        self._held = (self._x, self._r.copy(), None if self._J is None else self._J.copy())

    def fun(self, x: np.ndarray) -> np.ndarray:
        self._at(x)
        return self._r

    def jac(self, x: np.ndarray) -> np.ndarray:
        self._at(x)
        if self._J is not None:
            return self._J
        r0 = self._r
        J = np.empty((r0.size, x.size))
        lo, hi = self.bounds
        for i in range(x.size):       # least_squares' own step: 1e-3 max(1, |x|) away from zero, inside the bounds
            h = 1e-3 * max(abs(float(x[i])), 1.0) * (1.0 if x[i] >= 0 else -1.0)
            if not lo[i] <= x[i] + h <= hi[i]:
                h = -h
            xi = np.array(x, float)
            xi[i] += h
            J[:, i] = (self._plain(xi) - r0) / (xi[i] - x[i])
        return J


@dataclass
class PhysicalFit:
    """One cause (one nested variant) fitted: parameters (incl. the choice), chi2 on all modes,
    leave-one-mode-out chi2 and per-mode held-out residuals, the free parameter names."""

    cause: str
    params: dict
    free: tuple
    chi2: float
    chi2_cv: float = np.inf
    cv_per_mode: np.ndarray = field(default_factory=lambda: np.zeros(0))
    at_edge: tuple = ()
    ranked: list = field(default_factory=list)       # [(chi2, option, params)] of a choice, best first


#: Relative tolerance of the least squares on chi2 and on the (log) parameters: a chi2 is compared with others to
#: about 0.01, a factor reported to 4 digits (the default 1e-8 spent a quarter of the fits' solves beyond that).
FIT_TOL = 1e-6


def _fit_continuous(sim: PhysicalSimulation, cause: CauseSpec, free: Sequence[ParamSpec], fixed: dict,
                    mm: MeasuredModes, sel: np.ndarray, fmax: float, start: dict | None = None,
                    also: Sequence[Mapping] = ()) -> tuple[dict, float]:
    """Least squares over the free parameters (log-factors) from ``start`` (else from the nominal and
    from the best point of a grid inside the range: 7 points, 5 per parameter for two) and from each of
    ``also`` (a nested variant's fit: the parameters it left at their nominal start there); the best."""
    def full(x: np.ndarray) -> dict:
        p = dict(fixed)
        for s, xi in zip(free, x):
            p[s.name] = s.from_x(float(xi))
        return p

    def resid(x: np.ndarray) -> np.ndarray:
        f, P = sim.modes(cause.name, full(x), fmax)
        return residuals(mm, f, P)[sel].ravel()

    lo, hi = _x_box(free)
    first = start or {}
    starts = [search_x(free, first)]
    if start is None:      # and the best point of a coarse grid over the range
        inner = 9 if len(free) == 1 else 7
        grid = np.array(np.meshgrid(*[np.linspace(a, b, inner)[1:-1] for a, b in zip(lo, hi)])).reshape(len(free), -1).T
        costs = [float(np.sum(resid(x) ** 2)) for x in grid]
        starts.append(grid[int(np.argmin(costs))])
    starts += [search_x(free, q) for q in also]
    rj = _cause_residuals(sim, cause, free, full, mm, sel, fmax)
    best: tuple[dict, float] = ({}, np.inf)
    minima: list[tuple[np.ndarray, float]] = []
    for x0 in distinct_starts([np.clip(x0, lo + 1e-6 * (hi - lo), hi - 1e-6 * (hi - lo)) for x0 in starts]):
        x, cost = least_chi2(rj, free, x0, 30 * len(free), minima)
        minima.append((x, cost))
        if cost < best[1]:
            best = (full(x), cost)
    return best


#: Newton steps :func:`descend` takes from a fit's start before it leaves the fit to least squares.
FIT_STEPS = 10
#: :func:`descend` has converged when one more step would lower the chi2 by at most this fraction of it. Least
#: squares stops when its last step did by :data:`FIT_TOL`; a thousandth of that (one step more, where the steps
#: converge superlinearly) leaves a fit closer to the exact minimum than least squares leaves it.
DESCENT_TOL = 1e-3 * FIT_TOL


def least_chi2(rj: ResidualsWithJacobian, specs: Sequence[ParamSpec], x0: np.ndarray, max_nfev: int,
               known: Sequence[tuple[np.ndarray, float]] = ()) -> tuple[np.ndarray, float]:
    """The least chi2 of the residuals ``rj`` (search variables of ``specs``) from the start ``x0`` inside their box:
    (its point, its chi2). With at most :data:`DESCENT_PARAMETERS` parameters by :func:`descend` where it converges
    inside the box (or reaches one of the minima ``known`` from other starts: that one); else by
    :func:`scipy.optimize.least_squares` (bounded, at most ``max_nfev`` evaluations) from ``x0``, a log-factor that
    stops at an edge moved inside where chi2 allows (:func:`off_edges`)."""
    x0 = np.asarray(x0, float)
    if rj.analytic and x0.size <= DESCENT_PARAMETERS:
        rj.hold(x0)         # least squares starts here again when the descent leaves the fit to it
        got = descend(rj, specs, x0, np.array(rj.fun(x0)), np.array(rj.jac(x0)), None, FIT_STEPS, known)
        if got is not None:
            return got[0], got[1]
    lo, hi = rj.bounds
    res = least_squares(rj.fun, x0, bounds=(lo, hi), max_nfev=max_nfev, ftol=FIT_TOL, xtol=FIT_TOL, **rj.options())
    x, cost = off_edges(specs, res.x, float(2 * res.cost), lambda y: float(np.sum(rj.fun(y) ** 2)))
    return x, cost


#: :func:`least_chi2` descends by Newton steps with at most this many parameters; with more (a mass's rotary inertia
#: about two axes on top of its mass) the surface has several valleys near the start, and least squares' trust region
#: is left to choose among them as it did.
DESCENT_PARAMETERS = 2
#: A Newton step that lands within this (search variables, each) of a minimum another start reached goes there
#: (:func:`descend`'s ``known``).
SAME_MINIMUM = 1e-3


def descend(rj: ResidualsWithJacobian, specs: Sequence[ParamSpec], x: np.ndarray, r: np.ndarray, J: np.ndarray,
            rows: np.ndarray | None, steps: int, known: Sequence[tuple[np.ndarray, float]] = ()
            ) -> tuple[np.ndarray, float, np.ndarray] | None:
    """The least chi2 of the residuals ``rj`` on the rows ``rows`` (None: all) from ``x`` (residuals ``r`` and
    Jacobian ``J`` there) by Newton steps: ``d = -B^-1 g`` with ``g = J^T r`` (half chi2's gradient) and ``B`` half
    its curvature, Gauss-Newton's ``J^T J`` corrected by the last step's secant (:func:`_curvature`: the residuals are
    not small, so ``J^T J`` alone converges only linearly), halved while chi2 does not come down (twice at most).
    Converged when one more step would lower chi2 by at most :data:`DESCENT_TOL` of it: (the point, its chi2, all
    residuals there). None (for least squares to fit it): ``x`` not inside, no convergence within ``steps`` steps,
    or a step that leaves the box or stops in a parameter's edge band (:meth:`ParamSpec.at_edge`: where the bounds
    and :func:`off_edges` decide). ``known``: minima
    ``(x_j, chi2_j)`` of the same residuals from other starts; a step that would land within :data:`SAME_MINIMUM`
    of one whose chi2 is not above the current point's is on its way there (the descent would take the step and
    converge to it): that minimum is the answer, its residuals not returned (an empty array)."""
    lo, hi = rj.bounds

    def inside(y: np.ndarray) -> bool:
        return bool(np.all(y > lo) and np.all(y < hi) and not any(s.at_edge(s.from_x(float(yi)))
                                                                   for s, yi in zip(specs, y)))

    if not inside(x):
        return None
    on = np.ones(r.size, bool) if rows is None else rows
    chi2 = float(r[on] @ r[on])
    g = J[on].T @ r[on]
    before: tuple[np.ndarray, np.ndarray] | None = None
    for step in range(steps + 1):
        try:
            d = -np.linalg.solve(_curvature(J[on], x, g, before), g)
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(d)):
            break
        if -float(g @ d) <= DESCENT_TOL * chi2:
            return x, chi2, r
        for x_j, chi2_j in known:
            if chi2_j <= chi2 and float(np.max(np.abs(x + d - x_j))) <= SAME_MINIMUM:
                return np.array(x_j), float(chi2_j), np.zeros(0)
        if step == steps:
            break
        for _ in range(3):
            y = x + d
            if not inside(y):
                return None
            r_y = np.array(rj.fun(y))
            chi2_y = float(r_y[on] @ r_y[on])
            if chi2_y <= chi2:
                break
            d = 0.5 * d
        else:
            break
        J_y = np.array(rj.jac(y))
        before = (x, g)
        x, r, J, chi2 = y, r_y, J_y, chi2_y
        g = J[on].T @ r[on]
    return None


def _curvature(J: np.ndarray, x: np.ndarray, g: np.ndarray, before: tuple[np.ndarray, np.ndarray] | None
               ) -> np.ndarray:
    """Half the curvature of chi2 at ``x`` for :func:`descend`'s step (``g = J^T r``, half its gradient): Gauss-Newton's
    ``A = J^T J``, corrected with the previous point's ``before = (x', g')`` by the symmetric rank-one update that
    makes it hold the secant ``B s = y`` (``s = x - x'``, ``y = g - g'``; with one parameter ``B = y / s``): the
    residuals' own curvature, which ``A`` leaves out, along the last step. ``A`` when the update is ill-defined or
    not positive definite."""
    A = J.T @ J
    A = A + 1e-12 * max(float(np.trace(A)), 1e-300) * np.eye(x.size)
    if before is None:
        return A
    s_, y_ = x - before[0], g - before[1]
    u = y_ - A @ s_
    den = float(u @ s_)
    if not np.isfinite(den) or abs(den) <= 1e-8 * float(np.linalg.norm(u) * np.linalg.norm(s_)) or den == 0.0:
        return A
    B = A + np.outer(u, u) / den
    try:
        np.linalg.cholesky(B)
    except np.linalg.LinAlgError:
        return A
    return B


def search_x(specs: Sequence[ParamSpec], params: Mapping) -> np.ndarray:
    """The search variables (:meth:`ParamSpec.to_x`) of ``specs`` at the parameters ``params`` (a parameter they
    lack at its start, :meth:`ParamSpec.start`)."""
    return np.array([s.to_x(float(params.get(s.name, s.start()))) for s in specs])


def _x_box(specs: Sequence[ParamSpec]) -> tuple[np.ndarray, np.ndarray]:
    """The search variables' bounds (:attr:`ParamSpec.x_bounds`) of ``specs``: (lower, upper)."""
    return np.array([s.x_bounds[0] for s in specs]), np.array([s.x_bounds[1] for s in specs])


def _cause_residuals(sim: PhysicalSimulation, cause: CauseSpec, free: Sequence[ParamSpec], full: Any,
                     mm: MeasuredModes, sel: np.ndarray, fmax: float) -> ResidualsWithJacobian:
    """The residuals of ``cause`` at the parameters ``full(x)`` of the search variables ``x`` of ``free`` on the
    modes ``sel``, with their Jacobian (:class:`ResidualsWithJacobian`)."""
    return ResidualsWithJacobian(sim, lambda x: [(cause.name, full(x))], lambda x: sim.modes(cause.name, full(x), fmax),
                                 [(0, s.name) for s in free], lambda x: dv_dx(free, x), mm, sel, fmax, _x_box(free))


def distinct_starts(starts: Sequence[np.ndarray]) -> list[np.ndarray]:
    """The starts of a least-squares fit, each once (the first of equal ones): a fit is a function of its start, so
    a start equal to an earlier one (a grid's best point at the nominal, a nested variant's fit with its other
    parameters at their nominal) gives that fit again and cannot be lower."""
    out: list[np.ndarray] = []
    for x0 in starts:
        if not any(np.array_equal(x0, y) for y in out):
            out.append(x0)
    return out


#: Fits whose chi2 differ by less than this are not told apart (:data:`FIT_TOL`: a chi2 is compared with others to
#: about 0.01).
CHI2_RESOLUTION = 0.01


def off_edges(specs: Sequence[ParamSpec], x: np.ndarray, chi2: float, chi2_at: Any) -> tuple[np.ndarray, float]:
    """A fit ``x`` (chi2 ``chi2``; ``chi2_at(x)``) with each log-factor that stopped at an edge of its range
    (:meth:`ParamSpec.at_edge`) moved just inside the edge band (twice its width from the edge) when chi2 there is
    within :data:`CHI2_RESOLUTION` of the fit's: the data do not tell the edge from there. A spring far stiffer
    than what it holds is rigid, so a joint's rotational factor creeps up a valley whose floor falls by ~1e-4 per
    decade to the x 100 edge (an exact derivative follows it; a finite-difference one stopped anywhere on the
    way); the edge would say the cause wants more than its range allows, which the data do not say."""
    x = np.array(x, float)
    for i, s in enumerate(specs):
        if not s.log or not s.at_edge(s.from_x(float(x[i]))):
            continue
        a, b = s.x_bounds
        y = x.copy()
        y[i] = b - 2 * _EDGE * (b - a) if x[i] > 0.5 * (a + b) else a + 2 * _EDGE * (b - a)
        c = chi2_at(y)
        if c <= chi2 + CHI2_RESOLUTION:
            x, chi2 = y, c
    return x, chi2


def dv_dx(specs: Sequence[ParamSpec], x: np.ndarray) -> np.ndarray:
    """The parameters' derivatives by their search variables ``x`` (:meth:`ParamSpec.to_x`): ``v`` for a
    log-factor, 1 for a plain one."""
    return np.array([s.from_x(float(xi)) if s.log else 1.0 for s, xi in zip(specs, x)])


def _nominal(cause: CauseSpec) -> dict:
    return {s.name: s.nominal for s in cause.params if s.nominal is not None}


#: Options screened at once after the first pass (:func:`_first_pass`): the lowest bounds first, then batches of
#: this many while a bound is below the best fit so far.
FIRST_PASS_BATCH = N_SCREEN
#: Frequency residuals (in units of the mode's sigma, :attr:`MeasuredModes.sigma`) the first pass tests: a mode
#: whose window ``f_k (1 +- level sigma_k)`` certainly holds no candidate mode has ``|r_f| > level``.
FIRST_PASS_LEVELS = np.array([0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 14.0, 20.0, 30.0])
#: Points of the first pass's grid over the parameter's range (ends included): its cells bound the option.
FIRST_PASS_GRID = 25


def _first_pass(sim: PhysicalSimulation, cause: CauseSpec, specs: Sequence[ParamSpec], fixed: dict,
                mm: MeasuredModes, sel: np.ndarray, fmax: float, options: Sequence[str]
                ) -> list[tuple[float, str]] | None:
    """A lower bound of each option's chi2 over its whole parameter range, from the simulation's ``first_pass``
    (bounds of its mode count, :meth:`analysis.fe_model.FEVariants.first_pass`), sorted by the bound; None when
    the simulation has none for this cause (or it has several free or non-monotone parameters, or few options).

    The bound: on a grid cell ``[v_a, v_b]`` of a monotone parameter each mode count ``N_v(f)`` lies between
    its values at the two corners, so the modes in a window ``[x, y]`` number at most ``max_corners at_most(y)
    - min_corners at_least(x)``; none there means every candidate mode is farther than the window from the
    measured mode, whatever the pairing (:func:`pair`), so ``|r_f| > level`` for the widest empty window
    of ``FIRST_PASS_LEVELS`` (0 when none is empty; the shapes' residual counted as 0). The chi2 bound of a
    cell is the sum over the modes of that level, bounded as :func:`residuals` bounds it; an option's is the
    least over its cells. Windows are widened by ``_BOUND_SLACK`` against rounding."""
    bounds_of: Any = getattr(sim, "first_pass", None)
    if bounds_of is None or len(specs) != 1 or not specs[0].monotone or set(fixed) - {cause.choice}:
        return None
    s = specs[0]
    values = np.array([s.from_x(float(x)) for x in np.linspace(*s.x_bounds, FIRST_PASS_GRID)])
    fk, sk = mm.freq_hz[sel], mm.sigma[sel]
    lv = FIRST_PASS_LEVELS
    x = fk[:, None] * np.maximum(1.0 - lv[None, :] * sk[:, None], 0.0) * (1.0 - _BOUND_SLACK)
    y = fk[:, None] * (1.0 + lv[None, :] * sk[:, None]) * (1.0 + _BOUND_SLACK)
    got = bounds_of(cause.name, list(options), values, np.concatenate([x.ravel(), y.ravel()]), fmax)
    if got is None:
        return None
    at_least, at_most = (np.asarray(a) for a in got)
    n_opt, shape = len(options), (len(options), values.size, fk.size, lv.size)
    below_x = at_least[:, :, :x.size].reshape(shape)
    upto_y = at_most[:, :, x.size:].reshape(shape)
    most = np.maximum(upto_y[:, :-1], upto_y[:, 1:])          # (options, cells, modes, levels)
    least = np.minimum(below_x[:, :-1], below_x[:, 1:])
    free = most <= least                                        # windows nest: the empty ones lead
    empty = np.where(free.all(axis=-1), lv.size, np.argmin(free, axis=-1))
    r = np.concatenate([[0.0], lv])[empty]
    chi2 = np.sum((RESIDUAL_CAP * np.tanh(r / RESIDUAL_CAP)) ** 2, axis=-1)    # (options, cells)
    bound = chi2.min(axis=1)
    order = np.argsort(bound, kind="stable")
    return [(float(bound[i]), str(options[i])) for i in order[:n_opt]]


#: Grid points per parameter of a choice's screen, the range's ends included (one parameter; two: ``SCREEN_GRID_2``).
SCREEN_GRID = 9
SCREEN_GRID_2 = 5
#: Relative slack on the frequencies bounding a box (:func:`_chi2_bound`): a reduced model's rounding (1e-6).
_BOUND_SLACK = 1e-5


def _chi2_bound(mm: MeasuredModes, sel: np.ndarray, corners: Sequence[np.ndarray]) -> float:
    """A lower bound of chi2 on the modes ``sel`` over a box of monotone parameters (:attr:`ParamSpec.monotone`)
    given the candidate frequencies at its corners: the j-th frequency lies between its least and largest
    corner value everywhere in the box (above the computed band where a corner lacks it), so a measured mode
    is at least as far from every candidate mode as from the nearest such interval; the shapes' residual is
    counted as 0. Every pairing (:func:`pair`) is bounded: an unpaired mode gets the cap."""
    n = max(f.size for f in corners)
    lo = np.full(n, np.inf)
    hi = np.full(n, -np.inf)
    for f in corners:
        lo[:f.size] = np.minimum(lo[:f.size], f)
        hi[:f.size] = np.maximum(hi[:f.size], f)
        hi[f.size:] = np.inf
    lo, hi = lo * (1 - _BOUND_SLACK), hi * (1 + _BOUND_SLACK)
    fk = mm.freq_hz[sel][:, None]
    gap = np.maximum(lo[None, :] - fk, 0.0) + np.maximum(fk - hi[None, :], 0.0)
    r = (gap.min(axis=1) if n else np.full(fk.shape[0], np.inf)) / mm.freq_hz[sel] / mm.sigma[sel]
    return float(np.sum((RESIDUAL_CAP * np.tanh(r / RESIDUAL_CAP)) ** 2))


@dataclass
class _Screened:
    """One option on the screen's grid: the least chi2 at a grid point (an upper bound of its exact fit), the
    parameters there, and a lower bound of chi2 over the whole range (0: none known) with the cells it comes
    from (``[(bound, box)]``, a box a tuple of ``(x_lo, x_hi)`` per free parameter)."""

    chi2: float
    option: str
    params: dict
    bound: float
    cells: list = field(default_factory=list)
    at: _Chi2 | None = None


class _Chi2:
    """The chi2 and the frequencies of one option at points ``x`` of its free parameters (the simulation keeps
    its answers, so a corner shared by two boxes is solved once)."""

    def __init__(self, sim: PhysicalSimulation, cause: CauseSpec, specs: Sequence[ParamSpec], fixed: dict,
                 mm: MeasuredModes, sel: np.ndarray, fmax: float, option: str) -> None:
        self.sim, self.cause, self.specs, self.mm, self.sel, self.fmax = sim, cause, specs, mm, sel, fmax
        self.fixed = {**fixed, cause.choice: option}
        self._kept: dict[tuple, tuple[float, np.ndarray]] = {}

    def params(self, x: Sequence[float]) -> dict:
        return {**self.fixed, **{s.name: s.from_x(float(xi)) for s, xi in zip(self.specs, x)}}

    def at(self, x: Sequence[float]) -> tuple[float, np.ndarray]:
        key = tuple(float(xi) for xi in x)
        if key not in self._kept:
            f, P = self.sim.modes(self.cause.name, self.params(x), self.fmax)
            self._kept[key] = (float(np.sum(residuals(self.mm, f, P)[self.sel] ** 2)), f)
        return self._kept[key]

    def bound(self, box: Sequence[tuple[float, float]]) -> float:
        """:func:`_chi2_bound` over ``box`` from its corners."""
        return _chi2_bound(self.mm, self.sel, [self.at(x)[1] for x in product(*box)])


def _screen(sim: PhysicalSimulation, cause: CauseSpec, specs: Sequence[ParamSpec], fixed: dict, mm: MeasuredModes,
            sel: np.ndarray, fmax: float, options: Sequence[str]) -> list[_Screened]:
    """Each option on a grid of its free parameters, the range's ends included (``SCREEN_GRID`` points, two
    parameters ``SCREEN_GRID_2`` each), with its own model and pairing; with monotone parameters the grid's
    cells also bound the option's chi2 from below (:func:`_chi2_bound`, the least over its cells). Sorted by
    the grid's least chi2."""
    n = SCREEN_GRID if len(specs) == 1 else SCREEN_GRID_2
    axes = [np.linspace(*s.x_bounds, n) for s in specs]
    bounded = all(s.monotone for s in specs)
    out = []
    for opt in options:
        at = _Chi2(sim, cause, specs, fixed, mm, sel, fmax, opt)
        c, x = min((at.at(x)[0], x) for x in product(*axes))
        cells = []
        if bounded:
            for idx in np.ndindex(*(a.size - 1 for a in axes)):
                box = tuple((float(a[i]), float(a[i + 1])) for a, i in zip(axes, idx))
                cells.append((at.bound(box), box))
        bound = min(b for b, _ in cells) if cells else 0.0
        out.append(_Screened(c, opt, at.params(x), bound, cells, at))
    return sorted(out, key=lambda t: t.chi2)


def _screened(sim: PhysicalSimulation, cause: CauseSpec, specs: Sequence[ParamSpec], fixed: dict,
              mm: MeasuredModes, sel: np.ndarray, fmax: float, options: Sequence[str],
              held: dict[str, list[Mapping]]) -> list[_Screened]:
    """:func:`_screen` of ``options``, each option's nested fits in ``held`` (taken from it) its best point when
    lower than its grid's."""
    out = _screen(sim, cause, specs, fixed, mm, sel, fmax, options)
    for s in out:
        for q in held.pop(s.option, ()):
            c = float(np.sum(residuals(mm, *sim.modes(cause.name, q, fmax))[sel] ** 2))
            if c < s.chi2:
                s.chi2, s.params = c, dict(q)
    return sorted(out, key=lambda t: t.chi2)


#: Boxes split (each into two halves) to lift an option's bound above the best fit before it is fitted instead.
TIGHTEN_SPLITS = 12


def _tighten(at: _Chi2, s: _Screened, target: float, splits: int = TIGHTEN_SPLITS) -> None:
    """Lift ``s.bound`` towards ``target`` by splitting its lowest box in halves (along its widest parameter,
    relative to the range) at most ``splits`` times; a corner with a lower chi2 than the grid's best becomes the
    option's best point."""
    widths = [max(b - a, 1e-30) for a, b in (sp.x_bounds for sp in at.specs)]
    for _ in range(splits):
        if not s.cells or s.bound >= target:
            return
        s.cells.sort(key=lambda t: t[0])
        _, box = s.cells.pop(0)
        d = int(np.argmax([(b - a) / w for (a, b), w in zip(box, widths)]))
        mid = 0.5 * (box[d][0] + box[d][1])
        for half in ((box[d][0], mid), (mid, box[d][1])):
            part = box[:d] + (half,) + box[d + 1:]
            s.cells.append((at.bound(part), part))
            for x in product(*part):
                c = at.at(x)[0]
                if c < s.chi2:
                    s.chi2, s.params = c, at.params(x)
        s.bound = min(b for b, _ in s.cells)


def _inside(s: _Screened, specs: Sequence[ParamSpec]) -> list[dict]:
    """With several parameters (whose least squares may stop in a local minimum from the grid's best point, a
    corner of a rugged surface): the middle of the box with the lowest bound, where the frequencies can agree."""
    if len(specs) < 2 or not s.cells:
        return []
    box = min(s.cells, key=lambda t: t[0])[1]
    return [{sp.name: sp.from_x(0.5 * (a + b)) for sp, (a, b) in zip(specs, box)}]


def fit_cause(sim: PhysicalSimulation, cause: CauseSpec, free: Sequence[str], mm: MeasuredModes,
              sel: np.ndarray, fmax: float, options: Sequence[str] | None = None,
              start: dict | None = None, nested: Sequence[Mapping] = (), below: float = np.inf,
              best_only: bool = False) -> tuple[dict, float, list]:
    """Fit ``cause`` with the parameters ``free`` (others nominal) on the measured modes ``sel``.
    With a choice of at most ``N_SCREEN`` options: each fitted in full (:func:`_fit_continuous`), no screen.
    More: every option screened on a grid (:func:`_screen`), then fitted from its best grid point in the
    screen's order: the ``N_SCREEN`` best, and after them every option whose chi2 could still be below the best
    fit so far (its lower bound from the screen; an option without one always could). No option is dropped
    that could win. ``nested``: fits of a variant with fewer free parameters (with the choice, at their option):
    each is a start too (a screened option's best point when its chi2 there is lower), so a variant's chi2 is
    never above a nested one's. ``below``: only a fit below this chi2 is of use (:func:`_best_variant`): an
    option whose bound is not below it is not fitted (none fitted: chi2 inf). ``best_only``: the caller takes the best
    fit alone (not the options ranked): an option among the ``N_SCREEN`` best of the screen whose bound (made as
    without it) is not below the best fit so far is not fitted either; its fit could not be lower, so the best fit
    is the same, and the ranked options are those fitted.
    Returns (params, chi2, [(chi2, option, params)] of the fitted options, sorted)."""
    specs = [s for s in cause.params if s.name in free]
    fixed = {k: v for k, v in _nominal(cause).items() if k not in free}
    if cause.choice is None:
        p, c = _fit_continuous(sim, cause, specs, fixed, mm, sel, fmax, start, nested)
        return p, c, []
    held: dict[str, list[Mapping]] = {}
    for q in nested:
        held.setdefault(str(q[cause.choice]), []).append(q)
    todo = options if options is not None else cause.options
    screened: list[_Screened]
    pending: list[tuple[float, str]] = []       # after a first pass: (bound, option) not screened yet, by bound
    if held and options is None and any(s.requires is not None for s in specs):
        # a refinement refines the fits it is nested in, where they are, from there (its own nominal)
        def chi2(q: Mapping) -> float:
            return float(np.sum(residuals(mm, *sim.modes(cause.name, q, fmax))[sel] ** 2))

        screened = sorted((_Screened(c, opt, dict(q), -np.inf) for opt in todo if opt in held
                           for c, q in [min(((chi2(q), q) for q in held[opt]), key=lambda t: t[0])]),
                          key=lambda t: t.chi2)
        held = {}
    elif isinstance(start, dict) and options is not None and set(options) <= set(start):
        # the options' own fits as starts (a fold of the cross-validation): no coarse screen again
        screened = [_Screened(0.0, opt, start[opt], -np.inf) for opt in options]
    elif len(todo) <= N_SCREEN:
        # few options (a support, a joint, all of them): each gets the full search of its own parameters
        screened = [_Screened(0.0, opt, {}, -np.inf) for opt in todo]
    else:
        first = _first_pass(sim, cause, specs, fixed, mm, sel, fmax, todo)
        if first is None:
            screened = _screened(sim, cause, specs, fixed, mm, sel, fmax, todo, held)
        else:
            pending, screened = first, []
    ranked = []
    best: tuple[dict, float] = ({}, np.inf)
    i = 0
    while True:
        for s in screened:
            target = below if i < N_SCREEN else min(below, best[1])
            i += 1
            if best_only:               # an option lifted above the best fit so far is not fitted either
                target = min(target, best[1])
            if s.bound < target and s.at is not None:
                _tighten(s.at, s, target)
            if s.bound >= target:
                continue                    # its chi2 cannot come below the best fit's (or ``below``) in its range
            p, c = _fit_continuous(sim, cause, specs, {**fixed, cause.choice: s.option}, mm, sel, fmax,
                                   s.params or None, [*held.get(s.option, ()), *_inside(s, specs)])
            ranked.append((c, s.option, p))
            if c < best[1]:
                best = (p, c)
        # after the first pass: the next options whose bound is below the best fit so far (none: done)
        target = below if i < N_SCREEN else min(below, best[1])
        batch = [opt for b, opt in pending if b < target][:FIRST_PASS_BATCH]
        if not batch:
            break
        pending = [(b, opt) for b, opt in pending if opt not in set(batch)]
        screened = _screened(sim, cause, specs, fixed, mm, sel, fmax, batch, held)
    ranked.sort(key=lambda t: t[0])
    return best[0], best[1], ranked


def variants(cause: CauseSpec) -> list[tuple[str, ...]]:
    """The nested variants of a cause without refinements: every set of its parameters that ``require`` no other
    set free (fewest first). A refinement (a parameter that ``requires`` another: a mass's rotary inertia about
    one axis) is freed one at a time on top of the best of these, where it earns its keep (:func:`_best_variant`)."""
    names = [s.name for s in cause.params if s.requires is None]
    return [c for k in range(1, len(names) + 1) for c in combinations(names, k)]


def held_out_reaches(done: np.ndarray, least_rest: np.ndarray, target: float) -> bool:
    """Whether a held-out chi2 is certain to reach ``target``: its bound (:func:`held_out_bound`) reaches it."""
    return bool(held_out_bound(done, least_rest) >= target)


def held_out_bound(done: np.ndarray | Sequence[float], least_rest: np.ndarray) -> float:
    """The least a held-out chi2 can be: the folds ``done`` (their held-out chi2) and the rest,
    each at least its mode's chi2 at the all-modes least-squares minimum ``x`` (``least_rest``). A fold starts from
    ``x`` and only descends on the other modes, ``S_-k(x_k) <= S_-k(x)``, and ``S(x_k) >= S(x)`` at the least chi2 on
    all modes, so the left-out mode pays ``S(x_k) - S_-k(x_k) >= S(x) - S_-k(x) = r_k(x)^2``; before any fold the
    sum is the chi2 on all modes (the rule the fits already follow: a held-out chi2 is at least it)."""
    return float(np.sum(done) + np.sum(least_rest))


#: Newton steps a fold takes from the fit on all modes (:class:`FoldStart`) before it is left to least squares.
FOLD_STEPS = 4

class FoldStart:
    """A fit on all modes as each leave-one-mode-out fold starts from it: its search variables ``x`` (inside the
    box ``bounds``), the residuals ``r`` of every mode there and their Jacobian ``J`` (``rj``: a
    :class:`ResidualsWithJacobian` on all modes), made once for all the folds.

    Fold k minimises ``S_-k(x) = |r_-k(x)|^2``, the residuals of every mode but k. Its first Gauss-Newton step from
    the fit on all modes ``x*`` is ``d = -(J_-k^T J_-k)^-1 J_-k^T r_-k``; at an interior least-squares minimum
    ``J^T r = 0``, so ``J_-k^T r_-k = -J_k^T r_k`` and ``d = (A - J_k^T J_k)^-1 J_k^T r_k`` with ``A = J^T J``: the
    grouped-deletion formula of least squares, which for residuals linear in ``x`` is the fold's exact minimum and
    gives the held-out residual ``r_k + J_k d = (I - H_kk)^-1 r_k`` (``H_kk = J_k A^-1 J_k^T``) without a refit.
    The residuals here are not linear (the pairing, the cap, the modes' own dependence on the parameters), so the
    step is only the first of :func:`descend`'s (Newton steps, each with the residuals and Jacobian at the new point:
    one solve with derivatives each) to the fold's minimum, as close as least squares reaches it or closer
    (:data:`DESCENT_TOL`). The first step needs no solve (``r`` and ``J`` at ``x*`` serve every fold), so a fold costs
    one to three solves instead of least squares' four to eight. :meth:`minimum` gives up (None: the caller fits the
    fold by least squares from ``x*``, :func:`_fit_continuous`) when :func:`descend` does not converge inside the box
    within :data:`FOLD_STEPS` steps."""

    def __init__(self, rj: ResidualsWithJacobian, x: np.ndarray, specs: Sequence[ParamSpec]) -> None:
        self.rj, self.x, self.specs = rj, np.asarray(x, float), list(specs)
        self.r = np.array(rj.fun(self.x))
        self.J = np.array(rj.jac(self.x))

    def _rows(self, k: int) -> np.ndarray:
        rows = np.ones(self.r.size // 2, bool)
        rows[k] = False
        return np.repeat(rows, 2)

    def minimum(self, k: int) -> tuple[np.ndarray, float, np.ndarray] | None:
        """Fold ``k``'s minimum from ``x`` by :func:`descend`: (its search variables, ``S_-k`` there, the residuals of
        mode k there), or None (class docstring)."""
        rows = self._rows(k)
        got = descend(self.rj, self.specs, self.x, self.r, self.J, rows, FOLD_STEPS)
        return None if got is None else (got[0], got[1], got[2][~rows])


class _Folds:
    """The folds of one fitted variant (:func:`_best_of`): the cause ``cause`` with the parameters ``free``, its choice
    searched among ``options`` (None: no choice), each option from its fit on all modes in ``starts`` (the fit's
    parameters without a choice); each option's :class:`FoldStart` made when a fold first asks it."""

    def __init__(self, sim: PhysicalSimulation, cause: CauseSpec, free: tuple, mm: MeasuredModes, fmax: float,
                 options: Sequence[str] | None, starts: dict) -> None:
        self.sim, self.cause, self.mm, self.fmax, self.options, self.starts = sim, cause, mm, fmax, options, starts
        self.specs = [s for s in cause.params if s.name in free]
        self.fixed = {k: v for k, v in _nominal(cause).items() if k not in free}
        self._kept: dict[str | None, FoldStart] = {}

    def _fixed(self, option: str | None) -> dict:
        return self.fixed if option is None else {**self.fixed, self.cause.choice: option}

    def _full(self, option: str | None) -> Any:
        fixed = self._fixed(option)

        def full(x: np.ndarray) -> dict:
            return {**fixed, **{s.name: s.from_x(float(xi)) for s, xi in zip(self.specs, x)}}
        return full

    def _start(self, option: str | None) -> dict:
        return self.starts if option is None else self.starts[option]

    def start(self, option: str | None) -> FoldStart:
        if option not in self._kept:
            q = self._start(option)
            x = search_x(self.specs, q)
            rj = _cause_residuals(self.sim, self.cause, self.specs, self._full(option), self.mm,
                                  np.ones(self.mm.freq_hz.size, bool), self.fmax)
            self._kept[option] = FoldStart(rj, x, self.specs)
        return self._kept[option]

    def held_out(self, k: int) -> float:
        """Fold ``k``: the held-out chi2 of mode k, the cause refitted on the other modes at each option (the least
        chi2 there, the first of equal ones, as :func:`fit_cause` chooses), each by :meth:`FoldStart.minimum` or,
        where that gives up, by least squares from the option's fit (:func:`_fit_continuous`)."""
        sel = np.ones(self.mm.freq_hz.size, bool)
        sel[k] = False
        best: tuple[float, dict, np.ndarray | None] = (np.inf, {}, None)
        for option in (self.options if self.options is not None else [None]):
            got = self.start(option).minimum(k)
            if got is None:
                p, c = _fit_continuous(self.sim, self.cause, self.specs, self._fixed(option), self.mm, sel, self.fmax,
                                       self._start(option))
                held = None
            else:
                p, c, held = self._full(option)(got[0]), got[1], got[2]
            if c < best[0]:
                best = (c, p, held)
        if best[2] is None:
            best = (best[0], best[1], residuals(self.mm, *self.sim.modes(self.cause.name, best[1], self.fmax))[k])
        return float(np.sum(np.asarray(best[2]) ** 2))


def _held_out(sim: PhysicalSimulation, cause: CauseSpec, free: tuple, mm: MeasuredModes, fmax: float,
              options: Sequence[str] | None, start: dict, k: int, folds: _Folds | None = None) -> float:
    """One fold of the cross-validation (leave one mode out): the held-out chi2 of mode ``k``, the cause refitted on the
    other modes (the choice searched again among ``options``, each from its fit on all modes in ``start``). ``folds``
    (the variant's :class:`_Folds`, made for these arguments): each option's refit from Gauss-Newton steps shared by
    the folds (:class:`FoldStart`) where they converge."""
    if folds is not None:
        return folds.held_out(k)
    sel = np.ones(mm.freq_hz.size, bool)
    sel[k] = False
    p, _, _ = fit_cause(sim, cause, free, mm, sel, fmax, options, start)
    f, P = sim.modes(cause.name, p, fmax)
    return float(np.sum(residuals(mm, f, P)[k] ** 2))


def _best_variant(sim: PhysicalSimulation, cause: CauseSpec, mm: MeasuredModes, fmax: float,
                  rule: DecisionRule = DEFAULT_RULE) -> PhysicalFit | None:
    """The cause's nested variants (:func:`variants`) fitted (each also from the fits of the variants it contains,
    :func:`fit_cause`'s ``nested``) and cross-validated; the one with the least held-out chi2. Then its
    refinements (parameters that ``require`` one of its free parameters: a mass's rotary inertia about X, Y, Z),
    one parameter more at a time: the best variant with one refinement more replaces the current one only when it
    predicts the held-out modes ``rule.physical_min_gain_db`` better (:func:`refinement_gain_db`) and none of its
    parameters stops at an edge of its range.
    A refinement refines the current fit where it was made: its choice is searched among the options the current
    variant fitted (every option whose chi2 could come below that variant's best, :func:`fit_cause`).

    A fit's held-out chi2 is at least its chi2 on all modes (each fold starts from the full fit and can only
    descend on the other modes, so what it gains there the left-out mode pays at least back: the full fit is the
    least chi2 on all modes), so a variant whose chi2 on all modes already exceeds the held-out chi2 it would
    have to beat is not cross-validated: it cannot win."""
    fits: dict[tuple[str, ...], PhysicalFit] = {}
    allsel = np.ones(mm.freq_hz.size, bool)

    def fit(free: tuple[str, ...], below: float) -> None:
        inner = [q for v, f in fits.items() if set(v) < set(free) for q in _fitted_params(f)]
        p, chi2, ranked = fit_cause(sim, cause, free, mm, allsel, fmax, nested=inner, below=below)
        if np.isfinite(chi2):
            fits[free] = PhysicalFit(cause=cause.name, params=p, free=free, chi2=chi2, ranked=ranked)

    for free in variants(cause):
        fit(free, np.inf)
    best = _best_of(sim, cause, mm, fmax, list(fits.values()), np.inf)
    while best is not None:
        more = [s.name for s in cause.params if s.requires in best.free and s.name not in best.free]
        # one refinement more must bring the held-out chi2 physical_min_gain_db below the current's: its chi2 on all modes too
        bar = _refinement_bar(best.cv_per_mode, rule)
        frees = [tuple(n for n in (s.name for s in cause.params) if n in best.free or n == extra) for extra in more]
        for free in frees:
            fit(free, bar)
        refined = _best_of(sim, cause, mm, fmax, [fits[v] for v in frees if v in fits], bar,
                           lambda done, rest, now=best.cv_per_mode:
                           refinement_gain_bound(now, done, rest) >= rule.physical_min_gain_db)
        if (refined is None or refined.at_edge
                or refinement_gain_db(best.cv_per_mode, refined.cv_per_mode) < rule.physical_min_gain_db):
            break
        best = refined
    return best


def lost_modes(cv: np.ndarray) -> np.ndarray:
    """Mask of the held-out modes not predicted: chi2 (per mode, held out) at least :data:`LOST_MODE_CHI2`."""
    return np.asarray(cv) >= LOST_MODE_CHI2


def counted_modes(lost: np.ndarray) -> np.ndarray:
    """Mask of the held-out modes a comparison counts, given the mask ``lost`` of those it may leave out (modes no
    fit predicts, :func:`lost_modes`): all but the lost one when exactly one is lost; all when none or several are
    (several lost modes say the fit explains none of them, so each counts)."""
    lost = np.asarray(lost, bool)
    return ~lost if int(lost.sum()) == 1 else np.ones(lost.size, bool)


def refinement_gain_db(current: np.ndarray, refined: np.ndarray) -> float:
    """How much better (dB) a refined variant predicts the held-out modes than the current one (``current``,
    ``refined``: held-out chi2 per mode). One mode that neither predicts when it is held out (:func:`lost_modes` in
    both) is left out: it says nothing about which predicts better, and a mode only the refinement gives rise to (a
    heavy block's rotary inertia about one axis makes a mode the point mass has not) is such a mode, its own fold
    having no other witness of the refinement; its capped chi2 would drown the other modes' gain. Several such modes
    are all counted (the refinement explains none of them)."""
    keep = counted_modes(lost_modes(current) & lost_modes(refined))
    return gain_db(np.asarray(current)[keep], np.asarray(refined)[keep])


def refinement_gain_bound(current: np.ndarray, done: np.ndarray, least_rest: np.ndarray) -> float:
    """The most a refinement can gain (dB, :func:`refinement_gain_db`) over the current variant (held-out chi2 per mode
    ``current``) when its first folds are ``done`` (held-out chi2 per mode) and each remaining mode's held-out chi2 is
    at least ``least_rest`` (:func:`held_out_bound`'s, its chi2 at the fit on all modes). The gain compares all modes,
    or all but the one mode lost in both (:func:`counted_modes`): each mode the current variant loses could be that
    one when the refinement may lose it too (done and lost, or not done) and may keep every other mode the current
    variant loses (done and kept, or not done with a bound below :data:`LOST_MODE_CHI2`); all modes are compared when
    none may be lost in both or several may. Each comparison's refined sum is bounded from below by the folds done and
    the bounds of the rest, so the gain by the most of these; with every fold done, the gain itself."""
    current = np.asarray(current, float)
    refined = np.concatenate([np.asarray(done, float), np.asarray(least_rest, float)])
    d = len(done)
    lost_now = lost_modes(current)
    may_lose = np.ones(refined.size, bool)
    may_lose[:d] = lost_modes(refined[:d])
    may_keep = refined < LOST_MODE_CHI2
    # all modes compared: none lost in both (each mode the current variant loses may be kept) or several
    best = (gain_db(current, refined) if np.all(may_keep[lost_now]) or np.count_nonzero(lost_now & may_lose) > 1
            else -np.inf)
    for j in np.flatnonzero(lost_now & may_lose):
        others = lost_now.copy()
        others[j] = False
        if np.all(may_keep[others]):
            keep = np.ones(refined.size, bool)
            keep[j] = False
            best = max(best, gain_db(current[keep], refined[keep]))
    return best


def _refinement_bar(current: np.ndarray, rule: DecisionRule) -> float:
    """The most held-out chi2 (all modes) with which a refinement can beat the current variant (held-out chi2 per
    mode ``current``) by :func:`refinement_gain_db`: ``rule.physical_min_gain_db`` below the current's sum, or, with a
    mode the current variant loses, below the sum without that mode plus the most that mode can hold."""
    scale = rule.physical_min_gain_factor
    lost = np.asarray(current)[lost_modes(current)]
    if lost.size == 0:
        return float(np.sum(current)) * scale
    return max(float(np.sum(current)) * scale, (float(np.sum(current)) - float(lost.min())) * scale + MODE_CHI2_MAX)


def _fitted_params(fit: PhysicalFit) -> list[dict]:
    """The parameters of a fit at each option it fitted (its own, without a choice)."""
    return [q for _, _, q in fit.ranked] if fit.ranked else [fit.params]


def _best_of(sim: PhysicalSimulation, cause: CauseSpec, mm: MeasuredModes, fmax: float,
             fits: Sequence[PhysicalFit], bar: float, could_pass: Any = None) -> PhysicalFit | None:
    """Of the fitted variants ``fits``, cross-validated, the one with the least held-out chi2 below ``bar``
    (None: none can be). ``could_pass(done, least_rest)``: whether a variant whose folds ``done`` (held-out chi2 per
    mode) and bounds of the rest (as below) are these could still pass the caller's test of the answer (a refinement's
    gain over the current variant, :func:`refinement_gain_bound`); None (the caller would reject the answer) as soon
    as no variant could, whichever of them would be the answer.

    Best first: each variant's held-out chi2 is bounded from below by its folds done plus, for the folds to come,
    each mode's chi2 at its fit on all modes (:func:`held_out_reaches`; before any fold, its chi2 on all modes), and
    the next fold is always the one of the variant with the least bound (the lower chi2 on all modes first among
    equal bounds). A variant whose folds are all done then has the least held-out chi2 of all: every other one's is
    at least its bound, which is not below it; each fold is made alone (:func:`_held_out`), so it is the same
    variant with the same held-out chi2 as when each variant is cross-validated in turn with the best so far as its
    limit (both rest on the same bound, :func:`held_out_reaches`, which holds where each fit on all modes is the
    least chi2 there; where a fold finds a lower one, either order may keep another variant). The folds of a
    variant that cannot win stop as soon as its bound passes the least one's: a variant with a low chi2 on all modes
    that predicts the held-out modes worse than a simpler one is not cross-validated to its end first."""
    K = mm.freq_hz.size
    runs: list[tuple[PhysicalFit, list[str] | None, dict, np.ndarray, list[float], _Folds | None]] = []
    for fit in sorted(fits, key=lambda f: f.chi2):
        if fit.chi2 >= bar:
            break
        options = [o for _, o, _ in fit.ranked[:N_SCREEN_FOLD]] if fit.ranked else None
        starts = {o: q for _, o, q in fit.ranked} if fit.ranked else fit.params
        least = np.sum(residuals(mm, *sim.modes(cause.name, fit.params, fmax)) ** 2, axis=1)
        runs.append((fit, options, starts, least, [], _folds_of(sim, cause, fit.free, mm, fmax, options, starts)))

    def bound(run: tuple) -> float:
        done, least = run[4], run[3]
        return held_out_bound(done, least[len(done):])

    while runs:
        if could_pass is not None and not any(could_pass(np.asarray(r[4]), r[3][len(r[4]):]) for r in runs):
            return None                 # whichever variant is the answer, the caller rejects it
        i = min(range(len(runs)), key=lambda j: (bound(runs[j]), j))
        fit, options, starts, _, done, folds = runs[i]
        if held_out_reaches(np.asarray(done), runs[i][3][len(done):], bar):
            return None                 # no variant's held-out chi2 can come below ``bar``
        if len(done) == K:
            cv = np.array(done)
            return replace(fit, chi2_cv=float(cv.sum()), cv_per_mode=cv, at_edge=cause.at_edge(fit.params, fit.free))
        done.append(_held_out(sim, cause, fit.free, mm, fmax, options, starts, len(done), folds))
    return None


def _folds_of(sim: PhysicalSimulation, cause: CauseSpec, free: tuple, mm: MeasuredModes, fmax: float,
              options: Sequence[str] | None, starts: dict) -> _Folds | None:
    """The variant's folds by :class:`_Folds` when :func:`fit_cause` would refit each fold at ``options`` from its
    ``starts`` alone (a cause without a choice, or a choice with a start for each option) and the simulation gives
    the modes' derivatives; None: by :func:`fit_cause` itself."""
    if getattr(sim, "modes_jac_of", None) is None:
        return None
    if cause.choice is None or (options is not None and set(options) <= set(starts)):
        return _Folds(sim, cause, free, mm, fmax, options if cause.choice is not None else None, starts)
    return None


def physical_causes(sim: PhysicalSimulation, mm: MeasuredModes, fmax: float,
                    names: Sequence[str] | None = None, processes: int | None = None,
                    rule: DecisionRule = DEFAULT_RULE) -> list[PhysicalFit]:
    """Every cause (its best nested variant by leave-one-mode-out chi2) fitted; sorted by held-out
    chi2 (best first). The nominal simulation's chi2 is the caller's (``residuals`` of ``sim.modes(None, ...)``).

    The causes are independent: with ``processes`` > 1 they are fitted in that many forked processes
    (the same answers; a few tens of ms to start them). None: one per core
    (:func:`analysis.threads.worker_processes`: the user's thread count when given), one when the process
    may not fork (another Python thread running, a daemonic worker, no ``fork`` on the platform)."""
    causes = [c for c in sim.causes() if names is None or c.name in names]
    n = _cause_processes(len(causes), processes)
    if n > 1:
        fits = _fit_causes_forked(sim, causes, mm, fmax, n, rule)
    else:
        fits = [_fit_one_cause(sim, causes, i, mm, fmax, rule) for i in range(len(causes))]
    out = [f for f in fits if f is not None]
    out.sort(key=lambda x: x.chi2_cv)
    return out


def _fit_one_cause(sim: PhysicalSimulation, causes: Sequence[CauseSpec], i: int, mm: MeasuredModes,
                   fmax: float, rule: DecisionRule = DEFAULT_RULE) -> PhysicalFit | None:
    """Cause ``causes[i]``: its best variant, refitted on the full model when the reduced model disagreed."""
    cause = causes[i]
    progress("diagnosis: physical cause %d/%d, %s", i + 1, len(causes), cause.name)
    best = _best_variant(sim, cause, mm, fmax, rule)
    if best is not None and not _agrees_with_full_model(sim, cause, best, mm, fmax):
        log.warning("diagnosis: %s refitted on the full model (its reduced model disagreed)", cause.name)
        best = _best_variant(_FullModel(sim), cause, mm, fmax, rule)
    return best


def _cause_processes(n_causes: int, processes: int | None) -> int:
    """Processes for ``n_causes`` causes (:func:`physical_causes`)."""
    import multiprocessing
    import threading

    from ..threads import worker_processes

    if n_causes < 2 or "fork" not in multiprocessing.get_all_start_methods() or multiprocessing.current_process().daemon:
        return 1
    if processes is None:
        if threading.active_count() > 1:      # forking beside another thread may copy a lock it holds
            return 1
        processes = worker_processes()
    return max(1, min(int(processes), n_causes))


#: What the forked processes of :func:`_fit_causes_forked` read: (sim, causes, measured modes, fmax, rule).
_FORKED: tuple | None = None


def _one_blas_thread() -> None:
    """A forked process computes with one BLAS thread (the processes share the cores)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return
    threadpool_limits(1)


def _fit_forked_cause(i: int) -> PhysicalFit | None:
    sim, causes, mm, fmax, rule = _FORKED  # type: ignore[misc]
    return _fit_one_cause(sim, causes, i, mm, fmax, rule)


def _fit_causes_forked(sim: PhysicalSimulation, causes: Sequence[CauseSpec], mm: MeasuredModes, fmax: float,
                       n: int, rule: DecisionRule = DEFAULT_RULE) -> list[PhysicalFit | None]:
    """:func:`_fit_one_cause` of every cause in ``n`` forked processes (they inherit the simulation and
    its kept answers; only the fits come back), in the causes' order."""
    import multiprocessing

    global _FORKED
    _FORKED = (sim, causes, mm, fmax, rule)
    try:
        with multiprocessing.get_context("fork").Pool(n, initializer=_one_blas_thread) as pool:
            return pool.map(_fit_forked_cause, range(len(causes)), chunksize=1)
    finally:
        _FORKED = None


#: A fit's chi2 on the full model may differ from the reduced model's by this (absolute plus relative).
FULL_MODEL_CHI2_TOL = (0.01, 1e-3)


class _FullModel:
    """A simulation that solves candidates approximately (``exact_modes_of``: e.g. a reduced FE model)
    seen through its exact solver."""

    def __init__(self, sim: PhysicalSimulation) -> None:
        self.sim = sim

    def causes(self) -> Sequence[CauseSpec]:
        return self.sim.causes()

    def modes(self, cause: str | None, params: Mapping, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        return self.modes_of([] if cause is None else [(cause, params)], max_freq_hz)

    def modes_of(self, changes: Sequence[tuple[str, Mapping]], max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        return self.sim.exact_modes_of(changes, max_freq_hz)  # type: ignore[attr-defined]

    def model(self, cause: str | None, params: Mapping) -> ModalModel:
        return self.sim.model(cause, params)

    def model_of(self, changes: Sequence[tuple[str, Mapping]]) -> ModalModel:
        return self.sim.model_of(changes)


def _agrees_with_full_model(sim: PhysicalSimulation, cause: CauseSpec, fit: PhysicalFit, mm: MeasuredModes,
                            fmax: float) -> bool:
    """Does the chosen fit's chi2 on all modes hold on the full model (``exact_modes_of``, when the
    simulation has one) within ``FULL_MODEL_CHI2_TOL``? A simulation without one is exact already."""
    if not hasattr(sim, "exact_modes_of"):
        return True
    f, P = sim.exact_modes_of([(cause.name, fit.params)], fmax)
    chi2 = float(np.sum(residuals(mm, f, P) ** 2))
    atol, rtol = FULL_MODEL_CHI2_TOL
    return abs(chi2 - fit.chi2) <= atol + rtol * fit.chi2


def paired_well(mm: MeasuredModes, f: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Mask of the measured modes that pair with a mode of (f, P) by frequency (ratio within
    ``exp(PAIR_MAX_LOG_RATIO)``) and MAC (>= ``PAIR_MIN_MAC``)."""
    idx, macs = pair(mm, f, P)
    ok = idx >= 0
    good = np.zeros(mm.freq_hz.size, bool)
    good[ok] = (np.abs(np.log(f[idx[ok]] / mm.freq_hz[ok])) <= PAIR_MAX_LOG_RATIO) & (macs[ok] >= PAIR_MIN_MAC)
    return good


def same_structure(mm: MeasuredModes, f: np.ndarray, P: np.ndarray,
                   good: np.ndarray | None = None) -> tuple[bool, str]:
    """Do the measured modes pair with the simulation's by frequency and MAC? At least half of them
    must (:func:`paired_well`; ``good`` is its mask when the caller has it)."""
    good = paired_well(mm, f, P) if good is None else good
    n = int(good.sum())
    if 2 * n >= mm.freq_hz.size and n > 0:
        return True, ""
    return False, (f"not the same structure: only {n} of the {mm.freq_hz.size} measured modes pair with the "
                   f"simulation's by frequency (within {100 * (np.exp(PAIR_MAX_LOG_RATIO) - 1):.0f} %) and MAC "
                   f"(>= {PAIR_MIN_MAC}); check that the measured points are the simulation's points")


def shown_params(cause: CauseSpec, params: Mapping) -> dict:
    """The parameters as reported: every parameter of the cause (the nominal for those not freed),
    the choice, and derived values (``factor`` = sqrt(stiffness_factor) for ``stiffness_shift``)."""
    out: dict = {}
    if cause.choice is not None:
        out[cause.choice] = params[cause.choice]
    for s in cause.params:
        out[s.name] = float(params.get(s.name, s.nominal if s.nominal is not None else np.nan))
    if cause.name == "stiffness_shift":
        out["factor"] = float(np.sqrt(out["stiffness_factor"]))
    return out

