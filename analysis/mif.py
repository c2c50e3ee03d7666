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

__all__ = ["cmif", "mif"]


def cmif(frf: FRFSet) -> np.ndarray:
    """Singular values of the FRF matrix at every line: shape ``(n_freq, min(n_out, n_ref))``,
    largest first, in the unit of ``frf.H``. Non-finite lines come back as NaN."""
    Hk = np.moveaxis(np.asarray(frf.H), 2, 0)  # (n_freq, n_out, n_ref)
    finite = np.all(np.isfinite(Hk), axis=(1, 2))
    out = np.full((Hk.shape[0], min(Hk.shape[1], Hk.shape[2])), np.nan)
    if np.any(finite):
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
