"""Rayleigh-Ritz reduction of the frame's eigenproblem for changes on a few of its parts.

A candidate of the physical diagnosis is the nominal frame ``K0, M0`` changed on a few parts (an
element's bending stiffness, a node's mass, the supports' springs, a member's mass):
``K = K0 + sum_p a_p K_p``, ``M = M0 + sum_q b_q M_q``, each part nonzero only on a few DOFs. A mode of
the changed frame solves ``(K0 - lambda M0) phi = -(dK - lambda dM) phi``: it lies in the span of
``(K0 - lambda M0)^-1 X`` with ``X`` spanning the range of the change, whatever the size of the change.
Expanded in the nominal modes that span is the lowest nominal modes plus the flexibility of the
others, which for ``lambda`` well below the omitted modes is ``K0^-1 X`` (static correction) plus
``lambda K0^-1 M0 K0^-1 X`` (its first dynamic correction) and smaller terms. The basis is therefore

    V = [Phi_m, K0^-1 X, K0^-1 M0 K0^-1 X]     (M0-orthonormal, ``Phi_m`` the lowest ``N_MODES`` modes)

with ``X`` the unit vectors of the changed DOFs of a node or an element, the range of another local
part (on at most ``LOCAL_DOFS`` DOFs: the supports, the joints, the sensors' nodes) and ``D_p Phi_m`` for a part spread over a
whole member (its mass or bending stiffness: the first-order change of the nominal modes). The changed
frame's modes are those of ``(V^T K V, V^T M V)``: ``r`` unknowns (30 to about 100) instead of the
frame's ``n`` (186), and the projected parts ``V^T K_p V`` are computed once per set of changed parts,
so a candidate costs a sum of small matrices and one small eigenproblem. Ritz values bound the
eigenvalues from above and their error is quadratic in the basis's error: on the default frame the
reduced natural frequencies equal the full model's to 1e-6 relative (1e-12 to 6e-7; both solves'
own rounding is ~1e-11, see below) on changes far larger than the diagnosis meets (a 30 kg block, the
supports' springs x 0.001, an element at 0.02 of its bending stiffness, a member's EI x 0.3), see
``tests/test_ritz.py``.

A change of the whole frame costs no basis vector when it is proportional to the nominal matrices:
``K = s K0`` keeps the eigenvectors and scales the eigenvalues by ``s`` (``ReducedSpace.eigen``'s
``scale``). Young's modulus times ``E`` scales the members but not the springs of the supports and
joints: with ``S`` their sum, ``K = E (K0 - S) + S = E (K0 + (1/E - 1) S)``, i.e. ``scale = E`` and the
local part ``S`` with the coefficient ``1/E - 1`` (how :mod:`simulator.physical` states it). To first
order the changed modes move along ``K0^-1 (K0 - S) phi_i = phi_i - K0^-1 S phi_i``: only the springs'
static responses are new directions, so such a change needs the basis of a change of every spring (on
the default frame 36 DOFs: 72 vectors with the dynamic block) and none for the members. A smaller set
is not as accurate: the springs' and an element's ranges alone (24 instead of 36 vectors for the
springs, 4 instead of 12 for an element) leave errors of a few 1e-6 (a joint x 0.001 with the modulus
x 0.95, an element at 0.02). With a local change as well, a uniform change needs 100-135 unknowns, which
stays below :data:`MAX_FRACTION` with the lowest 30 or 40 modes.

Springs stiffened a hundredfold (the spring causes' upper bound) on the frame's light rotations make the
direct solve ``eigh(K, M)`` inexact: its eigenvalues' absolute error is the machine precision times the
largest eigenvalue of the pencil, ~1e13 times the lowest mode's, i.e. 1e-5 (one joint's rotational springs x
96) to 5e-4 (every joint's x 100 on top) relative. Both the full and the reduced model therefore solve the
inverse pencil ``M y = mu K y`` (:func:`inverse_eigh`, :func:`lowest_modes`), whose largest eigenvalues are
the lowest modes, each to the machine precision relative to itself: on those changes both agree to 1e-10 with
the energy quotients of the modes (``tests/test_ritz.py``).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg

from .errors import ModelError

__all__ = ["Part", "RitzReduction", "ReducedSpace", "N_MODES", "LOCAL_DOFS", "MAX_FRACTION", "inverse_eigh",
           "inverse_eigh_at", "lowest_modes"]

#: Nominal modes in every basis (on the default frame up to ~1.5 kHz, twice the highest mode the
#: diagnosis compares).
N_MODES = 30
#: A part on at most this many DOFs contributes their unit vectors; a larger one ``D_p Phi_m``.
LOCAL_DOFS = 24
#: The largest basis (a fraction of the frame's unknowns) solved reduced; a larger one goes to the full
#: model. A reduced solve (every eigenpair of the inverse pencil, :func:`inverse_eigh`) costs ~r^3, the full
#: one (the lowest modes of the inverse pencil, :func:`lowest_modes`) ~n^3 with a smaller constant; both are
#: accurate to 1e-10 (the basis's error is below the solve's). Measured on the default frame (186 unknowns,
#: one thread): 0.3 ms at 46 unknowns, 2.1-2.7 ms at 102-119 (a uniform stiffness change with a local one),
#: 4.1 ms at 123 (with a changed mass: the generalized problem), the full solve 4.2-7.6 ms; by r^3 the reduced
#: solve reaches the full one's cost near 0.8 n, so a basis up to 0.75 n is solved reduced (a basis costs 4-16
#: ms, once per set of changed parts).
MAX_FRACTION = 0.75
#: Basis directions whose M0-Gram eigenvalue is below this fraction of the largest are dropped.
_RANK_TOL = 1e-10

_sygvd, _potrf, _potri, _sygst, _sytrd, _stevd, _ormqr, _sterf, _stein = scipy.linalg.get_lapack_funcs(
    ("sygvd", "potrf", "potri", "sygst", "sytrd", "stevd", "ormqr", "sterf", "stein"), (np.zeros((1, 1)),))


@dataclass(frozen=True)
class Part:
    """A piece of a stiffness or mass matrix: ``block`` (square, len(dofs)) on the global DOFs ``dofs``."""

    dofs: np.ndarray
    block: np.ndarray

    def add_to(self, A: np.ndarray, c: float) -> None:
        """``A += c * part`` in place (``A`` square, the frame's DOFs)."""
        A[np.ix_(self.dofs, self.dofs)] += c * self.block

    def times(self, X: np.ndarray) -> np.ndarray:
        """``part @ X`` for X (n, k)."""
        out = np.zeros_like(X)
        out[self.dofs] = self.block @ X[self.dofs]
        return out

    def range(self, n: int) -> np.ndarray:
        """An orthonormal basis (n, rank) of the part's range (a joint's springs act on the difference of
        its two nodes' motions: six directions on twelve DOFs)."""
        e, U = np.linalg.eigh(self.block)
        keep = np.abs(e) > 1e-12 * np.abs(e).max()
        out = np.zeros((n, int(keep.sum())))
        out[self.dofs] = U[:, keep]
        return out

    def project(self, V: np.ndarray) -> np.ndarray:
        """``V^T part V`` (r, r)."""
        W = V[self.dofs]
        return W.T @ self.block @ W


class ReducedSpace:
    """The frame projected on one Ritz basis ``V`` (n, r): the nominal ``V^T K0 V``, ``V^T M0 V``, each changed
    part's projection and the basis's rows ``rows`` (global DOFs); :meth:`eigen` solves a candidate in it. The
    basis itself (the frame's size) is not kept: a search keeps a space per set of changed parts, hundreds on a
    fine frame, and only these small matrices are used."""

    def __init__(self, V: np.ndarray, K0: np.ndarray, M0: np.ndarray, kparts: Mapping, mparts: Mapping,
                 rows: Sequence[int] = ()) -> None:
        self.size = int(V.shape[1])
        #: ``V[rows]`` (len(rows), r): the basis at the DOFs asked for (the measured points)
        self.at = V[np.asarray(rows, dtype=int)]
        self.K0 = V.T @ K0 @ V
        self.M0 = V.T @ M0 @ V
        self.K0 = 0.5 * (self.K0 + self.K0.T)
        self.M0 = 0.5 * (self.M0 + self.M0.T)
        self.kparts = {k: p.project(V) for k, p in kparts.items()}
        self.mparts = {k: p.project(V) for k, p in mparts.items()}
        #: for a change of masses alone (``K0`` unchanged): ``K0``'s Cholesky factor ``L`` and ``L^-1 M L^-T`` of the
        #: nominal and of each mass part (lower triangles), made when first asked (False: ``K0`` not positive definite)
        self._factor: tuple[np.ndarray, np.ndarray] | bool | None = None
        self._mass_pencils: dict = {}

    def eigen(self, dk: Mapping, dm: Mapping, scale: float, w2_max: float) -> tuple[np.ndarray, np.ndarray]:
        """Eigenvalues ``omega^2`` in ``(1, w2_max)`` (rad/s)^2 of ``(scale (K0 + sum dk_p K_p), M0 + sum
        dm_q M_q)`` in this space and the Ritz vectors' coefficients (r, n_modes), M-normalised."""
        w2, Y = self.eigen_all(dk, dm)
        return _in_band(scale * w2, Y, w2_max)

    def eigen_at(self, dk: Mapping, dm: Mapping, scale: float, w2_max: float, at: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`eigen`'s eigenvalues and ``at @ Y`` (the Ritz vectors' coefficients ``Y`` mapped by ``at`` (p, r):
        the modes at a few DOFs) instead of ``Y``: by :func:`inverse_eigh_at`, which forms no eigenvector and solves
        for the modes in the band alone."""
        K, M = self.matrices(dk, dm)
        w2, AY = inverse_eigh_at(K, M, at, lambda w2: (scale * w2 > 1.0) & (scale * w2 < w2_max),
                                 None if dk else self._mass_pencil(dm))
        return scale * w2, AY

    def matrices(self, dk: Mapping, dm: Mapping) -> tuple[np.ndarray, np.ndarray | None]:
        """The candidate's reduced ``K0 + sum dk_p K_p`` and ``M0 + sum dm_q M_q`` (None: ``M0``, the identity
        to rounding)."""
        K = self.K0.copy()
        for key, c in dk.items():
            K += c * self.kparts[key]
        M = None
        if dm:
            M = self.M0.copy()
            for key, c in dm.items():
                M += c * self.mparts[key]
        return K, M

    def eigen_all(self, dk: Mapping, dm: Mapping) -> tuple[np.ndarray, np.ndarray]:
        """Every eigenpair of ``(K0 + sum dk_p K_p, M0 + sum dm_q M_q)`` in this space (the modulus' ``scale``
        not applied), ascending, the vectors M-normalised: by the inverse pencil (:func:`inverse_eigh`)."""
        K, M = self.matrices(dk, dm)
        pencil = None if dk else self._mass_pencil(dm)
        if pencil is not None:
            L, C = pencil
            try:
                mu, Z = np.linalg.eigh(C, UPLO="L")          # as sygvd: the pencil's eigenpairs, then y = L^-T z
            except np.linalg.LinAlgError:
                return inverse_eigh(K, M)
            Y = scipy.linalg.solve_triangular(L, Z, trans="T", lower=True, check_finite=False)
            mu, Y = mu[::-1], Y[:, ::-1]
            return 1.0 / mu, Y / np.sqrt(mu)
        return inverse_eigh(K, M)

    def _mass_pencil(self, dm: Mapping) -> tuple[np.ndarray, np.ndarray] | None:
        """A change of the masses ``dm`` alone as the inverse pencil of :func:`inverse_eigh` reduced by ``K0``'s
        Cholesky factor ``L``: ``(L, L^-1 (M0 + sum dm_q M_q) L^-T)`` (lower triangle), a sum of the nominal's and
        each part's, each made once (``K0`` is every such candidate's); None without a mass change or when ``K0`` is
        not positive definite."""
        if not dm:
            return None
        if self._factor is None:
            self._factor = False
            L, info = _potrf(self.K0, lower=1)
            if not info:
                C0, info = _sygst(self.M0, L, itype=1, lower=1)
                if not info:
                    self._factor = (L, C0)
        if not isinstance(self._factor, tuple):
            return None
        L, C0 = self._factor
        C = C0.copy()
        for key, c in dm.items():
            part = self._mass_pencils.get(key)
            if part is None:
                part, info = _sygst(self.mparts[key], L, itype=1, lower=1)
                if info:
                    return None
                self._mass_pencils[key] = part
            C += c * part
        return L, C


def _in_band(w2: np.ndarray, X: np.ndarray, w2_max: float) -> tuple[np.ndarray, np.ndarray]:
    """The eigenvalues ``w2`` (rad/s)^2 in ``(1, w2_max)`` and the columns of ``X`` that go with them."""
    keep = (w2 > 1.0) & (w2 < w2_max)
    return w2[keep], X[:, keep]


def inverse_eigh(K: np.ndarray, M: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Every eigenpair of ``K y = omega^2 M y`` (``M`` None: the identity; ``K``, ``M`` symmetric positive
    definite), ``omega^2`` ascending and the vectors M-normalised, solved as the inverse pencil
    ``M y = mu K y`` (``mu = 1 / omega^2``) on the Cholesky factor of ``K``.

    Why: a solver's eigenvalues carry an absolute error of about the machine precision times the largest
    eigenvalue of the pencil it reduces. ``eigh(K, M)`` reduces ``L_M^-1 K L_M^-T``, whose largest eigenvalue
    with stiff springs on light rotations is ~1e13 times the lowest mode's: the lowest frequencies come out off
    by 1e-5..1e-3 (relative) with springs x 100. The inverse pencil's largest eigenvalues are the lowest
    modes, each with an error of the machine precision relative to itself (the Cholesky factor of ``K`` is
    backward stable entry by entry). A ``K`` that is not positive definite (a mechanism) is solved directly.

    How: ``K^-1`` (Cholesky) and its eigenproblem (``syevd``); with ``M`` LAPACK's divide-and-conquer driver
    ``sygvd``. The fits' answers depend on these solves to their rounding (a least squares stopped at its tolerance
    moves with them), so a change of this routine changes the diagnosis' parameters at ~1e-8."""
    K = 0.5 * (K + K.T)
    if M is None:
        L, info = _potrf(K, lower=1)
        if not info:
            Kinv, info = _potri(L, lower=1)
        if info:
            return _direct_eigh(K, None)
        mu, Y = np.linalg.eigh(Kinv, UPLO="L")
        return 1.0 / mu[::-1], Y[:, ::-1]
    # M y = mu K y, the vectors K-normalised (y^T K y = 1, so y^T M y = mu)
    mu, Y, info = _sygvd(M, K, itype=1, jobz="V", uplo="L")
    if info:
        return _direct_eigh(K, M)
    mu, Y = mu[::-1], Y[:, ::-1]
    return 1.0 / mu, Y / np.sqrt(mu)


def inverse_eigh_at(K: np.ndarray, M: np.ndarray | None, A: np.ndarray, keep: Any = None,
                    pencil: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`inverse_eigh`'s eigenvalues ``omega^2`` (ascending) and its vectors ``Y`` seen through ``A`` (p, r):
    ``A @ Y`` (p, r). The same solve, except that the vectors are not formed: ``A Y = (A Q) Z`` (or ``(A L^-T Q)
    Z``) costs ~p r^2 instead of the ~r^3 of ``Q Z`` (with p a few measured DOFs and r ~50, a fifth of the
    solve). ``keep``: a function of the eigenvalues ``omega^2`` (ascending) that selects the modes wanted (a mask,
    the band a search compares): only those are returned, the tridiagonal form's eigenvalues solved alone (``sterf``)
    and the eigenvectors of the modes kept by inverse iteration (``stein``: a few of ~50, each ~r operations, instead
    of every eigenvector by divide and conquer). ``pencil``: ``K``'s Cholesky factor and the reduced pencil
    ``L^-1 M L^-T`` (lower triangle) when known (:meth:`ReducedSpace._mass_pencil`)."""
    K = 0.5 * (K + K.T)
    reduced = _tridiagonal(K, M, pencil)
    if reduced is None:
        w2, Y = _direct_eigh(K, M)
        if keep is None:
            return w2, A @ Y
        chosen = np.asarray(keep(w2), bool)
        return w2[chosen], A @ Y[:, chosen]
    L, c, d, e, tau = reduced
    if keep is None:
        mu, Z, info = _stevd(d, e)
        if info:
            return _at_direct(K, M, A)
    else:
        mu, info = _sterf(d, e)[:2] if d.size > 1 else (d.copy(), 0)
        if info:
            return _at_direct(K, M, A, keep)
        w2 = 1.0 / mu[::-1]
        wanted = np.flatnonzero(np.asarray(keep(w2), bool))
        n = d.size
        order = (n - 1 - wanted)[::-1]                 # ascending mu, as inverse iteration takes them
        mu = mu[order]
        if mu.size:
            split = np.zeros(n, np.int32)
            split[0] = n                               # one block: the whole tridiagonal form
            Z, info = _stein(d, e, mu, np.ones(n, np.int32), split)
            if info:
                return _at_direct(K, M, A, keep)
        else:
            Z = np.zeros((n, 0))
    B = np.array(A, dtype=float)
    if M is not None:
        B = scipy.linalg.solve_triangular(L, B.T, lower=True, check_finite=False).T
    if d.size > 1:
        B[:, 1:], _, info = _ormqr("R", "N", c[1:, :-1], tau, B[:, 1:], lwork=max(1, 64 * B.shape[0]))
        if info:
            raise np.linalg.LinAlgError(f"the reduced eigenproblem's reflectors failed (LAPACK ormqr info {info})")
    AY = (B @ Z)[:, ::-1]
    mu = mu[::-1]
    return 1.0 / mu, (AY if M is None else AY / np.sqrt(mu))


def _at_direct(K: np.ndarray, M: np.ndarray | None, A: np.ndarray, keep: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`inverse_eigh_at` by :func:`inverse_eigh` (when LAPACK's tridiagonal solvers fail)."""
    w2, Y = inverse_eigh(K, M)
    chosen = np.ones(w2.size, bool) if keep is None else np.asarray(keep(w2), bool)
    return w2[chosen], A @ Y[:, chosen]


def _tridiagonal(K: np.ndarray, M: np.ndarray | None, pencil: tuple[np.ndarray, np.ndarray] | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The inverse pencil ``M y = mu K y`` of :func:`inverse_eigh` (``K`` symmetric) reduced: ``K``'s Cholesky
    factor ``L`` (lower) and ``C`` (``K^-1``; with ``M``, ``L^-1 M L^-T``) tridiagonalised (``sytrd``, lower: its
    reflectors ``c``, diagonal ``d``, off-diagonal ``e``, ``tau``); None when ``K`` is not positive definite (or LAPACK
    fails); ``pencil``: ``L`` and ``C`` known."""
    if pencil is not None and M is not None:
        L, C = pencil
    else:
        L, info = _potrf(K, lower=1)
        if info:
            return None
        C, info = _potri(L, lower=1) if M is None else _sygst(M, L, itype=1, lower=1)
        if info:
            return None
    c, d, e, tau, info = _sytrd(C, lower=1)
    return None if info else (L, c, d, e, tau)


def _direct_eigh(K: np.ndarray, M: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`inverse_eigh` of a ``K`` that is not positive definite: the direct pencil ``K y = omega^2 M y``."""
    if M is None:
        w2, Y = np.linalg.eigh(K)
        return w2, Y
    # LAPACK's divide-and-conquer driver (without ``scipy.linalg.eigh``'s checks, which cost a third of a solve here)
    w2, Y, info = _sygvd(K, M, itype=1, jobz="V", uplo="L")
    if info:
        raise np.linalg.LinAlgError(f"the reduced eigenproblem failed (LAPACK sygvd info {info}): "
                                    "the changed mass matrix is not positive definite")
    return w2, Y


def lowest_modes(K: np.ndarray, M: np.ndarray, w2_max: float) -> tuple[np.ndarray, np.ndarray]:
    """The eigenpairs of the full model ``K phi = omega^2 M phi`` with ``1 < omega^2 < w2_max`` (rad/s)^2,
    ascending, M-normalised: the inverse pencil (:func:`inverse_eigh`'s reason) with only those computed."""
    try:
        mu, phi = scipy.linalg.eigh(M, K, subset_by_value=(1.0 / w2_max, 1.0), check_finite=False)
    except np.linalg.LinAlgError:       # K not positive definite (a mechanism): the direct pencil
        w2, phi = scipy.linalg.eigh(K, M, subset_by_value=(1.0, w2_max))
        return w2, phi
    mu, phi = mu[::-1], phi[:, ::-1]
    return 1.0 / mu, phi / np.sqrt(mu)


#: the message of a frame whose stiffness matrix is singular (it moves freely: nothing holds it)
SINGULAR_STIFFNESS = ("the frame's stiffness matrix is singular: the frame can move without deforming (a rigid-body "
                      "or mechanism mode at 0 Hz); give [supports] nodes and stiffness values > 0 that hold it "
                      "(and [joints] stiffness > 0 where members meet)")


class RitzReduction:
    """Builds the Ritz bases of the nominal frame ``K0, M0`` (module docstring)."""

    def __init__(self, K0: np.ndarray, M0: np.ndarray) -> None:
        self.K0, self.M0 = K0, M0
        self.w2, self.modes = scipy.linalg.eigh(K0, M0)
        try:
            self._chol = scipy.linalg.cho_factor(K0)
        except np.linalg.LinAlgError:
            raise ModelError(SINGULAR_STIFFNESS) from None

    def n_modes(self, w2_max: float) -> int:
        """Nominal modes a basis needs for eigenvalues up to ``w2_max`` (rad/s)^2: ``N_MODES``, or more
        so that the omitted modes lie above twice the highest frequency wanted (in steps of 10)."""
        need = int(np.searchsorted(self.w2, 4.0 * w2_max))
        return max(N_MODES, 10 * int(np.ceil(need / 10)))

    def space(self, kparts: Mapping, mparts: Mapping, n_modes: int = N_MODES, rows: Sequence[int] = ()
              ) -> ReducedSpace | None:
        """The reduced space for changes on ``kparts`` / ``mparts`` ({key: :class:`Part`}) with the lowest
        ``n_modes`` nominal modes, its basis kept at the DOFs ``rows``; None when the basis would have more than
        :data:`MAX_FRACTION` of the frame's unknowns (then the full model is solved)."""
        n = self.K0.shape[0]
        if n_modes > MAX_FRACTION * n:
            return None
        phi = self.modes[:, :n_modes]
        X = []
        for p in [*kparts.values(), *mparts.values()]:
            if p.dofs.size <= 12:             # a node, an element: every DOF (the range alone is less accurate)
                E = np.zeros((n, p.dofs.size))
                E[p.dofs, np.arange(p.dofs.size)] = 1.0
                X.append(E)
            elif p.dofs.size <= LOCAL_DOFS:   # springs between nodes act on differences: their range
                X.append(p.range(n))
            else:
                X.append(p.times(phi))
        if X:
            A = scipy.linalg.cho_solve(self._chol, np.hstack(X), check_finite=False)
            B = scipy.linalg.cho_solve(self._chol, self.M0 @ A, check_finite=False)
            R = np.hstack([A, B])
            R -= phi @ (phi.T @ (self.M0 @ R))
            norms = np.sqrt(np.maximum(np.einsum("ij,ij->j", R, self.M0 @ R), 0.0))
            R = R[:, norms > 0] / norms[norms > 0]
            e, U = np.linalg.eigh(R.T @ self.M0 @ R)
            keep = e > _RANK_TOL * e.max()
            Q = R @ (U[:, keep] / np.sqrt(e[keep]))
            V = np.hstack([phi, Q])
            # M0-orthonormal to rounding (the standard eigenproblem of a stiffness change relies on it)
            L = np.linalg.cholesky(V.T @ self.M0 @ V)
            V = scipy.linalg.solve_triangular(L, V.T, lower=True, check_finite=False).T
        else:
            V = phi
        if V.shape[1] > MAX_FRACTION * n:
            return None
        return ReducedSpace(V, self.K0, self.M0, kparts, mparts, rows)

    def whole(self, kparts: Mapping, mparts: Mapping, rows: Sequence[int] = ()) -> ReducedSpace:
        """The full model as a space: every nominal mode (M0-orthonormal to rounding), the basis in which the
        full model's candidates are differentiated like a reduced one's."""
        V = self.modes
        L = np.linalg.cholesky(V.T @ self.M0 @ V)
        V = scipy.linalg.solve_triangular(L, V.T, lower=True).T
        return ReducedSpace(V, self.K0, self.M0, kparts, mparts, rows)
