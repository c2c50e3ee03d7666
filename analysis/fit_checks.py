"""Checks of an LSFD result against its starting poles: migrated poles and duplicates.

All tests are measured in half-power bandwidths ``b = 2 zeta f_n`` (Hz) of the poles *as
fitted to the data* (``poles_raw``: the exponential window's damping included, because that
is the width the data show), floored at two spectral lines (``2 df``) so a pole sharper than
the frequency resolution still gets a sensible scale.

Migrated pole
    ``|f_end - f_start| > MIGRATE_BANDWIDTHS * max(b_start, b_end, 2 df)``. A weak initial
    pole that the data do not support is not pushed to zero residue by the nonlinear fit: it
    slides down the cost surface onto a strong neighbour and shares its resonance. A physical
    pole refined by LSFD moves by a small fraction of its bandwidth.

Duplicate pair
    two fitted poles closer than ``DUPLICATE_BANDWIDTHS`` of the larger half-bandwidth
    (``|f_a - f_b| < DUPLICATE_BANDWIDTHS * max(b_a, b_b) / 2``) *and* with residue vectors
    (all output/reference pairs, flattened) of MAC > ``DUPLICATE_MAC``: one resonance
    described twice. Two genuine close modes have different shapes (low MAC) and are kept.

Unsupported pole
    a pole with no peak of the first CMIF curve (prominence >= ``CMIF_SUPPORT_DB``) within its
    half-power bandwidth (at least two lines), a peak (prominence >= the visible peaks' 10 dB) within
    it in fewer than ``FRF_SUPPORT_SHARE`` of the FRFs, *and* a residue matrix (outputs x references) far from
    rank one (the largest singular value carries less than ``SHAPE_RANK_ONE_MIN`` of its energy): a
    mode of the structure has one shape, whichever output sees it (``R_r = psi_r L_r^T``), and a
    structure's resonance shows in the CMIF; a pole with neither is fitted to noise or to leakage
    between modes. Only sets with at least two outputs and two references can say so.

Hidden close pairs and weak modes missed by the stabilization are found from the misfit
(:mod:`analysis.pipeline`, step 7).
"""
from __future__ import annotations

import numpy as np

from .frf import FRFSet
from .mac import mac
from .modal import damping_ratio, natural_freq_hz

__all__ = [
    "bandwidth_hz",
    "migrated_poles",
    "duplicate_poles",
    "MIGRATE_BANDWIDTHS",
    "DUPLICATE_BANDWIDTHS",
    "DUPLICATE_MAC",
    "unsupported_poles",
    "CMIF_SUPPORT_DB",
    "SHAPE_RANK_ONE_MIN",
    "FRF_SUPPORT_SHARE",
]

MIGRATE_BANDWIDTHS = 3.0
DUPLICATE_BANDWIDTHS = 1.0
DUPLICATE_MAC = 0.8
CMIF_SUPPORT_DB = 3.0
SHAPE_RANK_ONE_MIN = 0.7
FRF_SUPPORT_SHARE = 0.1


def bandwidth_hz(poles: np.ndarray, df_hz: float = 0.0) -> np.ndarray:
    """Half-power bandwidth ``2 zeta f_n`` (Hz) of each pole (rad/s), at least ``2 df_hz``."""
    p = np.asarray(poles, dtype=complex)
    return np.maximum(2.0 * np.abs(damping_ratio(p)) * natural_freq_hz(p), 2.0 * float(df_hz))


def migrated_poles(start: np.ndarray, end: np.ndarray, df_hz: float = 0.0,
                   n_bandwidths: float = MIGRATE_BANDWIDTHS) -> np.ndarray:
    """Mask of poles that moved more than ``n_bandwidths`` half-power bandwidths.

    start, end : (m,) complex poles (rad/s), the same mode at the same index (raw poles, as
    fitted to the data). df_hz : line spacing (Hz) of the data. Returns (m,) bool.
    """
    s = np.asarray(start, dtype=complex)
    e = np.asarray(end, dtype=complex)
    if s.shape != e.shape:
        raise ValueError(f"start and end poles must have the same shape; got {s.shape} and {e.shape}")
    scale = np.maximum(bandwidth_hz(s, df_hz), bandwidth_hz(e, df_hz))
    return np.abs(natural_freq_hz(e) - natural_freq_hz(s)) > n_bandwidths * scale


def duplicate_poles(poles: np.ndarray, residues: np.ndarray, df_hz: float = 0.0,
                    moved: np.ndarray | None = None) -> np.ndarray:
    """Mask of poles that duplicate another one (see module docstring); the other is kept.

    poles : (m,) complex rad/s (raw); residues : (n_out, n_ref, m); moved : (m,) how far each
    pole moved during the fit (in bandwidths, any consistent measure): of a duplicate pair the
    one that moved more is flagged; without it the one with the smaller residue norm.
    Returns (m,) bool.
    """
    p = np.asarray(poles, dtype=complex)
    R = np.asarray(residues, dtype=complex).reshape(-1, p.size)
    f = natural_freq_hz(p)
    b = bandwidth_hz(p, df_hz)
    norm = np.linalg.norm(R, axis=0)
    out = np.zeros(p.size, dtype=bool)
    for i in np.argsort(f):
        for j in range(p.size):
            if j == i or out[i] or out[j]:
                continue
            if abs(f[i] - f[j]) >= DUPLICATE_BANDWIDTHS * 0.5 * max(b[i], b[j]):
                continue
            if mac(R[:, i], R[:, j]) <= DUPLICATE_MAC:
                continue
            if moved is not None and moved[i] != moved[j]:
                drop = i if moved[i] > moved[j] else j
            else:
                drop = i if norm[i] < norm[j] else j
            out[drop] = True
    return out


def unsupported_poles(frf: FRFSet, poles_raw: np.ndarray, residues: np.ndarray,
                      weights: np.ndarray | None = None) -> tuple[np.ndarray, list[str]]:
    """Mask of the poles neither the CMIF nor a consistent shape supports (module docstring), and a
    reason for each. ``poles_raw`` : (m,) complex rad/s as fitted to the data; ``residues`` : (n_out,
    n_ref, m); ``weights`` : (n_out, n_ref) the fit's FRF weights (1 / noise level): the shape is judged
    as measured against each FRF's noise. Sets with fewer than two outputs or two references: nothing
    is flagged."""
    from .mif import cmif
    from .peaks import PEAK_RULES

    p = np.asarray(poles_raw, dtype=complex)
    R = np.asarray(residues, dtype=complex)
    if weights is not None:
        R = R * np.asarray(weights, dtype=float)[..., None]
    out = np.zeros(p.size, dtype=bool)
    if R.ndim != 3 or R.shape[0] < 2 or R.shape[1] < 2 or p.size == 0:
        return out, []
    f = frf.freq_hz
    df = float(frf.line_spacing_hz)
    fn = natural_freq_hz(p)
    bw = bandwidth_hz(p, df)

    def peaks_hz(curve: np.ndarray, rule: str) -> np.ndarray:
        with np.errstate(divide="ignore"):
            db = 20.0 * np.log10(np.maximum(np.nan_to_num(curve, nan=0.0), 1e-300))
        return f[PEAK_RULES[rule].find(db)[0]]

    cmif_hz = peaks_hz(cmif(frf)[:, 0], "cmif_support")
    H = np.abs(np.asarray(frf.H)).reshape(-1, f.size)
    frf_hz = [peaks_hz(h, "visible") for h in H]
    why: list[str] = []
    for k in range(p.size):
        if cmif_hz.size and np.min(np.abs(cmif_hz - fn[k])) <= bw[k]:
            continue
        share = float(np.mean([x.size > 0 and np.min(np.abs(x - fn[k])) <= bw[k] for x in frf_hz]))
        if share >= FRF_SUPPORT_SHARE:
            continue
        s = np.linalg.svd(R[:, :, k], compute_uv=False)
        energy = float(np.sum(s ** 2))
        rank_one = float(s[0] ** 2) / energy if energy > 0 else 0.0
        if rank_one < SHAPE_RANK_ONE_MIN:
            out[k] = True
            why.append(f"{fn[k]:.5g} Hz: no CMIF peak within its bandwidth, a peak there in {100 * share:.0f} % of "
                       f"the FRFs, and shapes that disagree between outputs (rank-one share {rank_one:.2f} < "
                       f"{SHAPE_RANK_ONE_MIN:g})")
    return out, why
