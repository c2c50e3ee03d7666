"""Stabilization diagrams: poles of growing model order, each flagged by how stable it is.

For model sizes n = 1..max_modes the initial-pole method (LSCE or LSCF) gives a set of
poles. A pole is *physical* when its damped frequency lies in the band and its damping
ratio is in ``(0, max_damping)``. Each physical pole of order n is compared with the
nearest (in natural frequency) physical pole of order n - 1:

====== ========== =================================================================
class  name       condition (all relative to the previous-order pole)
====== ========== =================================================================
0      new        no previous pole within ``tol_freq``
1      freq       ``|f - f'| / f' < tol_freq``
2      damp       freq and ``|zeta - zeta'| < max(tol_damp zeta', abs_tol_damp)``
3      mac        damp and ``1 - MAC(psi, psi') < tol_mac``
====== ========== =================================================================

The damping test is relative-plus-absolute: a very lightly damped mode (zeta ~ 0.05 %) has
a damping estimate that scatters by more than 5 % of itself from order to order while its
frequency is rock-stable; ``abs_tol_damp`` (default 0.05 % of critical) keeps it.

The mode shapes ``psi`` come from a quick linear least-squares residue fit at each order
(:func:`quick_residues`): with the poles fixed, the FRFs are linear in the residues. To
stay fast on large sets, that fit uses at most ``MAX_SHAPE_LINES`` lines (a uniform
decimation of the band) and the FRFs projected on an orthonormal basis of their dominant
column space (randomized range finder; MAC is unchanged by that orthonormal projection,
up to the discarded noise).

A wide band (``wide_band=True``, the ``stabilization`` command's choice) is taken in sub-bands: a
band whose top is more than ``MAX_BAND_RATIO`` times its bottom holds weak low modes beside strong
high ones, and one model of the whole band spends its poles on the strong modes (a modal-test
engineer zooms in). The band is cut into sub-bands of equal logarithmic width (at most
``MAX_BAND_RATIO`` each), each cut moved to the lowest line of the summed FRF power within
``CUT_SEARCH`` of it (between resonances, never through one); each sub-band is fitted with
``SUB_BAND_OVERLAP`` more on either side and keeps the poles of its own part. The diagram's order n
is then the model size of each sub-band (none above what its lines support).

``refine_lsfd=True`` refines the physical poles of every order with a few iterations of
the nonlinear LSFD fitter (:func:`analysis.lsfd.fit_lsfd`), which gives the paper's LSFD
stabilization diagram (Fig. 8: "estimated pole lines are straight, not branched off");
the MAC then uses the LSFD residues.
"""
from __future__ import annotations

import logging
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .frf import FRFSet
from .lscf import BandData, prepare_band
from .mac import mac_matrix
from .modal import damping_ratio, natural_freq_hz, residual_basis
from .threads import limits_blas_threads

__all__ = [
    "StabilizationResult",
    "stabilization",
    "quick_residues",
    "CLASS_NAMES",
    "NEW",
    "STABLE_FREQ",
    "STABLE_DAMP",
    "STABLE_MAC",
    "ABS_TOL_DAMP",
]

log = logging.getLogger(__name__)

NEW, STABLE_FREQ, STABLE_DAMP, STABLE_MAC = 0, 1, 2, 3
CLASS_NAMES = ("new", "freq", "freq+damp", "freq+damp+mac")
METHODS = ("lsce", "lscf")
MAX_SHAPE_LINES = 1024
#: absolute damping-ratio tolerance of the damping-stability test (0.05 % of critical)
ABS_TOL_DAMP = 5e-4
#: ``wide_band``: largest top-to-bottom frequency ratio of one sub-band
MAX_BAND_RATIO = 8.0
#: ``wide_band``: a cut moves to the lowest summed FRF power within this factor of its place
CUT_SEARCH = 1.25
#: ``wide_band``: each sub-band is fitted this fraction wider on either side than the part it keeps
SUB_BAND_OVERLAP = 0.1
#: ``wide_band``: fewest lines a sub-band may hold (fewer: it joins its neighbour)
MIN_SUB_BAND_LINES = 48


@dataclass(frozen=True)
class StabilizationResult:
    """Poles per model order with their stability class.

    orders : model sizes n (number of modes of each model).
    poles : per order, (m,) complex poles in rad/s (upper half plane), all of them (with
        ``refine_lsfd``: the refined poles of that order's physical poles).
    physical : per order, bool mask: in band and 0 < zeta < max_damping.
    status : per order, int class per pole (see module docstring); -1 for non-physical poles.
    mac : per order, MAC with the matched pole of the previous order (NaN when unmatched).
    method : "lsce" or "lscf" (+ "+lsfd" when refined).
    band : (lo_hz, hi_hz) used.
    tol_freq, tol_damp, tol_mac, max_damping, abs_tol_damp : the criteria used.
    """

    orders: tuple
    poles: tuple
    physical: tuple
    status: tuple
    mac: tuple
    method: str
    band: tuple
    tol_freq: float
    tol_damp: float
    tol_mac: float
    max_damping: float
    meta: dict = field(default_factory=dict)
    abs_tol_damp: float = 0.0

    def stable_poles(self, min_class: int = STABLE_DAMP) -> tuple[np.ndarray, np.ndarray]:
        """All poles of class >= min_class over all orders: (poles rad/s, order of each)."""
        ps, os_ = [], []
        for n, p, s in zip(self.orders, self.poles, self.status):
            k = s >= min_class
            ps.append(p[k])
            os_.append(np.full(int(k.sum()), n))
        if not ps:
            return np.zeros(0, complex), np.zeros(0, int)
        return np.concatenate(ps), np.concatenate(os_)

    def to_dict(self) -> dict:
        """JSON-ready content: per order the physical poles with f (Hz), zeta, class."""
        rows = []
        for n, p, ph, s, m in zip(self.orders, self.poles, self.physical, self.status, self.mac):
            rows.append(
                {
                    "order": int(n),
                    "poles": [
                        {
                            "freq_hz": float(natural_freq_hz(p[i])),
                            "damping": float(damping_ratio(p[i])),
                            "pole": [float(p[i].real), float(p[i].imag)],
                            "class": CLASS_NAMES[int(s[i])],
                            "mac": None if not np.isfinite(m[i]) else float(m[i]),
                        }
                        for i in np.flatnonzero(ph)
                    ],
                }
            )
        return {
            "method": self.method,
            "band_hz": [float(self.band[0]), float(self.band[1])],
            "tolerances": {"freq": self.tol_freq, "damping": self.tol_damp, "mac": self.tol_mac,
                           "damping_abs": self.abs_tol_damp},
            "max_damping": self.max_damping,
            "orders": rows,
        }


def quick_residues(
    omega: np.ndarray, Y: np.ndarray, poles: np.ndarray, quantity: str, residual_form: str = "physical"
) -> np.ndarray:
    """Linear least-squares residues for fixed poles.

    Solves ``Y[o, k] ~ sum_r A_or / (j w_k - lambda_r) + B_or / (j w_k - conj lambda_r) + residuals``
    with independent complex A, B (a relaxation of B = conj A that keeps the problem
    complex-linear; exact for noise-free data). ``omega`` in rad/s. Returns A (N_o, n_poles).
    """
    jw = 1j * np.asarray(omega, dtype=float)
    lam = np.asarray(poles, dtype=complex)
    cols = [1.0 / (jw[:, None] - lam[None, :]), 1.0 / (jw[:, None] - np.conj(lam)[None, :])]
    Bres = residual_basis(omega, quantity, residual_form).T
    B = np.hstack(cols + [Bres])
    scale = np.linalg.norm(B, axis=0)
    scale[scale == 0] = 1.0
    Bs = B / scale
    # normal equations (fast; the columns are scaled to unit norm, a tiny ridge keeps
    # near-duplicate spurious poles from making the system singular)
    G = Bs.conj().T @ Bs
    G[np.diag_indices_from(G)] += 1e-10
    try:
        coef = np.linalg.solve(G, Bs.conj().T @ Y.T)
    except np.linalg.LinAlgError:
        coef = np.linalg.lstsq(Bs, Y.T, rcond=None)[0]
    coef = coef / scale[:, None]
    return coef[: lam.size].T


def _physical(poles: np.ndarray, lo: float, hi: float, max_damping: float) -> np.ndarray:
    fd = poles.imag / (2 * np.pi)
    z = damping_ratio(poles) if poles.size else np.zeros(0)
    return (fd >= lo) & (fd <= hi) & (z > 0) & (z < max_damping)


def _shape_data(bd: BandData, max_modes: int) -> tuple[np.ndarray, np.ndarray]:
    """Decimated lines (rad/s) and the FRFs projected on their dominant column space."""
    f, H = bd.freq_hz, bd.H
    step = max(1, int(np.ceil(f.size / MAX_SHAPE_LINES)))
    f, H = f[::step], H[:, ::step]
    n_keep = min(H.shape[0], 2 * max_modes + 8)
    if n_keep < H.shape[0]:
        # randomized range finder (seeded, so deterministic): Q spans the dominant columns of H;
        # MAC of Q^H psi equals MAC of psi for psi in that span
        rng = np.random.default_rng(0)
        Z = H @ (rng.standard_normal((H.shape[1], n_keep)) + 1j * rng.standard_normal((H.shape[1], n_keep)))
        Z = H @ (H.conj().T @ Z)  # one power iteration sharpens the subspace
        Q, _ = np.linalg.qr(Z)
        H = Q.conj().T @ H
    return 2 * np.pi * f, H


def _initial_poles(bd: BandData, max_modes: int, method: str) -> list[np.ndarray]:
    if method == "lsce":
        from .lsce import lsce_poles_all_orders

        return lsce_poles_all_orders(bd, max_modes)
    from .lscf import lscf_poles_all_orders

    return lscf_poles_all_orders(bd, max_modes)


def sub_band_cuts(bd: BandData) -> list[float]:
    """The cuts (Hz) of a wide band into sub-bands (module docstring); [] when one band will do."""
    lo, hi = bd.band
    f = bd.freq_hz
    k = int(np.ceil(np.log(hi / lo) / np.log(MAX_BAND_RATIO))) if lo > 0 else 1
    if k <= 1:
        return []
    power = np.sum(bd.H.real ** 2 + bd.H.imag ** 2, axis=0)
    cuts: list[float] = []
    for j in range(1, k):
        c = lo * (hi / lo) ** (j / k)
        near = np.flatnonzero((f >= c / CUT_SEARCH) & (f <= c * CUT_SEARCH))
        if near.size:
            c = float(f[near[np.argmin(power[near])]])
        edges = [lo, *cuts, c]
        if np.count_nonzero((f >= edges[-2]) & (f < c)) >= MIN_SUB_BAND_LINES:
            cuts.append(c)
    while cuts and np.count_nonzero(f >= cuts[-1]) < MIN_SUB_BAND_LINES:
        cuts.pop()
    return cuts


def _sub_band_poles(bd: BandData, cuts: Sequence[float], max_modes: int, method: str) -> list[np.ndarray]:
    """Poles per order n = 1..max_modes of a wide band taken in sub-bands at ``cuts`` (Hz, module
    docstring): the union over sub-bands of each one's model of n modes (none above what its lines
    support), keeping the poles whose damped frequency lies in its own part. The FRFs keep the scaling of
    the whole band (unit RMS there): scaled again within a sub-band, an FRF that holds mostly noise
    there would weigh as much as one that shows its modes."""
    from .bands import LINES_PER_MODE

    lo, hi = bd.band
    edges = [lo, *cuts, hi]
    parts: list[tuple[float, float, list[np.ndarray]]] = []
    for a, b in zip(edges[:-1], edges[1:]):
        ext = (max(lo, a * (1 - SUB_BAND_OVERLAP)), min(hi, b * (1 + SUB_BAND_OVERLAP)))
        keep = (bd.freq_hz >= ext[0]) & (bd.freq_hz <= ext[1])
        sub = BandData(bd.freq_hz[keep], bd.H[:, keep], ext)
        n_lines = int(sub.freq_hz.size)
        # the most modes its lines determine (LSCF: 2n + 1 coefficients; LSCE: its Hankel matrix)
        n_sub = max(1, min(max_modes, n_lines // LINES_PER_MODE if method == "lsce" else (n_lines - 1) // 2))
        parts.append((a, b, _initial_poles(sub, n_sub, method)))
    out = []
    for n in range(1, max_modes + 1):
        ps: list[np.ndarray] = []
        for j, (a, b, poles) in enumerate(parts):
            if n > len(poles):  # no repeated model above what the sub-band supports: a repeat is no evidence
                continue
            p = poles[n - 1]
            fd = p.imag / (2 * np.pi)
            own_lo = a if j > 0 else -np.inf              # the outer edges: the band's test (_physical)
            own_hi = b if j < len(parts) - 1 else np.inf
            ps.append(p[(fd >= own_lo) & (fd < own_hi)])
        allp = np.concatenate(ps) if ps else np.zeros(0, complex)
        out.append(allp[np.argsort(allp.imag)])
    return out


def _refine(frf: FRFSet, poles: np.ndarray, band: tuple[float, float],
            iterations: int) -> tuple[np.ndarray, np.ndarray | None]:
    """A few LSFD iterations from the given poles; returns (poles, flattened residues)."""
    from .lsfd import LSFDConvergenceWarning, fit_lsfd  # lazy: written by another engineer

    try:
        with warnings.catch_warnings():
            # a few iterations by design: stopping at max_iter is expected here
            warnings.simplefilter("ignore", LSFDConvergenceWarning)
            res = fit_lsfd(frf, poles, method="lm", band=band, max_iter=iterations)
    except (ValueError, np.linalg.LinAlgError, FloatingPointError) as exc:
        log.info("LSFD refinement failed (%s); keeping the initial poles", exc)
        return poles, None
    R = np.asarray(res.model.residues)
    return np.asarray(res.poles, dtype=complex), R.reshape(-1, R.shape[-1])


@limits_blas_threads
def stabilization(
    frf: FRFSet,
    max_modes: int,
    *,
    method: str = "lsce",
    band: Sequence[float] | None = None,
    refine_lsfd: bool = False,
    refine_iterations: int = 5,
    tol_freq: float = 0.01,
    tol_damp: float = 0.05,
    tol_mac: float = 0.02,
    max_damping: float = 0.2,
    min_modes: int = 1,
    abs_tol_damp: float = ABS_TOL_DAMP,
    wide_band: bool = False,
) -> StabilizationResult:
    """Stabilization diagram of models with n = min_modes..max_modes modes.

    Parameters
    ----------
    frf : the FRFs.
    max_modes : largest model size (number of modes; the polynomial order is 2 max_modes).
    method : "lsce" (zoomed impulse responses) or "lscf" (z-domain common denominator).
    band : (lo_hz, hi_hz) or None for all lines.
    refine_lsfd : refine each order's physical poles with ``refine_iterations`` LSFD steps.
    tol_freq, tol_damp, tol_mac : relative frequency, relative damping and 1 - MAC tolerances.
    abs_tol_damp : absolute damping-ratio tolerance (a damping change below it always counts
        as stable; default 5e-4 = 0.05 % of critical).
    max_damping : damping ratios at or above this are not physical.
    wide_band : take a band wider than ``MAX_BAND_RATIO`` in sub-bands (module docstring); order n
        is then the model size of each sub-band.

    Returns
    -------
    StabilizationResult (see its docstring).
    """
    if method not in METHODS:
        raise ValueError(f"method {method!r} is not one of {METHODS}")
    max_modes = int(max_modes)
    if max_modes < 1:
        raise ValueError(f"max_modes must be >= 1; got {max_modes}")
    for name, v in (("tol_freq", tol_freq), ("tol_damp", tol_damp), ("tol_mac", tol_mac)):
        if not (v > 0):
            raise ValueError(f"{name} must be > 0; got {v}")
    if not (abs_tol_damp >= 0):
        raise ValueError(f"abs_tol_damp must be >= 0; got {abs_tol_damp}")
    bd = prepare_band(frf, band)
    lo, hi = bd.band
    cuts = sub_band_cuts(bd) if wide_band else []
    all_poles = _sub_band_poles(bd, cuts, max_modes, method) if cuts else _initial_poles(bd, max_modes, method)
    omega_s, Ys = _shape_data(bd, max_modes)
    orders, poles_out, phys_out, status_out, mac_out = [], [], [], [], []
    prev_p = np.zeros(0, complex)
    prev_shapes = np.zeros((Ys.shape[0], 0), complex)
    for n in range(max(1, int(min_modes)), max_modes + 1):
        p = all_poles[n - 1]
        phys = _physical(p, lo, hi, max_damping)
        shapes = None
        if refine_lsfd and phys.any():
            rp, R = _refine(frf, p[phys], (lo, hi), refine_iterations)
            p = rp
            phys = _physical(p, lo, hi, max_damping)
            if R is not None and R.shape[1] == p.size:
                shapes = R[:, phys]
        p_phys = p[phys]
        if shapes is None:
            shapes = quick_residues(omega_s, Ys, p_phys, frf.quantity) if p_phys.size else np.zeros((Ys.shape[0], 0))
        status = np.full(p.size, -1, dtype=int)
        macs = np.full(p.size, np.nan)
        st_phys = np.zeros(p_phys.size, dtype=int)
        mac_phys = np.full(p_phys.size, np.nan)
        if p_phys.size and prev_p.size:
            fn, fp = natural_freq_hz(p_phys), natural_freq_hz(prev_p)
            zn, zp = damping_ratio(p_phys), damping_ratio(prev_p)
            rel = np.abs(fn[:, None] - fp[None, :]) / fp[None, :]
            j = np.argmin(rel, axis=1)
            ok_f = rel[np.arange(p_phys.size), j] < tol_freq
            ok_d = ok_f & (np.abs(zn - zp[j]) < np.maximum(tol_damp * zp[j], abs_tol_damp))
            if shapes.shape[0] == prev_shapes.shape[0]:
                M = mac_matrix(shapes, prev_shapes)
                mac_phys = M[np.arange(p_phys.size), j]
                mac_phys = np.where(ok_f, mac_phys, np.nan)
            ok_m = ok_d & (1.0 - np.nan_to_num(mac_phys, nan=0.0) < tol_mac)
            st_phys = ok_f.astype(int) + ok_d.astype(int) + ok_m.astype(int)
        status[phys] = st_phys
        macs[phys] = mac_phys
        orders.append(n)
        poles_out.append(p)
        phys_out.append(phys)
        status_out.append(status)
        mac_out.append(macs)
        prev_p, prev_shapes = p_phys, shapes
    return StabilizationResult(
        orders=tuple(orders),
        poles=tuple(poles_out),
        physical=tuple(phys_out),
        status=tuple(status_out),
        mac=tuple(mac_out),
        method=method + ("+lsfd" if refine_lsfd else ""),
        band=(lo, hi),
        tol_freq=float(tol_freq),
        tol_damp=float(tol_damp),
        tol_mac=float(tol_mac),
        max_damping=float(max_damping),
        abs_tol_damp=float(abs_tol_damp),
        meta={"quantity": frf.quantity, "n_frf": int(frf.H.shape[0] * frf.H.shape[1])},
    )
