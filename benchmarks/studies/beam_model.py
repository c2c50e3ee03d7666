"""A free-free beam as a user's FE model: Matrix Market K and M, a DOF map and a simulation TOML.

    .venv/bin/python benchmarks/studies/beam_model.py OUT_DIR [--theory euler|rotary|shear|timoshenko] [--length-m 1.3]
        [--height-m 0.0366] [--width-m 0.03] [--elements 520] [--sensor-at-m 0.5 --sensor-kg 0]

Plane bending of a straight uniform beam of rectangular section (height ``h`` in the plane of bending,
width ``b``), free at both ends, two DOFs per node (the transverse displacement Z, m, and the rotation
RY, rad), equal elements. The element (``--theory``):

* ``euler``: Euler-Bernoulli, cubic Hermite interpolation, consistent mass of the translation only;
* ``rotary``: Euler-Bernoulli plus the section's rotary inertia (Rayleigh's beam), consistent;
* ``shear``: the Timoshenko element below with a negligible rotary inertia (shear deformation alone);
* ``timoshenko``: shear deformation and rotary inertia, linear interpolation of both fields with the
  shear strain taken at the element's middle (one-point rule, no shear locking), consistent mass of the
  translation (``rho A``) and of the rotation (``rho I``); shear coefficient ``kappa = 10 (1 + nu) /
  (12 + 11 nu)`` (rectangle), ``G = E / (2 (1 + nu))``.

Steel by default (E 210 GPa, rho 7850 kg/m^3, nu 0.3). The DOF map labels the Z DOF of the node at
position ``x`` (m, from one end) ``beam:{k}:Z`` for the points given with ``--points`` (default: the
ModeLAB beam's nine hammer positions 0.1 ... 1.2 m as points 1 ... 9), every other node's Z DOF
``beam:{1000 + i}:Z`` (node i from the first end: candidates of an added mass), and the rotations not at all. ``--sensor-kg`` puts a
lumped mass on the translation of the node at ``--sensor-at-m`` (the accelerometer) into M itself.

:func:`beam_matrices` is the library function (K in N/m, M in kg, sparse); :func:`write_beam` writes the
folder. Run as a script it writes ``K.mtx``, ``M.mtx``, ``dofs.csv`` and ``model.toml`` into OUT_DIR.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import scipy.io
import scipy.sparse as sp

#: The ModeLAB beam's hammer positions (m along the beam), points 1 ... 9; the accelerometer at 0.5 m (point 4).
MODELAB_POINTS_M = (0.1, 0.25, 0.375, 0.5, 0.65, 0.8, 0.925, 1.05, 1.2)
#: The elements: Euler-Bernoulli, + rotary inertia (Rayleigh), + shear deformation alone, both (Timoshenko).
THEORIES = ("euler", "rotary", "shear", "timoshenko")
STEEL = {"E": 210e9, "rho": 7850.0, "nu": 0.3}


def beam_matrices(length_m: float, height_m: float, width_m: float, n_el: int, theory: str = "euler",
                  E: float = STEEL["E"], rho: float = STEEL["rho"], nu: float = STEEL["nu"]
                  ) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """K (N/m, N m/rad) and M (kg, kg m^2) of the free-free beam, DOFs ``[w_0, theta_0, w_1, theta_1, ...]``."""
    if theory not in THEORIES:
        raise ValueError(f"theory {theory!r}: give one of {', '.join(THEORIES)}")
    A = width_m * height_m
    inertia = width_m * height_m ** 3 / 12.0
    le = length_m / n_el
    if theory in ("euler", "rotary"):
        k = E * inertia / le ** 3 * np.array([[12, 6 * le, -12, 6 * le], [6 * le, 4 * le ** 2, -6 * le, 2 * le ** 2],
                                               [-12, -6 * le, 12, -6 * le], [6 * le, 2 * le ** 2, -6 * le, 4 * le ** 2]])
        m = rho * A * le / 420.0 * np.array([[156, 22 * le, 54, -13 * le], [22 * le, 4 * le ** 2, 13 * le, -3 * le ** 2],
                                             [54, 13 * le, 156, -22 * le], [-13 * le, -3 * le ** 2, -22 * le, 4 * le ** 2]])
        if theory == "rotary":      # the section's rotary inertia (Rayleigh's beam): consistent, Hermite
            m = m + rho * inertia / (30.0 * le) * np.array(
                [[36, 3 * le, -36, 3 * le], [3 * le, 4 * le ** 2, -3 * le, -le ** 2],
                 [-36, -3 * le, 36, -3 * le], [3 * le, -le ** 2, -3 * le, 4 * le ** 2]])
    else:
        kappa = 10 * (1 + nu) / (12 + 11 * nu)
        G = E / (2 * (1 + nu))
        kb = E * inertia / le * np.array([[0, 0, 0, 0], [0, 1, 0, -1], [0, 0, 0, 0], [0, -1, 0, 1]], float)
        bs = np.array([-1 / le, -0.5, 1 / le, -0.5])          # gamma = w' - theta at the middle
        k = kb + kappa * G * A * le * np.outer(bs, bs)
        lin = le / 6.0 * np.array([[2, 1], [1, 2]])
        m = np.zeros((4, 4))
        m[np.ix_([0, 2], [0, 2])] = rho * A * lin
        if theory == "timoshenko":
            m[np.ix_([1, 3], [1, 3])] = rho * inertia * lin
        else:                       # "shear": shear deformation alone, a rotation without inertia
            m[np.ix_([1, 3], [1, 3])] = 1e-9 * rho * inertia * lin
    n = 2 * (n_el + 1)
    rows, cols, kv, mv = [], [], [], []
    for e in range(n_el):
        idx = np.arange(2 * e, 2 * e + 4)
        rows.append(np.repeat(idx, 4))
        cols.append(np.tile(idx, 4))
        kv.append(k.ravel())
        mv.append(m.ravel())
    r, c = np.concatenate(rows), np.concatenate(cols)
    K = sp.csr_matrix((np.concatenate(kv), (r, c)), shape=(n, n))
    M = sp.csr_matrix((np.concatenate(mv), (r, c)), shape=(n, n))
    return K, M


def node_at(x_m: float, length_m: float, n_el: int) -> int:
    """The node at ``x_m`` (m from the first end); raises ValueError when no node lies there."""
    i = x_m / (length_m / n_el)
    if abs(i - round(i)) > 1e-6 or not 0 <= round(i) <= n_el:
        raise ValueError(f"no node at {x_m} m: choose a number of elements that puts a node there")
    return int(round(i))


def write_beam(folder: Path, *, length_m: float = 1.3, height_m: float = 0.0366, width_m: float = 0.03,
               n_el: int = 520, theory: str = "euler", points_m: tuple = MODELAB_POINTS_M,
               sensor_at_m: float = 0.5, sensor_kg: float = 0.0, zeta: float = 1e-4,
               E: float = STEEL["E"], rho: float = STEEL["rho"], nu: float = STEEL["nu"]) -> Path:
    """The beam as a user's FE model in ``folder`` (module docstring); returns the TOML's path."""
    folder.mkdir(parents=True, exist_ok=True)
    K, M = beam_matrices(length_m, height_m, width_m, n_el, theory, E, rho, nu)
    if sensor_kg:
        d = np.zeros(K.shape[0])
        d[2 * node_at(sensor_at_m, length_m, n_el)] = sensor_kg
        M = sp.csr_matrix(M + sp.diags(d))
    scipy.io.mmwrite(str(folder / "K.mtx"), sp.coo_matrix(K), symmetry="symmetric")
    scipy.io.mmwrite(str(folder / "M.mtx"), sp.coo_matrix(M), symmetry="symmetric")
    named = {node_at(x, length_m, n_el): k for k, x in enumerate(points_m, start=1)}
    rows = [f"{2 * i},beam:{named[i]}:Z" if i in named else f"{2 * i},beam:{1000 + i}:Z" for i in range(n_el + 1)]
    (folder / "dofs.csv").write_text("dof,point\n" + "\n".join(rows) + "\n")
    toml = folder / "model.toml"
    toml.write_text('[fe]\nstiffness = "K.mtx"\nmass = "M.mtx"\ndofs = "dofs.csv"\n\n'
                    f"[damping]\nzeta_default = {zeta}\n")
    return toml


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--theory", choices=THEORIES, default="euler")
    ap.add_argument("--length-m", type=float, default=1.3)
    ap.add_argument("--height-m", type=float, default=0.0366)
    ap.add_argument("--width-m", type=float, default=0.03)
    ap.add_argument("--elements", type=int, default=520)
    ap.add_argument("--sensor-at-m", type=float, default=0.5)
    ap.add_argument("--sensor-kg", type=float, default=0.0)
    a = ap.parse_args()
    toml = write_beam(a.out, length_m=a.length_m, height_m=a.height_m, width_m=a.width_m, n_el=a.elements,
                      theory=a.theory, sensor_at_m=a.sensor_at_m, sensor_kg=a.sensor_kg)
    print(f"wrote {toml} ({2 * (a.elements + 1)} DOF, {a.theory})")


if __name__ == "__main__":
    main()
