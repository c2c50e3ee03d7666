"""Numerical kernels of the nonlinear LSFD fit: model basis, variable projection, normal equations.

Model (the paper's eq. (11)) for FRF ``f`` (one (output, reference) pair) at line ``n``::

    H_f(w_n) = sum_r [ R_fr / (jw_n - lambda_r) + conj(R_fr) / (jw_n - conj(lambda_r)) ]
               + sum_k T_fk b_k(w_n)

with global poles ``lambda_r = sigma_r + j omega_r`` (rad/s) and per-FRF residues ``R_fr``
and residual terms ``T_fk`` (basis ``b_k`` from :func:`analysis.modal.residual_basis`).

Real linear parameters
----------------------
With ``K_r = 1/(jw - lambda_r)``, ``Kc_r = 1/(jw - conj(lambda_r))`` and ``R = a + j b``::

    R K_r + conj(R) Kc_r = a g1_r + b g2_r,   g1_r = K_r + Kc_r,   g2_r = j (K_r - Kc_r)

and ``T b_k = Re(T) b_k + Im(T) (j b_k)``. The columns ``g1_r, g2_r, b_k, j b_k`` form the
complex basis ``Phi`` (n_freq x P, ``P = 2 m + 2 n_res``) with *real* coefficients; stacking
real and imaginary parts (rows ``[Re; Im]``) gives the real problem ``A c_f ~ y_f`` with
``A`` (2 n_freq x P) shared by all FRFs.

Variable projection
-------------------
For fixed poles the coefficients are the least-squares solution ``c_f = A^+ y_f`` (one
QR of ``A`` serves every FRF as a right-hand side) and the residual is ``r_f = P y_f`` with
``P = I - Q Q^T`` (``A = Q R``). The nonlinear parameters are
``theta = (sigma_1, omega_1, ..., sigma_m, omega_m)`` (rad/s). Kaufman's Jacobian of
``r_f`` is ``J_f = -P (dA/dtheta) c_f``. The derivatives of the mode-r columns are

    E1_r = K_r^2 + Kc_r^2,  E2_r = j (K_r^2 - Kc_r^2)
    d(a g1 + b g2)/d sigma_r = a E1_r + b E2_r,   d(a g1 + b g2)/d omega_r = a E2_r - b E1_r

so ``J_f = -P E Gamma_f`` with ``E = [E1_1, E2_1, ..., E1_m, E2_m]`` (stacked real,
2 n_freq x 2 m) shared by all FRFs and ``Gamma_f`` block diagonal with the 2x2 blocks
``[[a, -b], [b, a]]`` of the residues of FRF f. Hence, with ``G = (P E)^T (P E)``::

    J^T J = sum_f Gamma_f^T G Gamma_f,    J^T r = -sum_f Gamma_f^T E^T r_f

(using ``P r_f = r_f``). The stacked Jacobian (2 n_freq n_frf x 2 m) is never formed:
the cost per evaluation is a QR of ``A`` plus a few products with the data matrix.

Weights
-------
Line weights ``w_n`` (real, > 0) multiply rows of ``A``, ``E`` and the data; FRF weights
``v_f`` multiply data columns. The fitted objective is ``S = sum_f sum_n |v_f w_n e_fn|^2``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .modal import residual_basis

__all__ = [
    "ProjectedProblem",
    "Evaluation",
    "poles_to_theta",
    "theta_to_poles",
    "Status",
    "NLSOutcome",
    "solve_scaled",
    "solve_upper",
    "projected_gram",
    "householder_project",
    "gram_from_G",
    "RANK_TOL",
    "MIN_GRAM_SAVING",
    "evaluation_flops",
    "gram_form_pays",
]

#: relative threshold on the diagonal of the QR factor below which the basis is rank deficient
RANK_TOL = 1e-11


#: the least saving, in floating-point operations per evaluation, for which the Gram-based form is used
#: (:func:`gram_form_pays`): an evaluation's NumPy calls cost about 0.1 ms whatever its size; a saving
#: below 1e5 operations (a few microseconds) is lost in them, and the direct form, whose rounding is
#: that of orthogonal transformations, is kept
MIN_GRAM_SAVING = 1e5


def evaluation_flops(n_lines: int, n_frf: int, n_modes: int, n_res: int) -> tuple[float, float]:
    """Floating-point operations of one evaluation of the projected problem in the Gram-based and in
    the direct form, ``(gram, direct)``, beyond what both share (the basis ``A``, its derivative columns
    ``E`` and the Householder factorisation of ``A``).

    Sizes: ``r = 2 n_lines`` real rows, ``P = 2 n_modes + 2 n_res`` basis columns, ``k = 2 n_modes``
    derivative columns, ``F = n_frf`` data columns (a product of an (a x b) and a (b x c) matrix costs
    ``2 a b c``, a symmetric one ``A^T A`` half of it, a triangular solve with c right-hand sides ``b^2 c``):

    * Gram-based (:meth:`ProjectedProblem.evaluate` with ``fast``): ``A^T Y`` and ``E^T Y``
      (``2 r F (P + k)``), ``A^T E`` (``2 r P k``), ``E^T E`` (``r k^2``), the triangular solves for
      ``Q^T Y``, ``Q^T E`` and the coefficients (``P^2 (2 F + k)``);
    * direct (:func:`householder_project`): ``V^T V`` for the reflectors' block form (``r P^2``),
      ``V^T [E Y]`` and ``[E Y] - V Z`` (``4 r P (k + F)``), ``G`` and ``E^T r`` from the rows below the
      basis (``r k^2 + 2 r k F``), the triangular solves (``P^2 (k + 2 F)``) and ``Q^T Y`` (``2 P^2 F``).

    The direct form costs more at every size (by ``r P^2 + 2 r P (k + F)`` and more), most where the
    FRFs are many: measured on one core of a shared 2-core machine, a whole direct evaluation (the
    shared part included) took 1.05 to 1.3 times a Gram-based one with 3 or 4 FRFs (1400 to 8200 lines,
    22 to 75 modes), 1.6 times with 85 or 222 FRFs and 3 times with 3000 FRFs (8000 lines, 40 modes);
    at a few dozen lines both cost their NumPy overhead, about 0.1 to 0.3 ms, within the machine's
    scatter. What the count leaves out is that a Gram-based evaluation can fall back to the
    direct one (it loses its digits to cancellation when a derivative column lies nearly inside the
    basis or the fit is nearly exact) and then costs both: :meth:`ProjectedProblem.evaluate` answers
    a fast request in the direct form while the last evaluation shows the Gram form would fail.
    """
    r, F = 2.0 * n_lines, float(n_frf)
    k = 2.0 * n_modes
    P = k + 2.0 * n_res
    gram = 2 * r * F * (P + k) + 2 * r * P * k + r * k ** 2 + P ** 2 * (2 * F + k)
    direct = r * P ** 2 + 4 * r * P * (k + F) + r * k ** 2 + 2 * r * k * F + P ** 2 * (k + 2 * F) + 2 * P ** 2 * F
    return gram, direct


def gram_form_pays(n_lines: int, n_frf: int, n_modes: int, n_res: int, falls_back: bool = False) -> bool:
    """Whether a Gram-based evaluation of a projected problem of these sizes is worth trying: it saves at
    least :data:`MIN_GRAM_SAVING` operations over the direct one (:func:`evaluation_flops`).

    Sizes: ``n_lines`` frequency lines, ``n_frf`` FRFs (data columns), ``n_modes`` poles, ``n_res``
    residual terms. ``falls_back``: the Gram form is expected to lose its digits at these poles (the
    last evaluation showed it) and fall back to the direct form, so an attempt would cost both forms:
    never worth it. A default capture's whole-band fit (3 FRFs x 1400 lines, 20 modes) saves about
    20 million operations an evaluation and uses it; its local fits of a few dozen lines around one
    resonance save some ten thousand and stay direct (those of 222 FRFs, 300 thousand: Gram-based)."""
    gram, direct = evaluation_flops(n_lines, n_frf, n_modes, n_res)
    if falls_back:
        gram += direct
    return direct - gram >= MIN_GRAM_SAVING


class Status:
    """Status codes of the nonlinear solvers (``> 0`` is success)."""

    MAX_ITER = 0
    FTOL = 1
    XTOL = 2
    ROUNDOFF = 4
    #: the poles were given (fitted elsewhere); residues and residual terms solved at them
    FIXED_POLES = 5
    S_INCREASED = -1
    UNSTABLE = -2
    COLLAPSED = -3
    NO_PROGRESS = -4


@dataclass
class NLSOutcome:
    """What a solver returns: final parameters, its evaluation and the bookkeeping."""

    theta: np.ndarray
    evaluation: Evaluation
    history: list
    iterations: int
    nfev: int
    status: int
    message: str


def poles_to_theta(poles: np.ndarray) -> np.ndarray:
    """(sigma_1, omega_1, ..., sigma_m, omega_m) in rad/s from poles ``sigma + j omega``."""
    p = np.asarray(poles, dtype=complex)
    return np.column_stack([p.real, p.imag]).ravel()


def theta_to_poles(theta: np.ndarray) -> np.ndarray:
    """Inverse of :func:`poles_to_theta`."""
    t = np.asarray(theta, dtype=float).reshape(-1, 2)
    return t[:, 0] + 1j * t[:, 1]


def _stack(z: np.ndarray) -> np.ndarray:
    """Rows [Re; Im] of a complex (n, ...) array -> real (2n, ...)."""
    return np.concatenate([z.real, z.imag], axis=0)


def _pair_columns(M: np.ndarray, X: np.ndarray, Xc: np.ndarray) -> None:
    """Write the stacked columns ``X + Xc`` and ``j (X - Xc)`` of (m, N) complex ``X``, ``Xc`` (a row per
    pole) into the first 2m columns of the real (2N, .) ``M`` (interleaved, rows [Re; Im]; in Fortran
    order every write is contiguous)."""
    m, N = X.shape
    np.add(X.real, Xc.real, out=M[:N, 0:2 * m:2].T)
    np.add(X.imag, Xc.imag, out=M[N:, 0:2 * m:2].T)
    np.subtract(Xc.imag, X.imag, out=M[:N, 1:2 * m:2].T)
    np.subtract(X.real, Xc.real, out=M[N:, 1:2 * m:2].T)


@dataclass
class Evaluation:
    """The variable-projection state at one set of poles.

    Both kinds hold the Gram quantities ``G = (P E)^T (P E)`` and ``E^T r`` the normal equations
    need; ``precise`` ones compute them with orthogonal transformations only, fast ones (see
    :meth:`ProjectedProblem.evaluate`) from the semi-normal equations.
    """

    theta: np.ndarray
    S: float
    coef: np.ndarray | None       # (P, n_frf) real coefficients of the weighted data
    rank_ok: bool
    rcond: float
    precise: bool = True
    E: np.ndarray | None = None   # (2N, 2m) weighted derivative columns
    G: np.ndarray | None = None   # (2m, 2m) (P E)^T (P E)
    EtR: np.ndarray | None = None  # (2m, n_frf) E^T r


class ProjectedProblem:
    """The separable least-squares problem of one FRF set (see the module docstring).

    Parameters
    ----------
    omega : (N,) rad/s.
    Y : (n_frf, N) complex FRFs (rows are the FRFs).
    quantity, residual_form : select the residual basis (:func:`analysis.modal.residual_basis`).
    line_weights : (N,) positive or None.
    frf_weights : (n_frf,) positive or None.
    """

    def __init__(
        self,
        omega: np.ndarray,
        Y: np.ndarray,
        quantity: str,
        residual_form: str,
        line_weights: np.ndarray | None = None,
        frf_weights: np.ndarray | None = None,
    ) -> None:
        self.omega = np.asarray(omega, dtype=float)
        self.jw = 1j * self.omega
        self.N = self.omega.size
        self.B = residual_basis(self.omega, quantity, residual_form)   # (n_res, N)
        self.n_res = self.B.shape[0]
        self.line_w = None if line_weights is None else np.asarray(line_weights, dtype=float)
        self.frf_w = None if frf_weights is None else np.asarray(frf_weights, dtype=float)
        Y = np.asarray(Y)
        # rows [Re; Im] of every FRF written contiguously, then seen transposed (2N, n_frf): two
        # plain copies of the data instead of two strided ones (a large set costs seconds so)
        rows = np.empty((Y.shape[0], 2 * self.N))
        rows[:, : self.N] = Y.real
        rows[:, self.N:] = Y.imag
        ys = rows.T
        if self.line_w is not None:
            ys *= np.concatenate([self.line_w, self.line_w])[:, None]
        if self.frf_w is not None:
            ys *= self.frf_w[None, :]
        self.Ys = ys                               # (2N, n_frf) weighted stacked data
        self.n_frf = ys.shape[1]
        self.y_norm2 = float(np.einsum("ij,ij->", ys, ys))
        # residual-term columns b_k and j b_k (fixed)
        if self.n_res:
            cols = np.empty((self.N, 2 * self.n_res), dtype=complex)
            cols[:, 0::2] = self.B.T
            cols[:, 1::2] = 1j * self.B.T
            self._res_cols = cols
        else:
            self._res_cols = np.zeros((self.N, 0), dtype=complex)
        #: whether the Gram-based form loses its digits at the poles of the last evaluation (a fast one
        #: fell back, or a precise one shows it would have: :meth:`_gram_loses_digits`): the poles an
        #: iteration tries next are close to those, so a fast request then goes straight to the direct
        #: form instead of paying for a Gram-based evaluation that would fall back to it
        self.gram_fails = False

    # ------------------------------------------------------------------ basis
    def n_linear(self, n_modes: int) -> int:
        """Number of real linear parameters per FRF, ``P = 2 m + 2 n_res``."""
        return 2 * n_modes + 2 * self.n_res

    def n_lines(self) -> int:
        """Lines that count as observations (non-zero line weight)."""
        return self.N if self.line_w is None else int(np.count_nonzero(self.line_w))

    def dof(self, n_modes: int) -> int:
        """Degrees of freedom of the real residuals with ``n_modes`` poles: ``2 lines n_frf`` real
        equations less ``2 m`` pole parameters and ``n_frf P`` linear ones (may be <= 0)."""
        return 2 * self.n_lines() * self.n_frf - 2 * n_modes - self.n_frf * self.n_linear(n_modes)

    def basis(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Weighted stacked basis ``A`` (2N x P) and derivative columns ``E`` (2N x 2m).

        Written straight into the real arrays (rows ``[Re; Im]``) from the real and imaginary parts
        of ``K``, ``Kc`` and their squares: no complex basis is built and stacked afterwards. Both are
        in Fortran order (a column after the other): the QR factorisation (LAPACK) reads ``A`` so
        without a transposed copy, and every column is written contiguously."""
        lam = theta_to_poles(theta)
        m, N = lam.size, self.N
        # reciprocals into fresh arrays: numpy's in-place complex division is several times slower
        K = np.reciprocal(self.jw[None, :] - lam[:, None])             # (m, N)
        Kc = np.reciprocal(self.jw[None, :] - np.conj(lam)[:, None])
        A = np.empty((2 * N, 2 * m + 2 * self.n_res), order="F")
        E = np.empty((2 * N, 2 * m), order="F")
        _pair_columns(A, K, Kc)
        _pair_columns(E, np.square(K, out=K), np.square(Kc, out=Kc))
        A[:N, 2 * m:] = self._res_cols.real
        A[N:, 2 * m:] = self._res_cols.imag
        if self.line_w is not None:
            w2 = np.concatenate([self.line_w, self.line_w])[:, None]
            A *= w2
            E *= w2
        return A, E

    # ------------------------------------------------------------- evaluation
    #: fast evaluations fall back to precise ones when S < FAST_MIN_REL_S ||y||^2, or when a derivative
    #: column keeps less than that fraction of its square norm outside the basis (diag G < FAST_MIN_REL_S diag E^T E)
    FAST_MIN_REL_S = 1e-6

    def prefers_gram(self, n_modes: int) -> bool:
        """Whether a fast (Gram-based) evaluation with ``n_modes`` poles is worth trying now: the cost
        model of :func:`gram_form_pays` at this problem's sizes, with the fall-back the last evaluation
        predicts (:attr:`gram_fails`)."""
        return gram_form_pays(self.N, self.n_frf, n_modes, self.n_res, self.gram_fails)

    def _gram_loses_digits(self, S: float, G: np.ndarray | None, E: np.ndarray) -> bool:
        """Whether the Gram-based form loses its digits to cancellation at an evaluation with ``S`` and
        (when already computed) ``G``: ``S < FAST_MIN_REL_S ||y||^2``, or a derivative column keeps less
        than that fraction of its square norm outside the basis."""
        if S < self.FAST_MIN_REL_S * self.y_norm2:
            return True
        if G is None:
            return False
        return not bool(np.all(np.diag(G) > self.FAST_MIN_REL_S * np.einsum("ij,ij->j", E, E)))

    def evaluate(self, theta: np.ndarray, *, fast: bool = False) -> Evaluation:
        """Project the data on the basis at ``theta``: S, coefficients and what the normal equations need.

        ``fast``: the Gram-based form may be used (where :meth:`prefers_gram`); else precise.

        Precise: Householder QR ``A = Q R`` (columns normalised) and the same reflectors applied
        to ``[E y]`` (:func:`householder_project`): ``S = ||r||^2``, ``G`` and ``E^T r`` from the
        rows of ``Q_full^T [E y]`` below the basis, without cancellation. Fast: only the
        triangular factor; ``Q^T y = R^-T (A^T y)``,
        ``S = ||y||^2 - ||Q^T y||^2``, ``E^T r = E^T y - (Q^T E)^T Q^T y`` and
        ``G = E^T E - (Q^T E)^T (Q^T E)``: the products ``A^T Y`` and ``E^T Y`` with the data instead
        of the reflectors applied to ``[E Y]`` (:func:`evaluation_flops` counts both), at the price of
        cancellation (relative error of S about eps cond(A) ||y||^2 / S); it falls back to the precise
        path when ``S < 1e-6 ||y||^2`` or a derivative column keeps less than 1e-6 of its square norm
        outside the basis; while the last evaluation shows that (:attr:`gram_fails`) a fast request
        is answered in the precise form at once (:meth:`prefers_gram`). When the basis is rank
        deficient (poles collapsed onto each other) ``rank_ok`` is False.
        """
        theta = np.array(theta, dtype=float)
        A, E = self.basis(theta)
        norms = np.sqrt(np.einsum("ij,ij->j", A, A))
        norms[norms == 0] = 1.0
        An = A / norms
        P = An.shape[1]
        # the reflectors cost no more than the triangle alone (the same factorisation): kept, a fast
        # evaluation that falls back to the precise one needs no second factorisation
        h, tau = np.linalg.qr(An, mode="raw")
        Rq = np.triu(h[:, :P].T)
        d = np.abs(np.diag(Rq))
        rcond = float(d.min() / d.max()) if d.size else 1.0
        rank_ok = bool(np.all(np.isfinite(Rq))) and rcond > RANK_TOL
        if not rank_ok:
            return Evaluation(theta, np.nan, None, False, rcond, precise=not fast)
        if fast and self.prefers_gram(theta.size // 2):
            # two products with the data (no copy of [A E] side by side: the same arithmetic)
            QtY = solve_upper(Rq, An.T @ self.Ys, transposed=True)
            S = self.y_norm2 - float(np.einsum("ij,ij->", QtY, QtY))
            if not self._gram_loses_digits(S, None, E):
                QtE = solve_upper(Rq, An.T @ E, transposed=True)
                G = E.T @ E - QtE.T @ QtE
                # a derivative column (nearly) inside the basis loses its digits to cancellation: precise then
                if not self._gram_loses_digits(S, G, E):
                    EtR = E.T @ self.Ys - QtE.T @ QtY
                    coef = solve_upper(Rq, QtY) / norms[:, None]
                    return Evaluation(theta, S, coef, True, rcond, precise=False, E=E, G=0.5 * (G + G.T), EtR=EtR)
        QtY, G, EtR, S = householder_project(h, tau, E, self.Ys)
        self.gram_fails = self._gram_loses_digits(S, G, E)
        coef = solve_upper(Rq, QtY) / norms[:, None]
        return Evaluation(theta, S, coef, True, rcond, precise=True, E=E, G=G, EtR=EtR)

    def normal_equations(self, ev: Evaluation) -> tuple[np.ndarray, np.ndarray]:
        """Kaufman's ``J^T J`` (2m x 2m) and gradient ``J^T r`` (2m,) at an evaluation.

        ``S = r^T r``, so ``dS/dtheta = 2 J^T r``.
        """
        if not ev.rank_ok:
            raise ValueError("normal equations need a full-rank evaluation")
        m = ev.theta.size // 2
        assert ev.coef is not None
        assert ev.G is not None and ev.EtR is not None
        JtJ, Gam = gram_from_G(ev.G, ev.coef[:2 * m])
        EtR = ev.EtR
        g = -np.einsum("rpif,rpf->ri", Gam, EtR.reshape(m, 2, -1)).reshape(2 * m)
        return JtJ, g

    # -------------------------------------------------------------- unpacking
    def linear_parameters(self, ev: Evaluation) -> tuple[np.ndarray, np.ndarray]:
        """Residues (n_frf, m) and residual terms (n_frf, n_res), complex, unweighted."""
        m = ev.theta.size // 2
        c = ev.coef
        assert c is not None, "linear parameters of a rank-deficient evaluation"
        if self.frf_w is not None:
            c = c / self.frf_w[None, :]
        R = (c[0:2 * m:2] + 1j * c[1:2 * m:2]).T
        T = (c[2 * m::2] + 1j * c[2 * m + 1::2]).T
        return R, T


def householder_project(h: np.ndarray, tau: np.ndarray, E: np.ndarray, Ys: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """``Q^T y``, ``G = (P E)^T (P E)``, ``E^T r`` and ``S = ||r||^2`` from a Householder QR of the basis.

    ``h, tau``: ``numpy.linalg.qr(A, mode="raw")`` of the (2N, P) basis; E : (2N, 2m) derivative
    columns; Ys : (2N, n_frf) data. The reflectors ``H_1 ... H_P = I - V T V^T`` (the compact WY
    form, ``T`` upper triangular) are applied to ``X = [E Ys]`` as two matrix products:
    ``C = Q_full^T X``; its first P rows are ``Q^T X`` and the rest ``C_b`` spans the orthogonal
    complement of the basis, so ``(P X)^T (P X) = C_b^T C_b`` (of which only the blocks ``G``, ``E^T r``
    and the trace of the data's block are formed). The explicit ``Q`` (whose forming
    costs more than the factorisation) and the projected residuals are never formed, and the
    rounding is that of Householder transformations (no cancellation).
    """
    P = tau.size
    m2 = E.shape[1]
    V1 = np.tril(h[:, :P].T, -1)          # the unit lower-triangular top of the reflectors
    V1[np.diag_indices(P)] = 1.0
    V2 = h.T[P:]                           # the rest (a view)
    VtV = V1.T @ V1 + V2.T @ V2
    # V^T X for X = [E Ys], E and the data one after the other (no copy of [E Ys] side by side)
    W = np.concatenate([V1.T @ E[:P] + V2.T @ E[P:], V1.T @ Ys[:P] + V2.T @ Ys[P:]], axis=1)
    if np.all(tau != 0):
        # T^-1 = strictly upper part of V^T V + diag(1 / tau) (the UT transform; tau_i = 2 / v_i^T v_i):
        # Z = T^T W by one triangular solve
        Tinv = np.triu(VtV, 1)
        Tinv[np.diag_indices(P)] = 1.0 / tau
        Z = solve_upper(Tinv, W, transposed=True)
    else:
        # a reflector that is the identity (tau = 0): LAPACK's forward, column-wise T (dlarft)
        T = np.zeros((P, P))
        for i in range(P):
            T[i, i] = tau[i]
            if i:
                T[:i, i] = -tau[i] * (T[:i, :i] @ VtV[:i, i])
        Z = T.T @ W
    # of the Gram matrix of the rows below the basis only the blocks needed: G, E^T r and S (not the
    # data's own n_frf x n_frf block)
    CbE = E[P:] - V2 @ Z[:, :m2]
    CbY = Ys[P:] - V2 @ Z[:, m2:]
    QtY = Ys[:P] - V1 @ Z[:, m2:]
    G = CbE.T @ CbE
    S = float(np.einsum("ij,ij->", CbY, CbY))
    return QtY, 0.5 * (G + G.T), CbE.T @ CbY, S


def projected_gram(Q: np.ndarray, E: np.ndarray, mode_coef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``sum_f Gamma_f^T (P E)^T (P E) Gamma_f`` (2m x 2m) and the ``Gamma`` array (m, 2, 2, n_frf).

    Q : (2N, P) orthonormal basis of A; E : (2N, 2m) derivative columns;
    mode_coef : (2m, n_frf) real coefficients ``(a_1, b_1, ..., a_m, b_m)`` (R = a + j b) per FRF.
    This is the Schur complement of the linear parameters in the Gauss-Newton matrix of the
    full problem, i.e. J^T J of the variable-projection (Kaufman) Jacobian.
    """
    PE = E - Q @ (Q.T @ E)
    return gram_from_G(PE.T @ PE, mode_coef)


def gram_from_G(G: np.ndarray, mode_coef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``sum_f Gamma_f^T G Gamma_f`` and ``Gamma`` from ``G = (P E)^T (P E)`` (see :func:`projected_gram`)."""
    m = G.shape[0] // 2
    G4 = G.reshape(m, 2, m, 2)
    a = mode_coef[0::2]                                     # (m, f)
    b = mode_coef[1::2]
    # Gam[r, p, i, f]: coefficient of E_(r,p) in d model_f / d theta_(r,i)
    Gam = np.empty((m, 2, 2, a.shape[1]))
    Gam[:, 0, 0] = a
    Gam[:, 1, 0] = b
    Gam[:, 0, 1] = -b
    Gam[:, 1, 1] = a
    # sum over the FRFs first (one matrix product), then the small contraction with G
    Gf = Gam.reshape(4 * m, -1)
    C = (Gf @ Gf.T).reshape(m, 2, 2, m, 2, 2)              # [r, p, i, s, q, j]
    # JtJ[r, i, s, j] = sum_pq G4[r, p, s, q] C[r, p, i, s, q, j], by broadcasting (an optimised einsum
    # spends more time choosing its order than computing)
    JtJ = (G4[:, :, None, :, :, None] * C).sum(axis=(1, 4)).reshape(2 * m, 2 * m)
    return 0.5 * (JtJ + JtJ.T), Gam


def solve_upper(R: np.ndarray, B: np.ndarray, transposed: bool = False) -> np.ndarray:
    """``R^-1 B`` (``R^-T B`` when ``transposed``) for an upper-triangular ``R`` (numpy only: the
    commands start without importing scipy). The transposed system is turned into an upper one by
    reversing the order of the unknowns, so the LU factorisation inside ``numpy.linalg.solve`` never
    pivots: the work and the rounding of a triangular solve."""
    if not transposed:
        return np.linalg.solve(R, B)
    return np.linalg.solve(R.T[::-1, ::-1], B[::-1])[::-1]


def solve_scaled(JtJ: np.ndarray, g: np.ndarray, D: np.ndarray, mu: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``(J^T J + mu D^2) d = -g`` through the scaled system.

    With ``M = D^-1 J^T J D^-1`` and ``x = D d``: ``(M + mu I) x = -D^-1 g``. Solved directly when
    positive definite (a Cholesky factorisation tells), least squares otherwise; NaN when no step can be computed (the
    iterations then reject it). Returns ``(d, x)``.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        M = JtJ / np.outer(D, D)
        rhs = -g / D
        Mm = M + mu * np.eye(M.shape[0])
    if not (np.all(np.isfinite(Mm)) and np.all(np.isfinite(rhs))):
        # no step can be computed (overflow, non-finite Jacobian): a NaN step, which the
        # iterations reject as "poles became non-finite" instead of raising
        x = np.full(rhs.shape, np.nan)
        return x, x
    try:
        np.linalg.cholesky(Mm)       # fails unless positive definite
        x = np.linalg.solve(Mm, rhs)  # one factorisation (numpy has no triangular solver)
    except (np.linalg.LinAlgError, ValueError):
        try:
            x = np.linalg.lstsq(Mm, rhs, rcond=None)[0]
        except np.linalg.LinAlgError:
            x = np.full(rhs.shape, np.nan)
    return x / D, x
