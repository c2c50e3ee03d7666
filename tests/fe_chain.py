"""An exactly solved spring-mass chain as a user's FE model on disk (Matrix Market K, M, a DOF map, a
TOML), and its "measured" FRFs by direct frequency-response solve (not the modal synthesis the diagnosis
fits): shared by tests/test_fe_model.py and tests/test_diagnosis_fe.py."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.io
import scipy.sparse as sp

from analysis.frf import FRFSet

K_SPRING = 1.0e6     # N/m, every spring
MASS = 1.0           # kg, every mass


def chain_matrices(n: int, k: float = K_SPRING, m: float = MASS) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """n equal masses m (kg) joined by n equal springs k (N/m), the first spring to ground."""
    main = np.full(n, 2 * k)
    main[-1] = k
    off = -k * np.ones(n - 1)
    return sp.diags([main, off, off], [0, 1, -1]).tocsr(), sp.identity(n, format="csr") * m


def chain_exact_hz(n: int, k: float = K_SPRING, m: float = MASS) -> np.ndarray:
    """w_j = 2 sqrt(k/m) sin((2j-1) pi / (2(2n+1))), in Hz, ascending."""
    j = np.arange(1, n + 1)
    return 2 * np.sqrt(k / m) * np.sin((2 * j - 1) * np.pi / (2 * (2 * n + 1))) / (2 * np.pi)


def write_chain(folder: Path, n: int, *, zeta: float = 0.01, groups: dict | None = None,
                K: sp.spmatrix | None = None, M: sp.spmatrix | None = None, symmetric: bool = True) -> Path:
    """The chain as a user's FE model in ``folder``: K.mtx, M.mtx, dofs.csv (DOF i is ``n:{i+1}:Z``, its
    group from ``groups`` {dof: name}) and model.toml; returns the TOML's path."""
    folder.mkdir(parents=True, exist_ok=True)
    K0, M0 = chain_matrices(n)
    K = K0 if K is None else K
    M = M0 if M is None else M
    kind = "symmetric" if symmetric else "general"
    scipy.io.mmwrite(str(folder / "K.mtx"), sp.coo_matrix(K), symmetry=kind)
    scipy.io.mmwrite(str(folder / "M.mtx"), sp.coo_matrix(M), symmetry=kind)
    head = "dof,point,group" if groups else "dof,point"
    rows = [f"{i},n:{i + 1}:Z" + (f",{groups.get(i, '')}" if groups else "") for i in range(n)]
    (folder / "dofs.csv").write_text("\n".join([head, *rows]) + "\n")
    toml = folder / "model.toml"
    toml.write_text('[fe]\nstiffness = "K.mtx"\nmass = "M.mtx"\ndofs = "dofs.csv"\n\n'
                    f"[damping]\nzeta_default = {zeta}\n")
    return toml


def direct_frfs(K: sp.spmatrix, M: sp.spmatrix, outputs: list[int], reference: int, freq_hz: np.ndarray,
                seed: int, noise: float = 0.003, eta: float = 0.02, dashpot: float = 2.0) -> FRFSet:
    """Accelerance ((m/s^2)/N) from ``reference`` to ``outputs`` (0-based DOFs of the chain, labelled
    ``n:{dof+1}:Z``) by solving ``(K (1 + j eta) - w^2 M + j w C) x = f`` at every line, with a damping
    unlike the diagnosis' modal one:
    damping: hysteretic ``K (1 + j eta)`` (loss factor ``eta``: ``eta / 2`` at each resonance) plus a
    dashpot of ``dashpot`` N s/m to ground at the first mass, plus complex noise of relative size ``noise``
    (seeded)."""
    Kd, Md = K.toarray(), M.toarray()
    C = np.zeros_like(Kd)
    C[0, 0] = dashpot
    w = 2 * np.pi * freq_hz
    H = np.empty((len(outputs), 1, w.size), complex)
    f = np.zeros(Kd.shape[0])
    f[reference] = 1.0
    for i, wi in enumerate(w):
        x = np.linalg.solve(Kd * (1 + 1j * eta) - wi ** 2 * Md + 1j * wi * C, f)
        H[:, 0, i] = -wi ** 2 * x[outputs]
    rng = np.random.default_rng(seed)
    H = H * (1 + noise * (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)) / np.sqrt(2))
    return FRFSet(freq_hz=freq_hz, H=H, quantity="accelerance", unit="(m/s^2)/N",
                  outputs=tuple(f"n:{o + 1}:Z" for o in outputs), references=(f"n:{reference + 1}:Z",))


def net_matrices(nx: int, ny: int, bracket: tuple[int, float] | None = None) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """A net of nx x ny nodes (0.05 kg each, X, Y, Z), neighbours joined by springs (Z 2e6 N/m, X and Y a hundred
    times stiffer), diagonal braces coupling X and Y, the edge nodes held to ground (5e6 N/m); node i (0-based)
    has DOFs 3i, 3i+1, 3i+2. ``bracket`` = (node, k): one more node of 0.05 kg hung on that node by springs of
    ``k`` N/m in X, Y and Z (a part on a flexible bracket)."""
    n_nodes = nx * ny + (bracket is not None)
    node = np.arange(nx * ny).reshape(ny, nx)
    rows: list = []
    cols: list = []
    vals: list = []

    def spring(a: np.ndarray, b: np.ndarray, i: int, j: int, k: float) -> None:
        ia, ib, ja, jb = 3 * a + i, 3 * b + i, 3 * a + j, 3 * b + j
        rows.extend([ia, ib, ia, ib])
        cols.extend([ja, jb, jb, ja])
        vals.extend([np.full(a.size, k), np.full(a.size, k), np.full(a.size, -k), np.full(a.size, -k)])

    for axis, k in ((0, 2.0e8), (1, 2.0e8), (2, 2.0e6)):
        spring(node[:, :-1].ravel(), node[:, 1:].ravel(), axis, axis, k)
        spring(node[:-1, :].ravel(), node[1:, :].ravel(), axis, axis, k)
    for i, j in ((0, 0), (1, 1), (0, 1), (1, 0)):
        spring(node[:-1, :-1].ravel(), node[1:, 1:].ravel(), i, j, 0.25e8)
    edge = np.unique(np.concatenate([node[0], node[-1], node[:, 0], node[:, -1]]))
    for axis in range(3):
        rows.append(3 * edge + axis)
        cols.append(3 * edge + axis)
        vals.append(np.full(edge.size, 5.0e6))
    if bracket is not None:
        for axis in range(3):
            spring(np.array([bracket[0]]), np.array([nx * ny]), axis, axis, bracket[1])
    n = 3 * n_nodes
    K = sp.coo_matrix((np.concatenate([np.asarray(v, float).ravel() for v in vals]),
                       (np.concatenate([np.asarray(r).ravel() for r in rows]),
                        np.concatenate([np.asarray(c).ravel() for c in cols]))), shape=(n, n)).tocsr()
    return K, sp.identity(n, format="csr") * 0.05


def write_net(folder: Path, nx: int, ny: int, bracket: tuple[int, float] | None = None) -> Path:
    """:func:`net_matrices` as a user's FE model in ``folder`` (node i is ``n:{i+1}``, X, Y and Z mapped)."""
    folder.mkdir(parents=True, exist_ok=True)
    K, M = net_matrices(nx, ny, bracket)
    scipy.io.mmwrite(str(folder / "K.mtx"), sp.coo_matrix(K), symmetry="symmetric")
    scipy.io.mmwrite(str(folder / "M.mtx"), sp.coo_matrix(M), symmetry="symmetric")
    rows = [f"{3 * i + a},n:{i + 1}:{'XYZ'[a]}" for i in range(K.shape[0] // 3) for a in range(3)]
    (folder / "dofs.csv").write_text("\n".join(["dof,point", *rows]) + "\n")
    toml = folder / "model.toml"
    toml.write_text('[fe]\nstiffness = "K.mtx"\nmass = "M.mtx"\ndofs = "dofs.csv"\n\n[damping]\nzeta_default = 0.01\n')
    return toml
