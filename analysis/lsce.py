"""Initial poles by the Least-Squares Complex Exponential method (LSCE), band-limited by zoom.

Band-limited impulse responses (zoom / band shift)
--------------------------------------------------
Only the lines of the band ``f_k = f_0 + k df`` (k = 0..N-1, uniform spacing) are used. Their
inverse DFT

    h_o[n] = (1/N) sum_k H_o(f_k) exp(+j 2 pi k n / N),   n = 0..N-1,

is the impulse response of the band shifted down by ``f_0`` (a complex signal sampled at
``dt = 1 / (N df)``). A mode ``R / (jw - lambda)`` contributes the periodised decaying
exponential ``R' z^n`` with ``z = exp((lambda - j 2 pi f_0) dt)``, exactly for the
infinite band and up to the truncation at the band edges otherwise. The conjugate
poles and the modes outside the band are not exponentials in this signal: they
act as the out-of-band residuals and are absorbed by extra (spurious) poles. No line
outside the band enters, so the low lines the paper (sec. 3.1) warns about can be left
out simply by the choice of band.

Prony / linear prediction
-------------------------
With ``m`` complex poles (here m = 2 n_modes: one per physical mode plus as many for the
residuals and conjugates), every FRF obeys the same recursion

    h_o[n + m] + sum_{i<m} a_i h_o[n + i] = 0,

solved in least squares with all FRFs stacked (one common set of ``a``). The first and last
``m`` samples (where the band truncation rings) are left out of the equations, and only
the first ``row_fraction`` (default 1/4) of the record is used: later samples hold little
but noise for all but the most lightly damped modes, and fitting noise splits the heavily
damped modes into branches. The
normal matrix ``C[i, j] = sum_o sum_n conj(h_o[n+i]) h_o[n+j]`` is built once for the
largest order; each order solves its leading block (:func:`lsce_poles_all_orders`).
The roots ``z_r`` of ``z^m + sum a_i z^i`` give the poles
``lambda_r = ln(z_r) / dt + j 2 pi f_0`` (rad/s), the angle of ``z_r`` taken in [0, 2 pi). Poles whose damped frequency falls
outside the band are aliases and are dropped; the rest (physical and spurious) are
returned.
"""
from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from .frf import FRFSet
from .lscf import BandData, prepare_band
from .threads import limits_blas_threads

__all__ = ["lsce_poles", "lsce_poles_all_orders"]

log = logging.getLogger(__name__)

ROW_FRACTION = 0.25


def _impulse_responses(frf: FRFSet | BandData, band: Sequence[float] | None
                       ) -> tuple[np.ndarray, float, float, tuple[float, float]]:
    bd = frf if isinstance(frf, BandData) else prepare_band(frf, band)
    f, H, (lo, hi) = bd.freq_hz, bd.H, bd.band
    df = np.diff(f)
    if f.size > 2 and np.ptp(df) > 1e-6 * np.mean(df):
        raise ValueError("LSCE needs uniformly spaced frequency lines; resample the FRFs or use method 'lscf'")
    step = float(np.mean(df))
    n = f.size
    h = np.fft.ifft(H, axis=1)
    dt = 1.0 / (n * step)
    return h, dt, float(f[0]), (lo, hi)


@limits_blas_threads
def lsce_poles_all_orders(frf: FRFSet | BandData, max_modes: int, *, band: Sequence[float] | None = None,
                          row_fraction: float = ROW_FRACTION) -> list[np.ndarray]:
    """LSCE poles (rad/s, Im > 0, in band, sorted by damped frequency) for n = 1..max_modes.

    See the module docstring for the band-limited (zoom) impulse responses and the
    linear prediction; model n has 2 n complex poles. ``row_fraction`` is the share of the
    impulse-response record used for equations (at least 4 equations per unknown).
    """
    if not 0 < row_fraction <= 1:
        raise ValueError(f"row_fraction must be in (0, 1]; got {row_fraction}")
    if int(max_modes) < 1:
        raise ValueError(f"number of modes must be >= 1; got {max_modes}")
    h, dt, f0, (lo, hi) = _impulse_responses(frf, band)
    n_o, n = h.shape
    M = 2 * int(max_modes)
    guard = M
    rows = n - 2 * guard - M
    rows = min(rows, max(int(row_fraction * n), 4 * M))
    if rows < M + 1:
        raise ValueError(
            f"the band holds {n} lines, too few for {max_modes} modes (needs > {5 * M}); "
            "widen the band or lower the order"
        )
    # Hankel blocks: A[o, r, i] = h[o, guard + r + i], i = 0..M
    win = np.lib.stride_tricks.sliding_window_view(h[:, guard:guard + rows + M], M + 1, axis=1)
    A = win.reshape(-1, M + 1)
    C = A.conj().T @ A
    out = []
    for k in range(1, int(max_modes) + 1):
        m = 2 * k
        # predict column m from columns 0..m-1 (rows equal across orders)
        G = C[:m, :m]
        b = -C[:m, m]
        try:
            a = np.linalg.solve(G, b)
        except np.linalg.LinAlgError:
            a = np.linalg.lstsq(G, b, rcond=None)[0]
        z = np.roots(np.concatenate([[1.0], a[::-1]]))
        z = z[np.abs(z) > 0]
        lam = np.log(z) / dt
        # the zoomed band spans [0, 1/dt) Hz: unwrap the angle into it, then shift back by f0
        lam = lam.real + 1j * (np.mod(lam.imag, 2 * np.pi / dt) + 2 * np.pi * f0)
        fd = lam.imag / (2 * np.pi)
        lam = lam[(fd >= lo) & (fd <= hi) & (lam.imag > 0)]
        out.append(lam[np.argsort(lam.imag)])
    return out


@limits_blas_threads
def lsce_poles(frf: FRFSet, n_modes: int, *, band: Sequence[float] | None = None,
               row_fraction: float = ROW_FRACTION) -> np.ndarray:
    """LSCE poles of the model with ``n_modes`` modes (2 n_modes complex poles in the zoomed band).

    Parameters
    ----------
    frf : FRFs with uniformly spaced lines (any quantity).
    n_modes : model size; the answer may hold up to 2 n_modes poles, physical and spurious.
    band : (lo_hz, hi_hz) or None for all lines.

    Returns
    -------
    complex poles in rad/s with Im > 0 whose damped frequency lies in the band, sorted by it.
    """
    return lsce_poles_all_orders(frf, n_modes, band=band, row_fraction=row_fraction)[-1]
