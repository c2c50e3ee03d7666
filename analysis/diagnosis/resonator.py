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
from typing import NamedTuple

import numpy as np

from ..frf import QUANTITY_POWER
from ..modal import ModalModel
from .effect_types import EffectError, shapes_at_references

__all__ = ["apply_local_resonator", "coupled_modes", "damped_coupled_modes", "local_resonator_derivative"]


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


class _Solution(NamedTuple):
    """The complex modes of :func:`damped_coupled_modes` in the order of the undamped coupled modes, with what
    their derivative needs: ``K = V diag(w2) V^T``, ``Ct = V^T C V``, the strongly coupled modes ``S`` and the
    state-space eigenvalues ``ev`` and eigenvectors ``vec`` of their block (``up``: the kept ones)."""

    w2: np.ndarray
    V: np.ndarray
    Ct: np.ndarray
    S: np.ndarray
    lam: np.ndarray
    X: np.ndarray
    a: np.ndarray
    ev: np.ndarray
    vec: np.ndarray
    up: np.ndarray


def _damped(K: np.ndarray, C: np.ndarray) -> _Solution | None:
    w2, V = np.linalg.eigh(K)
    W = np.sqrt(np.maximum(w2, 1e-300))
    Ct = V.T @ C @ V
    Wsq = W ** 2
    gap = np.abs(Wsq[:, None] - Wsq[None, :])
    strong = np.abs(Ct) * np.maximum(W[:, None], W[None, :]) > DAMPING_COUPLING * gap
    np.fill_diagonal(strong, False)
    S = np.flatnonzero(strong.any(axis=1))
    zr = np.diag(Ct) / (2 * W)                          # the projected damping ratios
    if np.any(zr >= 1):
        return None
    lam = W * (-zr + 1j * np.sqrt(np.maximum(1 - zr ** 2, 0.0)))
    X = V.astype(complex)
    a = 2j * lam.imag
    ev, vec, up = np.zeros(0, complex), np.zeros((0, 0), complex), np.zeros(0, int)
    if S.size:
        ns = S.size
        A = np.zeros((2 * ns, 2 * ns))                  # the state matrix [[0, I], [-diag(w2_S), -Ct_SS]]
        A[:ns, ns:] = np.eye(ns)
        A[ns:, :ns] = -np.diag(Wsq[S])
        A[ns:, ns:] = -Ct[np.ix_(S, S)]
        ev, vec = np.linalg.eig(A)
        up = np.flatnonzero(ev.imag > 0)
        if up.size != ns:
            return None
        up = up[np.argsort(ev[up].imag)]
        Y = vec[:ns, up]
        lam[S] = ev[up]
        X[:, S] = V[:, S] @ Y
        a[S] = np.einsum("ki,ki->i", Y, Ct[np.ix_(S, S)] @ Y + 2 * ev[up][None, :] * Y)
    return _Solution(w2, V, Ct, S, lam, X, a, ev, vec, up)


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
    sol = _damped(*_matrices(wn, zeta, g, w_a, zeta_a))
    if sol is None:
        return None
    order = np.argsort(sol.lam.imag)
    return sol.lam[order], sol.X[:, order], sol.a[order], sol.V[:, order]


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


def _inputs(model: ModalModel, params: Mapping) -> tuple[np.ndarray, float, float, np.ndarray]:
    """The shapes at the outputs, the resonator's own frequency (Hz), damping ratio and coupling, checked."""
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
    return phi, fa, za, _coupling(model, params, phi)


def _kept(model: ModalModel, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """``c_orm = R_orm 2 j w_d,m``: the receptance residues less what the shapes say of them (at the
    references, None without shapes there), times ``2 j w_d``; and the shapes at the references."""
    lam = np.asarray(model.poles, complex)
    R_old = np.asarray(model.residues, complex) / lam[None, None, :] ** QUANTITY_POWER[model.quantity]
    ref = shapes_at_references(model, phi)
    if ref is not None:                                 # what the shapes do not say of the fitted residues
        R_old = R_old - np.einsum("om,rm->orm", phi, ref) / (2j * lam.imag)[None, None, :]
    return R_old * (2j * lam.imag)[None, None, :], ref


def apply_local_resonator(model: ModalModel, params: Mapping) -> ModalModel:
    """A spring-mass of own frequency ``frequency_hz`` (Hz) and damping ratio ``zeta`` attached either at
    the output ``point`` with ``mass_kg`` (kg), or through ``coupling`` (``sqrt(m) phi_r`` at the point,
    one value per mode, in the model's mode order). The model gets one mode more. Each coupled mode's
    receptance residue is ``sum_r V_ri^2 R_r w_d,r / w_d,i`` (the fitted residues kept where the shapes
    cannot say more) plus ``[psi_o psi_ref - sum_r V_ri^2 phi_or phi_ref,r] / (2 j w_d,i)``, ``psi = Phi V``:
    exact when the residues are the shapes' own."""
    phi, fa, za, g = _inputs(model, params)
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
    c, ref = _kept(model, phi)
    R = np.einsum("orm,mi->ori", c, Xb ** 2) / a[None, None, :]
    if ref is not None:
        R = R + (phi @ Xb)[:, None, :] * (ref @ Xb)[None, :, :] / a[None, None, :]
    return _resonated(model, new, R, Vb, phi, ref)


def _resonated(model: ModalModel, poles: np.ndarray, R: np.ndarray, Vb: np.ndarray, phi: np.ndarray,
               ref: np.ndarray | None) -> ModalModel:
    """``model`` with the coupled modes: poles (rad/s), receptance residues ``R`` (in the model's form
    ``R lambda^p``) and the shapes at the outputs (and references) ``phi Vb`` (``Vb`` the undamped coupled
    modes' beam rows)."""
    meta = dict(model.meta)
    meta["output_shapes"] = phi @ Vb
    if ref is not None and "reference_shapes" in meta:
        meta["reference_shapes"] = ref @ Vb
    p = QUANTITY_POWER[model.quantity]
    return replace(model, poles=poles, residues=R * poles[None, None, :] ** p, meta=meta)


def local_resonator_derivative(model: ModalModel, params: Mapping
                               ) -> tuple[ModalModel, np.ndarray, np.ndarray]:
    """:func:`apply_local_resonator` and the derivatives of the new model's poles ``(n+1, P)`` (rad/s) and
    residues ``(n_out, n_ref, n+1, P)`` (the model's form) with respect to ``theta = (frequency_hz, zeta,
    coupling_1 .. coupling_n)``, ``P = n + 2`` (per Hz, per unit damping ratio, per unit coupling), exact.

    With ``u = [g; -1]`` the parameters move ``dK = 2 w_a dw_a u u^T + w_a^2 (du u^T + u du^T)`` and
    ``dC = 2 (zeta_a dw_a + w_a dzeta_a) u u^T + 2 zeta_a w_a (du u^T + u du^T)``. In the undamped coupled
    modes (``K V = V diag(w2)``, distinct ``w2``) ``dK~ = V^T dK V``, ``dw2_i = dK~_ii``, ``dV = V Q`` with
    ``Q_ki = dK~_ki / (w2_i - w2_k)`` (``Q_ii = 0``), and ``dCt = Q^T Ct + Ct Q + V^T dC V``. Every mode's
    receptance residue is linear in ``Pi_i = x_i x_i^T / a_i``: ``R_ori = sum_m c_orm (Pi_i)_mm +
    (Phi Pi_i Phi_ref^T)_or`` (:func:`apply_local_resonator`), so ``dR`` follows from ``dPi``:

    * a mode the damping does not couple, ``lambda_i = -c/2 + j sqrt(w2_i - c^2/4)`` (``c = Ct_ii``), ``x_i = v_i``,
      ``a_i = 2 j Im lambda_i``: ``dlambda_i = -dc/2 + j (dw2_i - c dc/2) / (2 Im lambda_i)``,
      ``dPi_i = (dv_i v_i^T + v_i dv_i^T) / a_i - Pi_i dIm lambda_i / Im lambda_i`` (a projected damping at its
      clip, in the overdamped fallback: ``dlambda_i = lambda_i dw2_i / (2 w2_i)``);
    * the modes ``S`` it couples: the state matrix ``A = [[0, I], [-diag(w2_S), -Ct_SS]]`` with eigenvalues
      ``ev_k``, right eigenvectors ``Z`` and left ``Z^-1`` has spectral projectors ``P_k``; ``dA`` has the bottom
      rows ``[-diag(dw2_S), -dCt_SS]``, ``F = Z^-1 dA Z``, ``dev_k = F_kk`` and
      ``dP_i = sum_{k != i} (P_k dA P_i + P_i dA P_k) / (ev_i - ev_k)``. The receptance's residue of the block is
      the top-right block of ``P_i``, ``M_i = y_i y_i^T / a_i``, so ``Pi_i = V_S M_i V_S^T`` and
      ``dPi_i = dV_S M_i V_S^T + V_S M_i dV_S^T + V_S dM_i V_S^T`` (no normalisation of eigenvectors enters).

    The residues in the model's form p are ``R lambda^p``: ``d(R lambda^p) = dR lambda^p + p R lambda^(p-1) dlambda``.
    The new model is built from the same solution (its modes, residues and shapes, as
    :func:`apply_local_resonator` computes them), so the eigenproblems are solved once per call."""
    phi, fa, za, g = _inputs(model, params)
    lam0 = np.asarray(model.poles, complex)
    wn, z = np.abs(lam0), -lam0.real / np.abs(lam0)
    w_a = 2 * np.pi * fa
    n = wn.size
    K, C = _matrices(wn, z, g, w_a, za)
    sol = _damped(K, C)
    clipped = np.zeros(n + 1, bool)
    if sol is not None:
        w2, V, Ct, S, lam, a = sol.w2, sol.V, sol.Ct, sol.S, sol.lam, sol.a
        order = np.argsort(lam.imag)
    else:                                               # the overdamped fallback: real modes, projected damping
        w2, V = np.linalg.eigh(K)
        Ct = V.T @ C @ V
        W = np.sqrt(np.maximum(w2, 1e-300))
        Zr = np.diag(Ct) / (2 * W)
        clipped = (Zr < 1e-6) | (Zr > 0.99)
        Zc = np.clip(Zr, 1e-6, 0.99)
        lam = W * (-Zc + 1j * np.sqrt(1 - Zc ** 2))
        a, S, order = 2j * lam.imag, np.zeros(0, int), np.arange(n + 1)
    # the parameters' moves in the undamped coupled modes: dK~ (P, n+1, n+1), of dC~ its diagonal and S block
    ut = V.T @ np.append(g, -1.0)
    UU = np.outer(ut, ut)
    G = V[:n, :, None] * ut[None, None, :]
    G = G + G.transpose(0, 2, 1)                        # V^T (e_r u^T + u e_r^T) V
    DK = np.empty((n + 2, n + 1, n + 1))
    DK[0], DK[1], DK[2:] = 4 * np.pi * w_a * UU, 0.0, w_a ** 2 * G
    # dC~_p = DC_p dc_scale_p: dK~_p scaled, and for zeta (which leaves K alone) UU
    dc_scale = np.concatenate([[za / w_a, 2 * w_a], np.full(n, 2 * za / w_a)])
    DC = DK.copy()
    DC[1] = UU
    dw2 = np.einsum("pii->pi", DK)
    gap = w2[None, :] - w2[:, None]                     # [k, i] = w2_i - w2_k
    inv = np.divide(1.0, gap, out=np.zeros_like(gap), where=gap != 0)
    np.fill_diagonal(inv, 0.0)
    Q = DK * inv[None]
    dV = V[None] @ Q
    # dCt = Q^T Ct + Ct Q + dC~ (Ct symmetric): its diagonal, and the S block below
    dc = 2 * np.einsum("ik,pki->pi", Ct, Q) + np.einsum("pii->pi", DC) * dc_scale[:, None]
    c_diag, im = np.diag(Ct), lam.imag
    dlam = -dc / 2 + 1j * (dw2 - c_diag * dc / 2) / (2 * im)
    dlam[:, clipped] = lam[clipped] * dw2[:, clipped] / (2 * w2[clipped])
    # Pi_i = xi_i eta_i^T and R_ori = sum_m c_orm xi_mi eta_mi + (Phi xi)_oi (Phi_ref eta)_ri, differentiated;
    # dR (o, r, i, P). A mode the damping does not couple: xi = v mu, eta = v, mu = 1 / a, so
    # d(xi_m eta_m) = 2 mu v_m dv_m + dmu v_m^2, dmu = -mu dIm lambda / Im lambda (the coupled modes replaced below)
    c, ref = _kept(model, phi)
    n_out, n_ref = c.shape[:2]
    mu = 1.0 / a
    dmu = -mu * dlam.imag / im
    vb, dvb = V[:-1], dV[:, :-1]
    cf = c.reshape(-1, n)
    vdv = np.moveaxis(vb[None] * dvb, 0, 1).reshape(n, -1)           # (n, P (n+1)), real
    cv = (cf.real @ vdv + 1j * (cf.imag @ vdv)).reshape(n_out, n_ref, n + 2, n + 1).transpose(0, 1, 3, 2)
    dR = 2 * mu[None, None, :, None] * cv + (cf @ vb ** 2).reshape(n_out, n_ref, n + 1)[..., None] * dmu.T[None, None]
    if ref is not None:
        pv, rv = phi @ vb, ref @ vb
        pdv, rdv = np.moveaxis(phi[None] @ dvb, 0, -1), np.moveaxis(ref[None] @ dvb, 0, -1)   # (o, i, P), (r, i, P)
        dR = dR + (mu[None, None, :, None] * (pdv[:, None] * rv[None, :, :, None] + pv[:, None, :, None] * rdv[None])
                   + (pv[:, None, :] * rv[None, :, :])[..., None] * dmu.T[None, None])
    if S.size:
        ns, up = S.size, sol.up                         # type: ignore[union-attr]
        vec, ev = sol.vec, sol.ev                       # type: ignore[union-attr]
        Zt, Zb = vec[:ns], vec[ns:]
        Wr = np.linalg.inv(vec)[:, ns:]                 # the left eigenvectors' bottom halves (rows)
        XS = Ct[S][None] @ Q[:, :, S]
        dCtS = XS + XS.transpose(0, 2, 1) + DC[:, S][:, :, S] * dc_scale[:, None, None]
        B = -(dw2[:, S][:, :, None] * Zt[None] + dCtS @ Zb[None])
        F = Wr[None] @ B
        dev = ev[None, :] - ev[:, None]                 # [k, i] = ev_i - ev_k
        D = np.divide(1.0, dev, out=np.zeros_like(dev), where=dev != 0)
        np.fill_diagonal(D, 0.0)
        dlam[:, S] = F[:, up, up]
        # P_i's top-right block z_i w_i^T, so xi = V_S z_i, eta = V_S w_i; its derivative
        # (Z F~_:i) w_i^T + z_i (W^T F~_i:), F~ = F D
        Fcol = F[:, :, up] * D[None, :, up]
        Frow = F[:, up, :].transpose(0, 2, 1) * D[None, :, up]
        VS, dVS = V[:-1, S], dV[:, :-1, S]
        z, w = Zt[:, up], Wr[up].T
        xb, eb = VS @ z, VS @ w
        dxb = dVS @ z[None] + VS[None] @ (Zt[None] @ Fcol)
        deb = dVS @ w[None] + VS[None] @ (Wr.T[None] @ Frow)
        dRS = np.moveaxis((cf[None] @ (dxb * eb[None] + xb[None] * deb)).reshape(-1, n_out, n_ref, ns), 0, -1)
        if ref is not None:
            dpx, drx = np.moveaxis(phi[None] @ dxb, 0, -1), np.moveaxis(ref[None] @ deb, 0, -1)
            dRS = dRS + (dpx[:, None] * (ref @ eb)[None, :, :, None] + (phi @ xb)[:, None, :, None] * drx[None])
        dR[:, :, S, :] = dRS
    # R in the order of the coupled modes' frequencies, as apply_local_resonator computes it
    Xs, as_ = (sol.X[:, order], sol.a[order]) if sol is not None else (V.astype(complex), a)
    Rs = np.einsum("orm,mi->ori", c, Xs[:-1] ** 2) / as_[None, None, :]
    if ref is not None:
        Rs = Rs + (phi @ Xs[:-1])[:, None, :] * (ref @ Xs[:-1])[None, :, :] / as_[None, None, :]
    R = np.empty_like(Rs)
    R[:, :, order] = Rs
    p = QUANTITY_POWER[model.quantity]
    dRp = dR * (lam ** p)[None, None, :, None] + (p * R * lam ** (p - 1))[..., None] * dlam.T[None, None]
    # the overdamped fallback's model as apply_local_resonator gives it (its projected damping summed otherwise)
    out = (_resonated(model, lam[order], Rs, V[:-1, order], phi, ref) if sol is not None
           else apply_local_resonator(model, params))
    return out, dlam.T[order], dRp[:, :, order]
