"""Mode indicator functions: where the FRFs say a mode is, independent of any fit.

Two indicators, each computed once here for the fitter, the plots and the report:

**CMIF** (complex mode indicator function, Shih et al. 1988). At every line ``k`` the FRF matrix
``H_k = H[:, :, k]`` (n_out x n_ref) is decomposed as ``H_k = U_k S_k V_k^H``; the CMIF is the set of
singular values ``s_1(k) >= s_2(k) >= ...`` (min(n_out, n_ref) curves, unit of ``H``). A peak of
``s_1`` marks a mode; a peak of ``s_2`` at (or near) the same line marks a second mode there, a
repeated or close pair that more references can separate. The number of curves that stand above
the noise at a line bounds the number of modes that contribute there.

**MIF** (the real-normal mode indicator function, for one reference). For a reference ``r`` and
the receptance form ``D = H / (j omega)^p``::

    MIF_r(k) = sum_o |Re D[o, r, k]| |D[o, r, k]| / sum_o |D[o, r, k]|^2

It lies in [0, 1] and dips towards 0 at a lightly damped normal mode (the response is then in
quadrature with the force, its real part vanishes) and is near 1 between modes. The conversion
to receptance matters for mobility, where the real and imaginary parts swap roles;
for accelerance the factor -omega^2 is real and changes nothing.
"""
from __future__ import annotations

import numpy as np

from .frf import QUANTITY_POWER, FRFSet

__all__ = ["SUMMARY_CURVES", "cmif", "indicator_summary", "mif", "summed_magnitude_db"]


def summed_magnitude_db(frf: FRFSet) -> np.ndarray:
    """20 log10 of the root-sum-square magnitude of all FRFs per line (a CMIF-like background), dB re 1
    unit of ``frf.H``; zeros floored 240 dB below the largest."""
    s = np.sqrt(np.nansum(np.abs(frf.H.reshape(-1, frf.freq_hz.size)) ** 2, axis=0))
    floor = max(float(np.max(s)) * 1e-12, 1e-300)
    return 20 * np.log10(np.maximum(s, floor))


#: outputs per reference from which the CMIF is computed from ``H^H H`` (n_ref x n_ref per line)
TALL_RATIO = 16


def cmif(frf: FRFSet) -> np.ndarray:
    """Singular values of the FRF matrix at every line: shape ``(n_freq, min(n_out, n_ref))``,
    largest first, in the unit of ``frf.H``. Non-finite lines come back as NaN."""
    Hk = np.moveaxis(np.asarray(frf.H), 2, 0)  # (n_freq, n_out, n_ref)
    finite = np.all(np.isfinite(Hk), axis=(1, 2))
    out = np.full((Hk.shape[0], min(Hk.shape[1], Hk.shape[2])), np.nan)
    if np.any(finite):
        n_out, n_ref = Hk.shape[1], Hk.shape[2]
        if n_out >= TALL_RATIO * n_ref:
            # many outputs (a scanning test): the eigenvalues of the small H^H H, not an SVD of
            # every tall matrix; the curves lose only what lies 150 dB under their top
            H = np.asarray(frf.H)
            G = np.empty((H.shape[-1], n_ref, n_ref), dtype=complex)
            for r in range(n_ref):
                for q in range(r, n_ref):
                    a, b = H[:, r], H[:, q]   # sum_o conj(a) b in real arithmetic (no temporaries)
                    G[:, r, q] = (np.einsum("ok,ok->k", a.real, b.real) + np.einsum("ok,ok->k", a.imag, b.imag)
                                  + 1j * (np.einsum("ok,ok->k", a.real, b.imag)
                                          - np.einsum("ok,ok->k", a.imag, b.real)))
                    G[:, q, r] = G[:, r, q].conj()
            G = G[finite]
            ev = np.linalg.eigvalsh(G)[:, ::-1]
            out[finite] = np.sqrt(np.clip(ev, 0.0, None))
        else:
            out[finite] = np.linalg.svd(Hk[finite], compute_uv=False)
    return out


def mif(frf: FRFSet, reference: int = 0) -> np.ndarray:
    """The real-normal MIF of one reference column: shape ``(n_freq,)``, dimensionless in [0, 1],
    near 0 at a lightly damped mode. Lines where the receptance is undefined (f = 0) or all
    responses are zero come back as NaN."""
    if not 0 <= reference < frf.n_references:
        raise ValueError(f"reference index {reference} is outside 0..{frf.n_references - 1}")
    p = QUANTITY_POWER[frf.quantity]
    jw = 1j * frf.omega
    with np.errstate(divide="ignore", invalid="ignore"):
        D = np.asarray(frf.H)[:, reference, :] / jw ** p
        num = np.sum(np.abs(D.real) * np.abs(D), axis=0)
        den = np.sum(np.abs(D) ** 2, axis=0)
        out = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)
    out[~np.isfinite(out)] = np.nan
    return np.clip(out, 0.0, 1.0)


#: curves of a CMIF summary (the strongest singular values; more are rarely above the noise)
SUMMARY_CURVES = 4


def indicator_summary(frf: FRFSet, band: tuple[float, float] | None = None, max_points: int = 400) -> dict:
    """A compact, JSON-able view of the mode indicators over ``band`` (Hz; default: all lines).

    The lines are grouped into at most ``max_points`` consecutive bins; each bin is represented by
    its line where the first CMIF curve peaks, so peaks survive the reduction. Keys:
    ``freq_hz`` (Hz), ``cmif_db`` (the first :data:`SUMMARY_CURVES` singular values per bin,
    dB re 1 unit of ``frf.H``, one list per curve, None where undefined), ``mif`` (the real-normal
    MIF of reference 0 at the same lines, dimensionless, only when there is one reference; else
    None), ``lines`` (how many lines the band holds) and ``unit``.
    """
    if max_points < 2:
        raise ValueError(f"max_points must be >= 2; got {max_points}")
    f = np.asarray(frf.freq_hz, float)
    lo, hi = (float(f[0]), float(f[-1])) if band is None else (float(band[0]), float(band[1]))
    idx = np.flatnonzero((f >= lo) & (f <= hi))
    s = cmif(frf)[idx, :SUMMARY_CURVES]
    with np.errstate(divide="ignore"):
        s_db = 20 * np.log10(s)
    s_db[~np.isfinite(s_db)] = np.nan
    edges = np.linspace(0, idx.size, min(idx.size, max_points) + 1).astype(int)
    pick = []
    for a, b in zip(edges[:-1], edges[1:]):
        seg = s_db[a:b, 0]
        pick.append(a + (int(np.nanargmax(seg)) if np.any(np.isfinite(seg)) else 0))
    sel = np.asarray(pick, dtype=int)

    def _list(x: np.ndarray, decimals: int) -> list:
        r = np.round(x, decimals)
        return [None if not np.isfinite(v) else float(v) for v in r]

    mif_curve = mif(frf, 0)[idx][sel] if frf.n_references == 1 else None
    return {"freq_hz": _list(f[idx][sel], 4), "cmif_db": [_list(s_db[sel, k], 2) for k in range(s_db.shape[1])],
            "mif": None if mif_curve is None else _list(mif_curve, 4), "lines": int(idx.size),
            "unit": frf.unit or ""}
