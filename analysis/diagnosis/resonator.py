"""A local resonator: a spring-mass attached to the structure at one point (a tuned absorber, a loose
part, a cable or a component on a soft mount), re-analysed with the simulation's modes.

In the modal coordinates ``q`` of the mass-normalised simulation and ``y = sqrt(m) x_a`` for the
attached mass (``x_a`` its displacement), with ``g_r = sqrt(m) phi_r(point)`` the coupling to mode r
(dimensionless; ``g_r^2`` is the resonator's mass as a fraction of mode r's modal mass) and
``u = [g; -1]``::

    K = diag(omega_r^2, 0) + omega_a^2 u u^T,   M = I,   C = diag(2 zeta_r omega_r, 0) + 2 zeta_a omega_a u u^T

``omega_a = 2 pi frequency_hz`` is the resonator's own frequency (on a rigid base), ``zeta_a`` its own
damping ratio. The coupled modes (one more than the simulation's) are the complex modes of
``q'' + C q' + K q = 0`` (state space, :func:`damped_coupled_modes`): the resonator's damper couples the
modes it sits on, and a resonator a few times more damped than the structure next to one of its modes
makes that coupling large, so no modal damping is assumed (the modes the damping couples by less than
:data:`DAMPING_COUPLING` keep the damping of their modal projection). Mode ``i`` with pole ``lambda_i`` and
eigenvector ``x_i`` (the modal coordinates and the resonator's) has the receptance residue
``psi_o psi_r / a_i``, ``psi = Phi x_i[:n]``, ``a_i = x_i^T (2 lambda_i I + C) x_i`` (``2 j omega_d`` for a
real mode). ``Phi`` are the mass-normalised shapes at the outputs, ``meta["output_shapes"]``; for an
FRF-file simulation they come from the driving point, so the resonator needs them as the sensors' mass
does. Below its frequency the resonator adds mass to the neighbouring modes, above it takes some away:
those shifts are part of the effect, not a second cause. (An overdamped pair, without enough
oscillating modes, falls back to the undamped modes ``K V = V Omega^2`` with the damping ratio of their
modal projection, :func:`coupled_modes`.)
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from ..frf import QUANTITY_POWER
from ..modal import ModalModel
from .effect_types import EffectError, shapes_at_references

__all__ = ["apply_local_resonator", "coupled_modes", "damped_coupled_modes"]


def coupled_modes(wn: np.ndarray, zeta: np.ndarray, g: np.ndarray, w_a: float, zeta_a: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undamped natural frequencies (rad/s, ascending), projected damping ratios and eigenvectors
    (n+1, n+1; the last row the attached mass's coordinate) of the modes ``wn`` (rad/s) with the
    resonator ``w_a`` (rad/s), ``zeta_a`` coupled through ``g``."""
    n = wn.size
    K, C = _matrices(wn, zeta, g, w_a, zeta_a)
    w2, V = np.linalg.eigh(K)
    W = np.sqrt(np.maximum(w2, 1e-300))
    z = np.einsum("ri,rs,si->i", V, C, V) / (2 * W)
    assert V.shape == (n + 1, n + 1)
    return W, np.clip(z, 1e-6, 0.99), V


def _matrices(wn: np.ndarray, zeta: np.ndarray, g: np.ndarray, w_a: float, zeta_a: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """Stiffness and damping (n+1, n+1; M = I) of the modes ``wn`` (rad/s) with the resonator."""
    u = np.append(np.asarray(g, float), -1.0)
    K = np.diag(np.append(wn ** 2, 0.0)) + w_a ** 2 * np.outer(u, u)
    C = np.diag(np.append(2 * zeta * wn, 0.0)) + 2 * zeta_a * w_a * np.outer(u, u)
    return K, C


#: modes whose damping couples them by more than this (``|C_ij| max(W_i, W_j) / |W_i^2 - W_j^2|`` in the
#: undamped coupled modes) are solved together as complex modes; the others keep their projected damping
DAMPING_COUPLING = 1e-3


def damped_coupled_modes(wn: np.ndarray, zeta: np.ndarray, g: np.ndarray, w_a: float, zeta_a: float
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The complex modes of the modes ``wn`` (rad/s), damping ratios ``zeta``, with the resonator ``w_a``
    (rad/s), ``zeta_a`` coupled through ``g``: poles (n+1, rad/s, positive imaginary parts ascending),
    eigenvectors (n+1, n+1; the last row the attached mass's coordinate), their scales
    ``a_i = x_i^T (2 lambda_i I + C) x_i`` (the receptance residue of coordinates k, l is
    ``x_ki x_li / a_i``) and the undamped coupled modes ``V`` in the same order (real, orthonormal).
    Solved in the undamped coupled modes: those the damping couples
    (:data:`DAMPING_COUPLING`) by the state-space eigenproblem of their block of ``V^T C V``, the others
    as real modes with their projected damping. None when fewer modes oscillate (an overdamped pair)."""
    K, C = _matrices(wn, zeta, g, w_a, zeta_a)
    w2, V = np.linalg.eigh(K)
    W = np.sqrt(np.maximum(w2, 1e-300))
    Ct = V.T @ C @ V
    gap = np.abs(W[:, None] ** 2 - W[None, :] ** 2)
    strong = np.abs(Ct) * np.maximum(W[:, None], W[None, :]) > DAMPING_COUPLING * gap
    np.fill_diagonal(strong, False)
    S = np.flatnonzero(strong.any(axis=1))
    lam = W * (-np.diag(Ct) / (2 * W) + 1j * np.sqrt(np.maximum(1 - (np.diag(Ct) / (2 * W)) ** 2, 0.0)))
    if np.any(np.diag(Ct) / (2 * W) >= 1):
        return None
    X = V.astype(complex)
    a = 2j * lam.imag
    if S.size:
        ns = S.size
        A = np.block([[np.zeros((ns, ns)), np.eye(ns)], [-np.diag(W[S] ** 2), -Ct[np.ix_(S, S)]]])
        ev, vec = np.linalg.eig(A)
        up = np.flatnonzero(ev.imag > 0)
        if up.size != ns:
            return None
        up = up[np.argsort(ev[up].imag)]
        Y = vec[:ns, up]
        lam[S] = ev[up]
        X[:, S] = V[:, S] @ Y
        a[S] = np.einsum("ki,ki->i", Y, Ct[np.ix_(S, S)] @ Y + 2 * ev[up][None, :] * Y)
    order = np.argsort(lam.imag)
    return lam[order], X[:, order], a[order], V[:, order]


def _coupling(model: ModalModel, params: Mapping, phi: np.ndarray) -> np.ndarray:
    if "coupling" in params:
        g = np.asarray(params["coupling"], float)
        if g.shape != (model.poles.size,):
            raise EffectError(f"local_resonator: coupling needs one value per mode ({model.poles.size}), got {g.shape}")
        return g
    point = params.get("point")
    if point not in model.outputs:
        raise EffectError(f"local_resonator: give 'coupling' (one value per mode) or 'point' (one of the outputs "
                          f"{list(model.outputs)}) with 'mass_kg'; got point {point!r}")
    m = float(params.get("mass_kg", 0.0))
    if not m >= 0:
        raise EffectError(f"local_resonator: mass_kg must be >= 0 (kg), got {m!r}")
    return np.sqrt(m) * phi[list(model.outputs).index(point)]


def apply_local_resonator(model: ModalModel, params: Mapping) -> ModalModel:
    """A spring-mass of own frequency ``frequency_hz`` (Hz) and damping ratio ``zeta`` attached either at
    the output ``point`` with ``mass_kg`` (kg), or through ``coupling`` (``sqrt(m) phi_r`` at the point,
    one value per mode, in the model's mode order). The model gets one mode more. Each coupled mode's
    receptance residue is ``sum_r V_ri^2 R_r w_d,r / w_d,i`` (the fitted residues kept where the shapes
    cannot say more) plus ``[psi_o psi_ref - sum_r V_ri^2 phi_or phi_ref,r] / (2 j w_d,i)``, ``psi = Phi V``:
    exact when the residues are the shapes' own."""
    shapes = model.meta.get("output_shapes")
    if shapes is None:
        raise EffectError("local_resonator needs the mode shapes at the outputs (model.meta['output_shapes']): "
                          "a simulation from a frame configuration, or an FRF file with a driving point")
    phi = np.asarray(shapes, float)
    fa = float(params.get("frequency_hz", 0.0))
    za = float(params.get("zeta", 0.01))
    if not fa > 0:
        raise EffectError(f"local_resonator: frequency_hz must be > 0 (Hz), got {fa!r}")
    if not 0 <= za < 1:
        raise EffectError(f"local_resonator: zeta must be in [0, 1), got {za!r}")
    g = _coupling(model, params, phi)
    lam = np.asarray(model.poles, complex)
    wn, z = np.abs(lam), -lam.real / np.abs(lam)
    damped = damped_coupled_modes(wn, z, g, 2 * np.pi * fa, za)
    if damped is not None:
        new, X, a, V = damped
        Xb, Vb = X[:-1], V[:-1]
    else:
        W, Z, V = coupled_modes(wn, z, g, 2 * np.pi * fa, za)
        Vb = V[:-1]                                     # (n_old, n_new): the beam's modal coordinates
        new = W * (-Z + 1j * np.sqrt(1 - Z ** 2))
        Xb, a = Vb.astype(complex), 2j * new.imag
    p = QUANTITY_POWER[model.quantity]
    R_old = np.asarray(model.residues, complex) / lam[None, None, :] ** p
    ref = shapes_at_references(model, phi)
    if ref is not None:                                 # what the shapes do not say of the fitted residues
        R_old = R_old - np.einsum("om,rm->orm", phi, ref) / (2j * lam.imag)[None, None, :]
    R = np.einsum("orm,mi->ori", R_old * (2j * lam.imag)[None, None, :], Xb ** 2) / a[None, None, :]
    if ref is not None:
        R = R + (phi @ Xb)[:, None, :] * (ref @ Xb)[None, :, :] / a[None, None, :]
    meta = dict(model.meta)
    meta["output_shapes"] = phi @ Vb
    if ref is not None and "reference_shapes" in meta:
        meta["reference_shapes"] = ref @ Vb
    return replace(model, poles=new, residues=R * new[None, None, :] ** p, meta=meta)
