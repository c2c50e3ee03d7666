"""Initial poles by the Least-Squares Complex Frequency-domain method (LSCF, common denominator).

Model
-----
All FRFs ``H_o`` (every output/reference pair, o = 1..N_o) share one denominator:

    H_o(w) ~ N_o(w) / D(w),   N_o(w) = sum_j Omega(w)^j beta_oj,   D(w) = sum_j Omega(w)^j alpha_j,

with the z-domain basis ``Omega(w) = exp(-j w Ts)``, ``j = 0..p`` (p = 2 * n_modes) and the
sampling time ``Ts = 1 / (2 f_hi)`` (f_hi the top of the band), so that every line of the
band lies below the Nyquist frequency of the discrete-time model.

The linearised equation error ``N_o - H_o D`` stacked over the lines gives, per FRF, the
normal-equation blocks (real parts because the coefficients are real)

    R = Re(G^H G),   S_o = -Re(G^H Y_o),   T_o = Re(Y_o^H Y_o),   G[k, j] = Omega_k^j,
    Y_o = diag(H_o) G,

and eliminating the numerators leaves the reduced normal equations of the denominator

    M alpha = 0,   M = sum_o (T_o - S_o^T R^-1 S_o).

The constraint ``alpha_p = 1`` (highest coefficient) fixes the scale; with it the
physical poles come out stable and the mathematical poles mostly unstable
(Cauwberghs/Peeters: the reason pLSCF stabilization diagrams are clean). R, S_o, T_o
are Toeplitz (entries depend on i - j only), so they are built from 2p+1 sums per FRF.

Roots: ``D`` is a polynomial in ``x = exp(-s Ts)``; a root ``x_r`` gives the
continuous-time pole ``lambda_r = -ln(x_r) / Ts`` (rad/s).

Each FRF is scaled to unit RMS in the band first (one scalar per FRF), so strong and
weak responses take part alike; this does not change the poles of noise-free data. FRFs that
carry noise of one level by construction (the principal response functions of
:mod:`analysis.compression`, ``meta[EQUAL_NOISE]``) are scaled by one common scalar instead: a
weak one is weak because it is mostly noise.

All orders at once: with the Cholesky factor ``R = L L^T``, ``X_o = L^-1 S_o`` gives
``S_o^T R^-1 S_o = X_o^T X_o``; because ``L`` is lower triangular the leading
``(q, q)`` block of ``X_o`` belongs to order q - 1, so the reduced matrices of every
order follow from one cumulative sum over the rows of ``X_o`` (see
:func:`lscf_denominators`).
"""
from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .frf import FRFSet
from .threads import limits_blas_threads
from .work_limits import check_model_order

__all__ = ["lscf_poles", "lscf_poles_all_orders", "band_data", "parse_band", "prepare_band", "BandData"]

log = logging.getLogger(__name__)


#: ``FRFSet.meta`` key: the FRFs carry noise of one level (principal response functions,
#: :mod:`analysis.compression`); they are not scaled to unit RMS one by one
EQUAL_NOISE = "equal_noise"


def parse_band(band: Sequence[float] | None, freq_hz: np.ndarray) -> tuple[float, float]:
    """Check a band ``(lo_hz, hi_hz)`` against the data; ``None`` is the whole span.

    Raises ValueError naming the problem (reversed band, band outside the data).
    """
    f = np.asarray(freq_hz, dtype=float)
    if band is None:
        return float(f[0]), float(f[-1])
    try:
        lo, hi = (float(band[0]), float(band[1]))
    except (TypeError, ValueError, IndexError) as exc:
        raise ValueError(f"band must be a pair (lo_hz, hi_hz); got {band!r}") from exc
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo >= hi:
        raise ValueError(f"band {lo:g}:{hi:g} Hz is empty or reversed: give LO < HI in Hz")
    if hi < f[0] or lo > f[-1]:
        raise ValueError(
            f"band {lo:g}:{hi:g} Hz lies outside the data ({f[0]:.6g}..{f[-1]:.6g} Hz): choose a band inside it"
        )
    lo, hi = max(lo, float(f[0])), min(hi, float(f[-1]))
    n = int(np.count_nonzero((f >= lo) & (f <= hi)))
    if n < 8:
        raise ValueError(f"band {lo:g}:{hi:g} Hz holds only {n} lines; widen it (at least 8 lines)")
    return lo, hi


@dataclass(frozen=True)
class BandData:
    """The lines of a band, ready for the kernels: ``freq_hz[n_f]``, ``H[N_o, n_f]`` (FRFs stacked
    output-major, each scaled to unit RMS, all-zero FRFs dropped) and ``band`` (lo, hi) in Hz."""

    freq_hz: np.ndarray
    H: np.ndarray
    band: tuple


def prepare_band(frf: FRFSet, band: Sequence[float] | None) -> BandData:
    """Check the band and cut, stack and scale the FRFs once (see :class:`BandData`)."""
    lo, hi = parse_band(band, frf.freq_hz)
    i0 = int(np.searchsorted(frf.freq_hz, lo, side="left"))
    i1 = int(np.searchsorted(frf.freq_hz, hi, side="right"))
    f = frf.freq_hz[i0:i1]
    H = frf.H[..., i0:i1].reshape(-1, f.size)
    if not np.all(np.isfinite(H)):
        raise ValueError("the FRFs hold NaN or inf inside the band; choose a band without them")
    rms = np.sqrt(np.mean(H.real ** 2 + H.imag ** 2, axis=1))
    keep = rms > 0
    if not np.any(keep):
        raise ValueError("all FRFs are zero inside the band; nothing to fit")
    if frf.meta.get(EQUAL_NOISE):
        # rows of equal noise (principal response functions): scaled alike, so that each counts by
        # its signal-to-noise ratio
        scale = np.full(int(np.sum(keep)), 1.0 / float(np.sqrt(np.mean(rms[keep] ** 2))))
    else:
        scale = 1.0 / rms[keep]
    Hs = (H[keep] if not np.all(keep) else H) * scale[:, None]
    return BandData(f, Hs, (lo, hi))


def band_data(frf: FRFSet, band: Sequence[float] | None) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
    """The lines of the band: ``(freq_hz[n_f], H2[N_o, n_f], (lo, hi))`` (see :func:`prepare_band`)."""
    bd = prepare_band(frf, band)
    return bd.freq_hz, bd.H, bd.band


def _toeplitz_sums(f: np.ndarray, H: np.ndarray, ts: float, p: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sums over lines ``sum_k w_k exp(j omega_k Ts m)`` for m = -p..p, for the weights
    1 (r), H_o (s) and sum_o |H_o|^2 (t: only the sum over FRFs enters the reduced normal
    equations); returns the real parts r[2p+1], t[2p+1] and the complex s[N_o, 2p+1].

    When the lines sit on a grid ``f_k = i_k df`` and ``Ts = 1 / (2 i_top df)``, the sums are
    one FFT of length ``2 i_top`` per FRF (exact); otherwise a direct product with the
    (n_f, 2p+1) exponentials.
    """
    m = np.arange(-p, p + 1)
    df = float(np.mean(np.diff(f))) if f.size > 1 else 0.0
    idx = np.rint(f / df).astype(np.int64) if df > 0 else None
    on_grid = (
        idx is not None
        and np.allclose(idx * df, f, rtol=0, atol=1e-9 * f[-1])
        and np.all(np.diff(idx) > 0)
        and abs(ts * 2 * idx[-1] * df - 1) < 1e-12
        and 2 * idx[-1] > 2 * p + 1
    )
    if on_grid:
        assert idx is not None
        n_fft = int(2 * idx[-1])
        cols = np.mod(m, n_fft)

        def sums(w: np.ndarray) -> np.ndarray:
            # sum_k w_k exp(+j 2 pi i_k q / n_fft) at q = m (mod n_fft), in chunks of rows
            out = np.empty((w.shape[0], cols.size), dtype=complex)
            for a in range(0, w.shape[0], 64):
                W = np.zeros((min(64, w.shape[0] - a), n_fft), dtype=complex)
                W[:, idx] = w[a : a + 64]
                out[a : a + 64] = (np.fft.ifft(W, axis=1) * n_fft)[:, cols]
            return out

        real_rows = np.vstack([np.ones(f.size), np.sum(H.real ** 2 + H.imag ** 2, axis=0)])
        rt = sums(real_rows).real
        return rt[0], sums(H), rt[1]
    omega = 2 * np.pi * f
    E = np.exp(1j * np.outer(omega * ts, m))  # (n_f, 2p+1)
    r = E.sum(axis=0).real
    s = H @ E
    t = np.sum(H.real ** 2 + H.imag ** 2, axis=0) @ E
    return r, s, t.real


def _toeplitz_index(p: int) -> np.ndarray:
    """Index into the m = -p..p sums for entry (i, j) = i - j of the conjugated product."""
    i = np.arange(p + 1)
    return (i[:, None] - i[None, :]) + p


def lscf_denominators(frf: FRFSet | BandData, max_modes: int, *,
                      band: Sequence[float] | None = None) -> tuple[list[np.ndarray], float]:
    """Denominator coefficients ``alpha`` (length 2n+1, alpha[-1] = 1) for n = 1..max_modes,
    and the sampling time Ts (s). See the module docstring for the mathematics.
    ``frf`` may be an already prepared :class:`BandData` (``band`` is then ignored)."""
    if int(max_modes) < 1:
        raise ValueError(f"number of modes must be >= 1; got {max_modes}")
    P = 2 * int(max_modes)
    bd = frf if isinstance(frf, BandData) else prepare_band(frf, band)
    f, H = bd.freq_hz, bd.H
    check_model_order(int(max_modes), f.size, H.shape[0])  # before allocating (2n+1)^3 arrays
    ts = 1.0 / (2.0 * float(f[-1]))
    r, s, t = _toeplitz_sums(f, H, ts, P)
    idx = _toeplitz_index(P)
    # entries (i, j): conj(Omega^i) Omega^j = exp(j w Ts (i - j))
    R = r[idx]
    # S_o[i, j] = -Re s_o[idx[i, j]], laid out (row i, col j, frf o) for the solve: one real array
    S = np.ascontiguousarray(-s.real.T)[idx]
    T = t[idx]
    try:
        L = np.linalg.cholesky(R)
    except np.linalg.LinAlgError:
        L = np.linalg.cholesky(R + np.eye(P + 1) * 1e-12 * np.trace(R))
    X = np.linalg.solve(L, S.reshape(P + 1, -1))  # L^-1 S (numpy: no scipy import for the diagram alone)
    X = X.reshape(P + 1, P + 1, -1)  # (row i, col a, frf o)
    # G_i[a, b] = sum_o X[i, a, o] X[i, b, o]; cumulative over rows i
    G = np.matmul(X, X.transpose(0, 2, 1))
    Gc = np.cumsum(G, axis=0)
    out = []
    for n in range(1, int(max_modes) + 1):
        q = 2 * n + 1
        M = T[:q, :q] - Gc[q - 1, :q, :q]
        M = 0.5 * (M + M.T)
        try:
            a = np.linalg.solve(M[:-1, :-1], -M[:-1, -1])
        except np.linalg.LinAlgError:
            a = np.linalg.lstsq(M[:-1, :-1], -M[:-1, -1], rcond=None)[0]
        out.append(np.concatenate([a, [1.0]]))
    return out, ts


def _roots_to_poles(alpha: np.ndarray, ts: float) -> np.ndarray:
    """Continuous-time poles (rad/s, Im > 0) from alpha (ascending powers of exp(-s Ts))."""
    x = np.roots(alpha[::-1])
    x = x[np.abs(x) > 0]
    lam = -np.log(x.astype(complex)) / ts
    lam = lam[np.imag(lam) > 0]
    return lam[np.argsort(np.imag(lam))]


@limits_blas_threads
def lscf_poles_all_orders(frf: FRFSet | BandData, max_modes: int, *,
                          band: Sequence[float] | None = None) -> list[np.ndarray]:
    """Poles (rad/s, upper half plane, sorted by damped frequency) for n = 1..max_modes."""
    alphas, ts = lscf_denominators(frf, max_modes, band=band)
    return [_roots_to_poles(a, ts) for a in alphas]


@limits_blas_threads
def lscf_poles(frf: FRFSet, n_modes: int, *, band: Sequence[float] | None = None) -> np.ndarray:
    """LSCF poles of a model with ``n_modes`` modes (denominator order 2 n_modes).

    Parameters
    ----------
    frf : the FRFs (any quantity; all output/reference pairs share the denominator).
    n_modes : number of mode pairs of the model (spurious poles included in the answer).
    band : (lo_hz, hi_hz) or None for all lines.

    Returns
    -------
    (m,) complex poles in rad/s with Im > 0, sorted by damped frequency; includes
    unstable/spurious ones (selection is done later).
    """
    return lscf_poles_all_orders(frf, n_modes, band=band)[-1]
