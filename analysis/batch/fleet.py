"""Resonance inspection of a fleet: modes paired across units, robust statistics, outlier flags.

Pure numpy/scipy over :class:`~analysis.batch.unit_modes.UnitModes`; no files, no Dask.

The method, per unit ``u`` and reference mode ``k`` (reference: a given fit, or the fleet's median
unit, :func:`median_unit`):

1. **Pairing** (:func:`pair_modes`). The unit's *common shift* ``c_u`` is the median of
   ``ln(f_u / f_ref)`` over its nearest modes; each reference mode is then paired with at most one
   mode of the unit by an optimal assignment (Hungarian) on the cost
   ``((ln(f_uj / f_ref,k) - c_u) / 0.005)^2 + 4 (1 - MAC_kj)``, pairs further than ``tol`` (5 %)
   apart after the common shift are not allowed. ``c_u`` is re-estimated from the pairs.
2. **The unit's pattern.** ``d_uk = ln(f_uk / f_ref,k) - c_u``: the shift of mode k beyond the
   unit's common shift. Material scatter (modulus, density) scales every frequency alike and lands
   in ``c_u``; a local defect (a crack, a soft joint, a loose support) shifts modes by different
   amounts and shows in ``d_uk``.
3. **Robust statistics** per mode over the units that have it: median ``m_k`` and
   ``s_k = 1.4826 MAD`` (the standard deviation for normal data; one outlier in ten does not move
   them), ``s_k`` floored by the median of the fits' own relative standard deviations.
4. **Flags.** A unit is an outlier when, for some mode found in at least ``min_found`` of the
   units, ``|d_uk - m_k| > z_limit s_k`` and ``> min_shift`` (both: statistically and
   practically significant), or its common shift is an
   outlier of the fleet's common shifts by the same two rules (every mode off alike: a wrong
   material or geometry). The reasons name the mode, the shift in %, and the distance in robust
   standard deviations. A mode the unit lacks is a note, not a flag: the automatic fit misses a
   weak mode now and then in good units too, and a defect that moves a mode out of its pairing
   window moves others that do pair.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..mac import mac_matrix
from .unit_modes import UnitModes

__all__ = ["Pairing", "FleetMode", "UnitFlags", "FleetResult", "pair_modes", "median_unit", "assess_fleet",
           "robust_center_spread", "MIN_PAIRED_FRACTION"]

_MAD_TO_SIGMA = 1.4826

#: a unit (or a simulation) whose modes pair with fewer than this fraction of the reference's judged
#: modes is not the same structure (-)
MIN_PAIRED_FRACTION = 0.5


@dataclass(frozen=True)
class Pairing:
    """How one unit's modes pair with the reference's: ``index[k]`` is the unit's mode paired with
    reference mode k (-1: none), ``mac[k]`` its MAC (NaN: no common outputs or not paired),
    ``common_shift`` the median ln(f_unit / f_ref) over the pairs (-)."""

    index: np.ndarray
    mac: np.ndarray
    common_shift: float


@dataclass(frozen=True)
class FleetMode:
    """One reference mode across the fleet: reference frequency (Hz), how many units have it, the
    median and robust spread of the units' pattern shift (%), median frequency (Hz) and damping (-)."""

    index: int
    ref_freq_hz: float
    found: int
    found_fraction: float
    assessed: bool
    shift_median_pct: float
    shift_spread_pct: float
    freq_median_hz: float
    damping_median: float
    damping_spread: float


@dataclass
class UnitFlags:
    """One unit's outcome: paired modes, its pattern shifts and their distances, the verdict."""

    name: str
    file: str
    status: str                               # "ok" or "error"
    error: str | None = None
    flagged: bool = False
    reasons: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)      # what is odd but not a flag (a weak mode not found)
    common_shift_pct: float = float("nan")
    pairing: Pairing | None = None
    shift_pct: np.ndarray = field(default_factory=lambda: np.zeros(0))   # per reference mode, NaN: not paired
    z: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass
class FleetResult:
    """The fleet: reference (a unit's name or a file), its modes' statistics, every unit's flags,
    and the rules' thresholds."""

    reference: str
    modes: list[FleetMode]
    units: list[UnitFlags]
    common_shift_median_pct: float
    common_shift_spread_pct: float
    rules: dict


def robust_center_spread(x: np.ndarray) -> tuple[float, float]:
    """Median and 1.4826 x median absolute deviation of the finite values of ``x`` (NaN, NaN if none)."""
    v = np.asarray(x, float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan"), float("nan")
    med = float(np.median(v))
    return med, _MAD_TO_SIGMA * float(np.median(np.abs(v - med)))


def _common_outputs(a: UnitModes, b: UnitModes) -> tuple[np.ndarray, np.ndarray]:
    common = [o for o in a.outputs if o in b.outputs]
    return (a.shapes[[a.outputs.index(o) for o in common]], b.shapes[[b.outputs.index(o) for o in common]])


def pair_modes(ref: UnitModes, unit: UnitModes, tol: float = 0.05) -> Pairing:
    """Pair the modes of ``unit`` with those of ``ref`` (see the module's step 1); ``tol`` is the
    largest relative frequency difference (-) after the common shift."""
    n_ref = ref.n_modes
    index = -np.ones(n_ref, int)
    mac = np.full(n_ref, np.nan)
    if n_ref == 0 or unit.n_modes == 0:
        return Pairing(index, mac, float("nan"))
    L = np.log(unit.freq_hz[None, :] / ref.freq_hz[:, None])            # (n_ref, n_unit)
    nearest = L[np.arange(n_ref), np.argmin(np.abs(L), axis=1)]
    close = nearest[np.abs(nearest) < 0.25]               # a first guess, wider than tol: a whole unit may be off
    c = float(np.median(close)) if close.size else 0.0
    sa, sb = _common_outputs(ref, unit)
    M = mac_matrix(sa, sb) if sa.shape[0] >= 2 else np.full(L.shape, np.nan)
    for _ in range(2):
        dev = L - c
        cost = (dev / 0.005) ** 2 + np.where(np.isfinite(M), 4.0 * (1.0 - M), 0.0)
        allowed = np.abs(dev) <= tol
        big = 1e6 + cost.max(initial=0.0)
        rows, cols = linear_sum_assignment(np.where(allowed, cost, big))
        keep = allowed[rows, cols]
        index[:] = -1
        index[rows[keep]] = cols[keep]
        paired = index >= 0
        if not paired.any():
            break
        c_new = float(np.median(L[paired, index[paired]]))
        if abs(c_new - c) < 1e-9:
            break
        c = c_new
    paired = index >= 0
    mac[paired] = M[paired, index[paired]]
    return Pairing(index, mac, c if paired.any() else float("nan"))


def median_unit(units: Sequence[UnitModes], clip: float = 0.03, max_sample: int = 101) -> int:
    """Index of the fleet's median unit (a medoid): the unit whose modes are closest, in the median
    over the other units, to theirs (each distance: mean over both units' modes of the nearest
    |ln f ratio|, clipped at ``clip`` so a missing or extra mode counts once, not without bound).
    Units with more than ``max_sample`` members are compared with an evenly spaced sample."""
    usable = [i for i, u in enumerate(units) if u.n_modes > 0]
    if not usable:
        raise ValueError("no unit has any mode: nothing to take as the reference")
    sample = usable if len(usable) <= max_sample else [usable[int(j)] for j in
                                                       np.linspace(0, len(usable) - 1, max_sample).round()]
    logs = {i: np.log(units[i].freq_hz) for i in usable}

    def dist(a: np.ndarray, b: np.ndarray) -> float:
        d = np.abs(a[:, None] - b[None, :])
        return 0.5 * (float(np.minimum(d.min(axis=1), clip).mean()) + float(np.minimum(d.min(axis=0), clip).mean()))

    best, best_cost = usable[0], np.inf
    for i in usable:
        cost = float(np.median([dist(logs[i], logs[j]) for j in sample if j != i] or [0.0]))
        if cost < best_cost - 1e-15:
            best, best_cost = i, cost
    return best


def assess_fleet(units: Sequence[UnitModes | None], names: Sequence[str], files: Sequence[str], *,
                 reference: UnitModes | None = None, reference_name: str = "", errors: Sequence[str | None] = (),
                 tol: float = 0.05, z_limit: float = 6.0, min_shift_pct: float = 0.5, min_found: float = 0.9,
                 common_min_shift_pct: float = 3.0) -> FleetResult:
    """Pair, measure and flag every unit (see the module docstring). ``units[i]`` None (with
    ``errors[i]`` the reason) is a unit with no result: listed, not assessed, not flagged."""
    errs = list(errors) + [None] * (len(units) - len(errors))
    ok = [i for i, u in enumerate(units) if u is not None and u.n_modes > 0]
    if reference is None:
        if not ok:
            raise ValueError("no unit has a usable fit: the fleet has no reference")
        usable = [u for u in units if u is not None and u.n_modes > 0]
        r = ok[median_unit(usable)]
        reference, reference_name = units[r], names[r]
    assert reference is not None
    n_ref = reference.n_modes
    out: list[UnitFlags] = []
    D = np.full((len(units), n_ref), np.nan)        # pattern shift ln(f/f_ref) - c_u (-)
    F, Z, S = (np.full((len(units), n_ref), np.nan) for _ in range(3))   # paired f (Hz), zeta, f std (Hz)
    for i, u in enumerate(units):
        flags = UnitFlags(name=names[i], file=files[i], status="ok" if i in ok else "error",
                          error=errs[i] if i not in ok else None)
        if i not in ok:
            flags.error = flags.error or "the fit found no modes"
        else:
            assert u is not None
            p = pair_modes(reference, u, tol)
            flags.pairing = p
            flags.common_shift_pct = 100.0 * p.common_shift
            got = p.index >= 0
            D[i, got] = np.log(u.freq_hz[p.index[got]] / reference.freq_hz[got]) - p.common_shift
            F[i, got], Z[i, got], S[i, got] = (a[p.index[got]] for a in (u.freq_hz, u.damping, u.freq_std_hz))
        out.append(flags)
    n_ok = max(len(ok), 1)
    found = np.sum(np.isfinite(D), axis=0)
    rel_std = np.full(n_ref, np.nan)
    modes: list[FleetMode] = []
    centre = np.zeros(n_ref)
    spread = np.zeros(n_ref)
    for k in range(n_ref):
        m, s = robust_center_spread(D[:, k])
        rel = S[:, k] / F[:, k]
        rel_std[k] = float(np.nanmedian(rel)) if np.isfinite(rel).any() else 0.0
        centre[k], spread[k] = m, max(s if np.isfinite(s) else 0.0, rel_std[k], 1e-5)
        fk = F[np.isfinite(F[:, k]), k]
        zm, zs = robust_center_spread(Z[:, k])
        modes.append(FleetMode(index=k, ref_freq_hz=float(reference.freq_hz[k]), found=int(found[k]),
                               found_fraction=float(found[k]) / n_ok, assessed=bool(found[k] >= min_found * n_ok),
                               shift_median_pct=100 * m, shift_spread_pct=100 * spread[k],
                               freq_median_hz=float(np.median(fk)) if fk.size else float("nan"),
                               damping_median=zm, damping_spread=zs))
    cs = np.nan_to_num(np.array([out[i].common_shift_pct for i in ok]) / 100.0)
    c_med, c_spread = robust_center_spread(cs)
    c_spread = max(c_spread if np.isfinite(c_spread) else 0.0, 1e-5)
    for i in ok:
        f = out[i]
        f.shift_pct = 100.0 * (D[i] - centre)
        f.z = (D[i] - centre) / spread
        for k, mode in enumerate(modes):
            if not mode.assessed:
                continue
            where = f"mode {k + 1} ({mode.ref_freq_hz:.1f} Hz)"
            if not np.isfinite(D[i, k]):
                f.notes.append(f"{where}: not found within {100 * tol:g} % (found in {100 * mode.found_fraction:.0f} % "
                                 "of the units)")
            elif abs(f.z[k]) > z_limit and abs(f.shift_pct[k]) > min_shift_pct:
                f.reasons.append(f"{where}: {f.shift_pct[k]:+.2f} % from the fleet beyond the unit's common shift "
                                 f"({abs(f.z[k]):.0f} robust sigma; fleet spread {100 * spread[k]:.3f} %)")
        judged = [k for k, m in enumerate(modes) if m.assessed]
        n_pair = sum(np.isfinite(D[i, k]) for k in judged)
        if judged and n_pair < MIN_PAIRED_FRACTION * len(judged):
            f.reasons.append(f"only {n_pair} of the fleet's {len(judged)} modes pair with the reference's "
                             f"(within {100 * tol:g} % after the unit's common shift): a different structure?")
        zc = (cs[ok.index(i)] - c_med) / c_spread
        dc = 100.0 * (cs[ok.index(i)] - c_med)
        if abs(zc) > z_limit and abs(dc) > common_min_shift_pct:
            f.reasons.append(f"every mode {dc:+.2f} % from the fleet ({abs(zc):.0f} robust sigma): material or geometry")
        f.flagged = bool(f.reasons)
    rules = {"pairing_tolerance_pct": 100 * tol, "z_limit": z_limit, "min_shift_pct": min_shift_pct,
             "min_found_fraction": min_found, "common_min_shift_pct": common_min_shift_pct,
             "spread": "1.4826 x median absolute deviation, floored by the fits' median relative std"}
    return FleetResult(reference=reference_name, modes=modes, units=out, common_shift_median_pct=100 * c_med,
                       common_shift_spread_pct=100 * c_spread, rules=rules)
