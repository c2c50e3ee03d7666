"""Exact time response of the modal model to a sampled force (modal superposition).

Mode r (mass-normalised, proportional damping) obeys ``q'' + 2 zeta_r w_r q' + w_r^2 q = phi_in,r f(t)``.
Its unit impulse response is ``h_r(t) = exp(-zeta_r w_r t) sin(w_d,r t) / w_d,r = 2 Re(A_r exp(lambda_r t))``
with ``A_r = 1 / (2 j w_d,r)`` and pole ``lambda_r = -zeta_r w_r + j w_d,r`` (rad/s).

The complex modal state ``z_r(t) = int_0^t exp(lambda_r (t - tau)) f(tau) dtau`` is propagated exactly
between samples (period ``T = 1/fs``) for a force that is linear between samples (first-order hold):

    z[n] = E z[n-1] + I1 f[n] + (I0 - I1) f[n-1],   E = exp(lambda T),
    I0 = (E - 1) / lambda,   I1 = (E - 1 - lambda T) / (lambda^2 T).

Displacement, velocity and acceleration of mode r per unit participation are then, exactly at the samples,

    x_r = 2 Re(A_r z_r),  v_r = 2 Re(A_r lambda_r z_r),  a_r = 2 Re(A_r lambda_r^2 z_r) + f

(``2 Re(A_r lambda_r) = 1`` gives the direct term of the acceleration). The response at output ``o`` is
``y_o = sum_r phi_o,r phi_in,r y_r``. No integrator error: the only approximation is the
first-order hold of the force between samples.

:func:`simulate_segment` runs the same recursion on a grid ``q`` times finer than the output rate
(period ``T/q``), collapsed over blocks of ``q`` fine steps so that only the output instants are formed:

    z[(j+1) q] = E^q z[j q] + sum_{i=1..q} E^(q-i) u[j q + i],   u[k] = I1 f[k] + (I0 - I1) f[k-1]

(``E``, ``I0``, ``I1`` for the fine step). After the force has ended every mode decays freely,
``z(t) = z(t_e) exp(lambda (t - t_e))``, evaluated exactly at the output instants.
"""
from __future__ import annotations

import numpy as np
import scipy.signal

__all__ = ["foh_coefficients", "modal_states", "simulate_response", "simulate_segment", "RESPONSE_QUANTITIES"]

RESPONSE_QUANTITIES = ("displacement", "velocity", "acceleration")


def _em1_minus_x(x: np.ndarray) -> np.ndarray:
    """exp(x) - 1 - x without cancellation for small |x| (Taylor series to x^14 below |x| = 0.1)."""
    x = np.asarray(x, dtype=complex)
    out = np.expm1(x) - x
    small = np.abs(x) < 0.1
    if np.any(small):
        xs = x[small]
        term = xs * xs / 2.0
        acc = term.copy()
        for k in range(3, 15):
            term = term * xs / k
            acc = acc + term
        out[small] = acc
    return out


def foh_coefficients(poles: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(b0, b1, E) per pole for ``z[n] = E z[n-1] + b0 f[n] + b1 f[n-1]`` (see module docstring).

    ``poles`` in rad/s (must have Re < 0 or be oscillatory: lambda != 0), ``fs_hz`` in Hz.
    """
    lam = np.atleast_1d(np.asarray(poles, dtype=complex))
    if fs_hz <= 0:
        raise ValueError(f"sample rate must be > 0 Hz, got {fs_hz}")
    if np.any(lam == 0):
        raise ValueError("a pole at 0 rad/s (rigid-body mode) has no bounded response; add supports")
    T = 1.0 / fs_hz
    x = lam * T
    E = np.exp(x)
    I0 = np.expm1(x) / lam
    I1 = _em1_minus_x(x) / (lam ** 2 * T)
    return I1, I0 - I1, E


def modal_states(force: np.ndarray, poles: np.ndarray, fs_hz: float) -> np.ndarray:
    """Complex modal states z_r[n] (n_modes, n) for the force samples ``force`` (n,), zero before sample 0."""
    f = np.asarray(force, dtype=float)
    if f.ndim != 1:
        raise ValueError(f"force must be one record (n,), got shape {f.shape}")
    b0, b1, E = foh_coefficients(poles, fs_hz)
    z = np.empty((b0.size, f.size), dtype=complex)
    # the force is usually zero after a short pulse: filter over its support, then decay freely
    nz = np.flatnonzero(f)
    if nz.size == 0:
        z[:] = 0.0
        return z
    i0, i1 = int(nz[0]), min(int(nz[-1]) + 2, f.size)
    z[:, :i0] = 0.0
    seg = f[i0:i1].astype(complex)
    for r in range(b0.size):
        z[r, i0:i1] = scipy.signal.lfilter([b0[r], b1[r]], [1.0, -E[r]], seg)
    if i1 < f.size:
        k = np.arange(1, f.size - i1 + 1)
        z[:, i1:] = z[:, i1 - 1:i1] * np.exp(np.outer(np.log(E), k))
    return z


def _recursion(seg: np.ndarray, b0: np.ndarray, b1: np.ndarray, E: np.ndarray) -> np.ndarray:
    """z (n_modes, len(seg)) of ``z[n] = E z[n-1] + b0 seg[n] + b1 seg[n-1]`` from rest.

    Short records (a hammer pulse) step through time vectorised over the modes; long ones run
    ``scipy.signal.lfilter`` per mode (its per-call overhead is then negligible)."""
    n = seg.size
    z = np.empty((E.size, n), dtype=complex)
    if n > 512:
        x = seg.astype(complex)
        for r in range(E.size):
            z[r] = scipy.signal.lfilter([b0[r], b1[r]], [1.0, -E[r]], x)
        return z
    u = np.outer(b0, seg)
    u[:, 1:] += np.outer(b1, seg[:-1])
    acc = np.zeros(E.size, dtype=complex)
    for k in range(n):
        acc = E * acc + u[:, k]
        z[:, k] = acc
    return z


def _check_shapes(poles: np.ndarray, phi_out: np.ndarray, phi_in: np.ndarray,
                  quantity: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if quantity not in RESPONSE_QUANTITIES:
        raise ValueError(f"quantity {quantity!r} is not one of {RESPONSE_QUANTITIES}")
    lam = np.atleast_1d(np.asarray(poles, dtype=complex))
    po = np.atleast_2d(np.asarray(phi_out, dtype=float))
    pi = np.asarray(phi_in, dtype=float).reshape(-1)
    if po.shape[1] != lam.size or pi.size != lam.size:
        raise ValueError(f"shapes disagree: {lam.size} poles, phi_out {po.shape}, phi_in {pi.shape}")
    if np.any(np.imag(lam) <= 0):
        raise ValueError("poles must be oscillatory, in the upper half plane (Im > 0); drop rigid-body modes")
    return lam, po, pi


def simulate_segment(
    force_seg: np.ndarray,
    seg_start: int,
    oversample: int,
    fs_hz: float,
    n_samples: int,
    poles: np.ndarray,
    phi_out: np.ndarray,
    phi_in: np.ndarray,
    quantity: str = "acceleration",
) -> np.ndarray:
    """Response (n_out, n_samples) at ``fs_hz`` to a force known on a fine grid.

    ``force_seg`` (N) holds the force at rate ``q fs`` (``q = oversample``) on the fine-grid indices
    ``seg_start, seg_start + 1, ...`` (``seg_start`` may be negative: the force began before the record);
    the force is zero elsewhere and linear between fine samples. Output sample ``n`` is at fine index
    ``n q`` (time ``n / fs``). The modal states are propagated exactly over the segment on the fine grid,
    then each mode decays freely, evaluated exactly at the output instants (see module docstring).
    """
    lam, po, pi = _check_shapes(poles, phi_out, phi_in, quantity)
    q = int(oversample)
    if q < 1:
        raise ValueError(f"oversample must be an integer >= 1, got {oversample}")
    n = int(n_samples)
    W = po * pi[None, :]
    p = RESPONSE_QUANTITIES.index(quantity)
    Wc = W * (1.0 / (2j * np.imag(lam)) * lam ** p)[None, :]  # (n_out, n_modes): phi phi A lambda^p
    y = np.zeros((po.shape[0], n))
    f = np.asarray(force_seg, dtype=float).reshape(-1)
    if f.size == 0 or not np.any(f):
        return y
    # Align the segment to the output grid: fine indices a0 + j q (j = 0..nb) are output samples
    # n0 + j. Zeros before the force change nothing; one zero after it completes the last linear piece.
    n0 = seg_start // q
    a0 = n0 * q
    lead = seg_start - a0
    nb = -(-(lead + f.size) // q)
    s_al = np.zeros(1 + nb * q)
    s_al[lead:lead + f.size] = f
    b0, b1, E = foh_coefficients(lam, q * fs_hz)
    # fine recursion z[k] = E z[k-1] + u[k], u[k] = b0 s[k] + b1 s[k-1], collapsed over blocks of q:
    # z[(j+1) q] = E^q z[j q] + sum_{i=1..q} E^(q-i) u[j q + i]
    u = np.outer(b0, s_al)
    u[:, 1:] += np.outer(b1, s_al[:-1])
    Z = np.empty((lam.size, nb + 1), dtype=complex)
    Z[:, 0] = u[:, 0]
    if q == 1:
        U = u[:, 1:]
    else:
        pw = np.exp(np.outer(lam / (q * fs_hz), q - np.arange(1, q + 1)))  # (n_modes, q): E^(q-i)
        U = np.einsum("mbi,mi->mb", u[:, 1:].reshape(lam.size, nb, q), pw)
    Eq = np.exp(lam / fs_hz)
    if nb > 1024:  # long records: one lfilter call per mode
        for r in range(lam.size):
            Z[r, 1:], _ = scipy.signal.lfilter([1.0], [1.0, -Eq[r]], U[r], zi=[Eq[r] * Z[r, 0]])
    else:
        acc = Z[:, 0]
        for j in range(nb):
            acc = Eq * acc + U[:, j]
            Z[:, j + 1] = acc
    # outputs inside the aligned segment (output samples n0 .. n0 + nb), clipped to the record
    lo, hi = max(n0, 0), min(n0 + nb, n - 1)
    if hi >= lo:
        cols = np.arange(lo, hi + 1) - n0
        y[:, lo:hi + 1] = 2.0 * np.real(Wc @ Z[:, cols])
        if quantity == "acceleration":
            y[:, lo:hi + 1] += W.sum(axis=1)[:, None] * s_al[cols * q][None, :]
    # free decay after the segment, exactly at the output instants
    n_c = max(n0 + nb + 1, 0)
    m = n - n_c
    if m > 0:
        B = 256
        nblk = -(-m // B)
        T = 1.0 / fs_hz
        d0 = (n_c - (n0 + nb)) * T  # from the segment's last aligned point to output sample n_c (s)
        P = np.exp(np.outer(lam * T, np.arange(B)))                            # (n_modes, B)
        starts = np.exp(np.outer(d0 + np.arange(nblk) * B * T, lam))           # (nblk, n_modes)
        V = Wc[None, :, :] * (starts * Z[:, -1][None, :])[:, None, :]          # (nblk, n_out, n_modes)
        Y = 2.0 * np.real(V @ P)                                               # (nblk, n_out, B)
        y[:, n_c:] = np.moveaxis(Y, 0, 1).reshape(po.shape[0], nblk * B)[:, :m]
    return y


def simulate_response(
    force_n: np.ndarray,
    fs_hz: float,
    poles: np.ndarray,
    phi_out: np.ndarray,
    phi_in: np.ndarray,
    quantity: str = "acceleration",
) -> np.ndarray:
    """Response (n_out, n) to the force ``force_n`` (N, samples at ``fs_hz`` Hz) applied at the input DOF.

    poles : (n_modes,) rad/s, upper half plane. phi_out : (n_out, n_modes) mode shapes at the outputs,
    phi_in : (n_modes,) at the input (both mass-normalised, signed by the point directions).
    quantity : "displacement" (m), "velocity" (m/s) or "acceleration" (m/s^2). Inputs are not modified.

    The force is linear between its samples (first-order hold). The recursion runs only over the
    force's support; after the force ends each mode decays freely, ``z[n] = z[m] E^(n-m)``, evaluated in
    blocks as a matrix product with a table of ``E^k`` (every block start uses ``exp(lambda T k)``
    directly, so no rounding accumulates).
    """
    f = np.asarray(force_n, dtype=float)
    if f.ndim != 1:
        raise ValueError(f"force must be one record (n,), got shape {f.shape}")
    nz = np.flatnonzero(f)
    if nz.size == 0:
        _check_shapes(poles, phi_out, phi_in, quantity)
        return np.zeros((np.atleast_2d(phi_out).shape[0], f.size))
    i0, i1 = int(nz[0]), int(nz[-1]) + 1
    return simulate_segment(f[i0:i1], i0, 1, fs_hz, f.size, poles, phi_out, phi_in, quantity)
