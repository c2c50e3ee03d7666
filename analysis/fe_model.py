"""The user's own finite-element model as the simulation: reading it, its modes, and its physical causes.

A simulation TOML with an ``[fe]`` table names the model's files (paths relative to the TOML)::

    [fe]
    stiffness = "K.mtx"      # Matrix Market, symmetric, sparse (N/m, N m/rad)
    mass = "M.mtx"           # Matrix Market, symmetric positive definite (kg, kg m^2)
    dofs = "dofs.csv"        # columns dof,point[,group]: 0-based DOF, its label component:node:direction
    [damping]
    zeta_default = 0.01      # or Rayleigh: alpha = ... (1/s), beta = ... (s)
    [sensors]                # optional: the accelerometers' mass (kg) at each measured output's node
    mass_kg = 0.0
    [modes]                  # optional: modes of the simulated FRFs up to this (Hz; default twice the band's top)
    max_freq_hz = 2000.0

:func:`load_fe_model` reads and checks it (:class:`FEModel`; bad input raises
:class:`analysis.errors.FEModelError` naming the file and row). :func:`sparse_modes` solves
``K phi = w^2 M phi`` by shift-invert Lanczos (``scipy.sparse.linalg.eigsh``, the shift below the
lowest mode), asking for more modes until one lies past the top asked for, so 10^4-10^5 DOF work.

:class:`FEVariants` answers the protocol of :class:`analysis.diagnosis.physical.PhysicalSimulation`
(``causes``, ``modes``, ``model``, ``modes_of``, ``model_of``, ``exact_modes_of``): the causes that make
sense on any FE model, the rows of :data:`FE_CAUSES`:

=====================  ===================================  ==============================================
name                   parameters                           change
=====================  ===================================  ==============================================
``added_mass``         ``point`` (node), ``mass_kg``        a lumped mass on every mapped DOF of the node
``ground_spring``      ``point`` (node), ``stiffness_n_m``  a spring to ground on every mapped DOF of the node
``stiffness_shift``    ``stiffness_factor`` (``factor`` =   K x stiffness_factor (the whole model)
                       its square root)
``mass_scale``         ``factor``                           M x factor (the whole model)
``group_stiffness``    ``group``, ``factor``                the couplings between the group's DOFs x factor
``group_mass``         ``group``, ``factor``                M's entries between the group's DOFs x factor
``mass_loading``       ``mass_kg``                          the sensors' mass at every measured output node
=====================  ===================================  ==============================================

A node is the label without its direction (``n:8`` of ``n:8:Z``). Damping is not a physical cause here:
the diagnosis' FRF-level catalogue fits it (``damping_change``) on top of the model's ``[damping]``.

Candidates are solved in a Rayleigh-Ritz space (the unchanged model's modes up to ``RITZ_FACTOR`` times
the top asked for, plus the static response to the changed DOFs with ``KRYLOV_BLOCKS - 1`` inertia
corrections, or the group's first-order correction):
a few small dense eigenproblems instead of a sparse one per candidate. :meth:`FEVariants.exact_modes_of`
solves the full sparse model (the diagnosis checks each chosen fit with it). :meth:`FEVariants.first_pass`
bounds the mode count of every node with a mass or a spring from both sides at once (the kept modes and each
node's residual flexibility, no sparse solve per node), so a search over every node is exact and cheap.
"""
from __future__ import annotations

import csv
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import tomllib

from .diagnosis.physical import CauseSpec, ParamSpec
from .errors import FEModelError, PointLabelError
from .modal import ModalModel, pole_from_fz
from .points import parse_point

__all__ = ["FEModel", "FEVariants", "FE_CAUSES", "FECause", "load_fe_model", "is_fe_config", "sparse_modes",
           "DENSE_MAX_DOF", "RITZ_FACTOR", "MODEL_MASS", "MODEL_STIFFNESS", "SENSOR_MASS"]

log = logging.getLogger(__name__)

#: Models up to this many DOF are solved densely (``scipy.linalg.eigh``); larger ones by shift-invert Lanczos.
DENSE_MAX_DOF = 300
#: The Ritz space holds the unchanged model's modes up to this multiple of the highest frequency asked.
RITZ_FACTOR = 2.0
#: Blocks of the static response to a changed node's DOFs in the Ritz space: the response and its inertia
#: corrections ``((K0 - sigma M0)^-1 M0)^j (K0 - sigma M0)^-1 E``, j < KRYLOV_BLOCKS.
KRYLOV_BLOCKS = 3
#: The shift of the Lanczos solver: ``sigma = -(SHIFT_FRACTION * 2 pi f_top)^2``, below every mode (rigid ones too).
SHIFT_FRACTION = 0.05
#: Relative asymmetry tolerated in a matrix (of its largest entry): rounding of an exporter.
SYMMETRY_RTOL = 1e-9
#: Modes with ``w^2`` below this fraction of the top asked for are rigid-body modes (not compared).
RIGID_W2_FRACTION = 1e-8


def _w2(freq_hz: float) -> float:
    return float((2 * np.pi * freq_hz) ** 2)


# --------------------------------------------------------------------------- reading
@dataclass(frozen=True)
class FEModel:
    """A user's FE model: ``K`` (N/m), ``M`` (kg) as CSR matrices of ``n`` DOF; ``dofs``: point label
    (``component:node:direction`` as in the map) -> DOF; ``groups``: group name -> DOFs; damping as a
    constant ratio ``zeta_default`` or Rayleigh ``alpha`` (1/s), ``beta`` (s); ``sensor_mass_kg`` at each
    measured output's node; ``max_freq_hz`` (None: twice the band's top); ``source`` the TOML."""

    K: sp.csr_matrix
    M: sp.csr_matrix
    dofs: dict
    groups: dict = field(default_factory=dict)
    zeta_default: float | None = 0.01
    alpha: float = 0.0
    beta: float = 0.0
    sensor_mass_kg: float = 0.0
    max_freq_hz: float | None = None
    source: str = "the FE model"
    dofs_file: str = "the DOF map"

    @property
    def n_dof(self) -> int:
        return int(self.K.shape[0])

    def damping_ratios(self, freq_hz: np.ndarray) -> np.ndarray:
        """Modal damping ratios at the natural frequencies ``freq_hz`` (Hz): the constant ratio, or Rayleigh
        ``alpha / (2 w) + beta w / 2``."""
        f = np.asarray(freq_hz, float)
        if self.zeta_default is not None:
            return np.full(f.shape, float(self.zeta_default))
        w = 2 * np.pi * np.maximum(f, 1e-12)
        return self.alpha / (2 * w) + self.beta * w / 2

    def nodes(self) -> tuple[str, ...]:
        """Every node of the map (``component:node``), in the map's order."""
        return tuple(self.node_map())

    def node_map(self) -> dict[str, np.ndarray]:
        """Node (``component:node``) -> the DOFs of its every mapped direction, in the map's order."""
        out: dict[str, list[int]] = {}
        for lbl, d in self.dofs.items():
            out.setdefault(_node(lbl), []).append(int(d))
        return {n: np.array(v, int) for n, v in out.items()}

    def dof_of(self, point: str) -> tuple[int, int]:
        """(DOF, sign) of a measured point ``component:node:direction``: the map's DOF in that axis, the sign
        +1 when the point and the map's label point the same way. Raises :class:`FEModelError`."""
        p = parse_point(point)
        for sign in (1, -1):
            key = f"{p.component}:{p.node}:{'-' if p.sign * sign < 0 else ''}{p.direction.lstrip('-')}"
            if key in self.dofs:
                return int(self.dofs[key]), sign
        raise FEModelError(f"{self.dofs_file}: no row for the measured point {point} (in either sense); add the "
                           "DOF of that point to the map, or measure at a mapped point")

    def total_mass_kg(self) -> float:
        """The model's mass (kg): the rigid translation's ``u^T M u`` in the axis of most mapped mass."""
        best = 0.0
        axes = {lbl: parse_point(lbl).direction.lstrip("-") for lbl in self.dofs}
        for axis in "XYZ":
            idx = np.array([d for lbl, d in self.dofs.items() if axes[lbl] == axis], int)
            if idx.size:
                best = max(best, float(self.M[idx][:, idx].sum()))
        return best


def _node(label: str) -> str:
    p = parse_point(label)
    return f"{p.component}:{p.node}"


def is_fe_config(path: str | Path) -> bool:
    """Is ``path`` a TOML with an ``[fe]`` table (the user's FE model)? False for anything else (a frame
    configuration, an FRF file, an unreadable file: its own loader reports that)."""
    p = Path(path)
    if p.suffix.lower() != ".toml":
        return False
    try:
        with open(p, "rb") as fh:
            return isinstance(tomllib.load(fh).get("fe"), dict)
    except (OSError, tomllib.TOMLDecodeError):
        return False


def load_fe_model(path: str | Path) -> FEModel:
    """Read and check the FE model of the TOML ``path`` (module docstring). Raises :class:`FEModelError`
    (one line: the file, the row, what to do) for a missing or unreadable file, non-square, non-symmetric
    or mismatched matrices, a mass matrix that is not positive definite, a DOF map that does not match."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except OSError as exc:
        raise FEModelError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise FEModelError(f"{path}: not valid TOML ({exc})") from None
    fe = doc.get("fe")
    if not isinstance(fe, dict):
        raise FEModelError(f"{path}: no [fe] table; give stiffness, mass and dofs files in [fe]")
    files = {}
    for key in ("stiffness", "mass", "dofs"):
        if not isinstance(fe.get(key), str):
            raise FEModelError(f"{path}: [fe] {key} is missing; give the file name (e.g. {key} = \"{key}.mtx\")")
        files[key] = path.parent / fe[key]
    K = _read_matrix(files["stiffness"], "stiffness")
    M = _read_matrix(files["mass"], "mass")
    if K.shape != M.shape:
        raise FEModelError(f"{files['mass']}: {M.shape[0]} x {M.shape[1]} but the stiffness {files['stiffness']} "
                           f"is {K.shape[0]} x {K.shape[1]}; give both matrices over the same DOFs")
    _check_positive_definite(M, files["mass"])
    dofs, groups = _read_dofs(files["dofs"], K.shape[0])
    damping = doc.get("damping")
    if not isinstance(damping, dict):
        raise FEModelError(f"{path}: no [damping] table; give zeta_default, or Rayleigh alpha and beta")
    zeta, alpha, beta = _damping(damping, path)
    sensors = doc.get("sensors", {})
    modes = doc.get("modes", {})
    sensor_mass = _number(sensors.get("mass_kg", 0.0), path, "[sensors] mass_kg", minimum=0.0)
    fmax = modes.get("max_freq_hz")
    return FEModel(K=K, M=M, dofs=dofs, groups=groups, zeta_default=zeta, alpha=alpha, beta=beta,
                   sensor_mass_kg=sensor_mass,
                   max_freq_hz=None if fmax is None else _number(fmax, path, "[modes] max_freq_hz", minimum=1e-12),
                   source=str(path), dofs_file=str(files["dofs"]))


def _number(v: Any, path: Path, what: str, minimum: float) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < minimum:
        raise FEModelError(f"{path}: {what} = {v!r}; give a number >= {minimum:g}")
    return float(v)


def _damping(table: dict, path: Path) -> tuple[float | None, float, float]:
    rayleigh = "alpha" in table or "beta" in table
    if "zeta_default" in table and rayleigh:
        raise FEModelError(f"{path}: [damping] has both zeta_default and Rayleigh alpha/beta; give one of them")
    if "zeta_default" in table:
        z = _number(table["zeta_default"], path, "[damping] zeta_default", minimum=0.0)
        if z >= 1:
            raise FEModelError(f"{path}: [damping] zeta_default = {z}; give a ratio below 1 (0.01 is 1 %)")
        return z, 0.0, 0.0
    if rayleigh:
        a = _number(table.get("alpha", 0.0), path, "[damping] alpha", minimum=0.0)
        b = _number(table.get("beta", 0.0), path, "[damping] beta", minimum=0.0)
        if a == 0 and b == 0:
            raise FEModelError(f"{path}: [damping] alpha and beta are both 0; give a damping")
        return None, a, b
    raise FEModelError(f"{path}: [damping] is empty; give zeta_default, or Rayleigh alpha and beta")


def _read_matrix(path: Path, what: str) -> sp.csr_matrix:
    """A square, symmetric, finite sparse matrix from a Matrix Market file."""
    import scipy.io

    try:
        A = scipy.io.mmread(str(path))
    except OSError as exc:
        raise FEModelError(f"{path}: cannot read the {what} matrix ({exc.strerror or exc})") from None
    except (ValueError, IndexError, TypeError) as exc:
        raise FEModelError(f"{path}: not a Matrix Market file ({exc}); export the {what} matrix in Matrix Market "
                           "coordinate format") from None
    A = sp.csr_matrix(A, dtype=float)
    if A.shape[0] != A.shape[1]:
        raise FEModelError(f"{path}: the {what} matrix is {A.shape[0]} x {A.shape[1]}; it must be square")
    if not np.all(np.isfinite(A.data)):
        row = int(np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))[np.flatnonzero(~np.isfinite(A.data))[0]])
        raise FEModelError(f"{path}: row {row + 1} holds NaN or inf; export the {what} matrix again")
    D = (A - A.T).tocoo()
    scale = float(np.max(np.abs(A.data), initial=0.0))
    bad = np.flatnonzero(np.abs(D.data) > SYMMETRY_RTOL * scale)
    if bad.size:
        i, j = int(D.row[bad[0]]), int(D.col[bad[0]])
        raise FEModelError(f"{path}: the {what} matrix is not symmetric: row {i + 1}, column {j + 1} holds "
                           f"{A[i, j]:.6g} but row {j + 1}, column {i + 1} holds {A[j, i]:.6g} (1-based, as in the "
                           "file); export the symmetric matrix")
    A.eliminate_zeros()
    return A


def _check_positive_definite(M: sp.csr_matrix, path: Path) -> None:
    """Raise :class:`FEModelError` naming the first row where M is not positive definite: a diagonal entry
    <= 0, else the first non-positive pivot of its symmetric factorisation (``M = L D L^T``)."""
    d = M.diagonal()
    bad = np.flatnonzero(~(d > 0))
    if bad.size:
        raise FEModelError(f"{path}: the mass matrix is not positive definite: row {bad[0] + 1} has diagonal "
                           f"{d[bad[0]]:.6g} (1-based); give every DOF a mass or inertia, or condense massless "
                           "DOFs out")
    try:
        lu = spla.splu(M.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
        piv = lu.U.diagonal()
        order = lu.perm_c
    except RuntimeError:
        raise FEModelError(f"{path}: the mass matrix is singular; it must be positive definite") from None
    neg = np.flatnonzero(~(piv > 0))
    if neg.size:
        row = int(order[neg[0]])
        raise FEModelError(f"{path}: the mass matrix is not positive definite (its factorisation fails at row "
                           f"{row + 1}, 1-based); check the exported mass matrix")


def _read_dofs(path: Path, n: int) -> tuple[dict, dict]:
    """The DOF map ``dof,point[,group]``: label -> DOF and group -> DOFs, checked against ``n`` DOF."""
    try:
        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise FEModelError(f"{path}: cannot read the DOF map ({exc.strerror or exc})") from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise FEModelError(f"{path}: not a CSV text file ({exc})") from None
    if not rows:
        raise FEModelError(f"{path}: empty; give a header dof,point[,group] and one row per measured DOF")
    head = [h.strip().lower() for h in rows[0]]
    if head[:2] != ["dof", "point"] or (len(head) > 2 and head[2:] != ["group"]):
        raise FEModelError(f"{path}: row 1 is {','.join(rows[0])!r}; the header must be dof,point or dof,point,group")
    dofs: dict[str, int] = {}
    seen: dict[int, int] = {}
    groups: dict[str, list[int]] = {}
    for i, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) < 2 or len(row) > len(head):
            raise FEModelError(f"{path}: row {i} has {len(row)} columns; the header has {len(head)}")
        try:
            dof = int(row[0])
        except ValueError:
            raise FEModelError(f"{path}: row {i}: dof {row[0]!r} is not an integer") from None
        if not 0 <= dof < n:
            raise FEModelError(f"{path}: row {i}: dof {dof} is outside the matrices' {n} DOFs (0-based: 0 to "
                               f"{n - 1}); the map does not match the matrices")
        try:
            p = parse_point(row[1])
        except PointLabelError as exc:
            raise FEModelError(f"{path}: row {i}: {exc}") from None
        label = str(p)
        if dof in seen:
            raise FEModelError(f"{path}: row {i}: dof {dof} is mapped already on row {seen[dof]}")
        twin = f"{p.component}:{p.node}:{'' if p.sign < 0 else '-'}{p.direction.lstrip('-')}"
        if label in dofs or twin in dofs:
            raise FEModelError(f"{path}: row {i}: point {label} is mapped already (dof {dofs.get(label, dofs.get(twin))})")
        dofs[label] = dof
        seen[dof] = i
        if len(row) > 2 and row[2].strip():
            groups.setdefault(row[2].strip(), []).append(dof)
    if len(seen) > n:
        raise FEModelError(f"{path}: {len(seen)} DOFs mapped but the matrices have {n}")
    if not dofs:
        raise FEModelError(f"{path}: no DOF rows; give one row per measurable DOF")
    return dofs, {g: np.array(sorted(v), int) for g, v in groups.items()}


# --------------------------------------------------------------------------- modes
def _shift_solver(K: sp.spmatrix, M: sp.spmatrix, sigma: float) -> Callable[[np.ndarray], np.ndarray]:
    """``x -> (K - sigma M)^-1 x`` (``x`` a vector or the columns of a matrix) by one sparse LU factorisation."""
    A = (K - sigma * M).tocsc()
    try:
        # K - sigma M is symmetric positive definite (sigma below every mode): a symmetric fill-reducing
        # ordering and no pivoting keep the factors about a third smaller than the general LU's (faster solves)
        lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        return lu.solve
    except RuntimeError as exc:
        raise FEModelError(f"the shifted stiffness K - sigma M is singular ({exc}); the model has a mode below "
                           f"{np.sqrt(max(-sigma, 0.0)) / (2 * np.pi):.3g} Hz or a negative stiffness") from None


def _count_below(K: sp.spmatrix, M: sp.spmatrix, w2: float) -> int:
    """The number of modes below ``w2`` (rad^2/s^2) by Sylvester's law of inertia: the negative pivots of a
    symmetric factorisation of ``K - w2 M`` (no pivoting, so a guess where a pivot is tiny: the solver's first
    ask, which it checks); 0 when the factorisation fails."""
    try:
        lu = spla.splu(sp.csc_matrix(K - w2 * M), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
    except RuntimeError:
        return 0
    return int(np.sum(lu.U.diagonal() < 0))


def sparse_modes(K: sp.spmatrix, M: sp.spmatrix, max_freq_hz: float, *, sparse: bool | None = None,
                 solve: Callable[[np.ndarray], np.ndarray] | None = None, sigma: float | None = None,
                 expect: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Natural frequencies (Hz, ascending, rigid-body modes included) up to ``max_freq_hz`` and the
    mass-normalised mode shapes (n_dof, n_modes) of ``K phi = w^2 M phi``.

    Models above ``DENSE_MAX_DOF`` DOF (or with ``sparse``) by shift-invert Lanczos:
    ``scipy.sparse.linalg.eigsh`` with ``sigma = -(SHIFT_FRACTION 2 pi max_freq_hz)^2`` (below every mode,
    so ``K - sigma M`` is positive definite even for a free model; ``solve`` is its inverse when the caller
    holds one), asking for twice as many modes until one lies past ``max_freq_hz`` (first for ``expect``
    modes and a few more: a count known from a similar model)."""
    n = int(K.shape[0])
    w2max = _w2(max_freq_hz)
    if n < 3 or not (sparse if sparse is not None else n > DENSE_MAX_DOF):
        w2, phi = scipy.linalg.eigh(_dense(K), _dense(M), subset_by_value=(-np.inf, w2max))
        return np.sqrt(np.maximum(w2, 0.0)) / (2 * np.pi), phi
    if sigma is None:
        sigma = -SHIFT_FRACTION ** 2 * w2max
    if solve is None:
        solve = _shift_solver(K, M, sigma)
    op = spla.LinearOperator((n, n), matvec=solve, dtype=float)
    k = min(n - 1, max(12, expect + 4))
    while True:
        w2, phi = spla.eigsh(K, k=k, M=M, sigma=sigma, OPinv=op, which="LM", tol=1e-12,
                             v0=np.ones(n) / np.sqrt(n))
        order = np.argsort(w2)
        w2, phi = w2[order], phi[:, order]
        if w2[-1] > w2max:
            break
        if k >= n - 1:          # Lanczos gives at most n - 1 modes: every mode of a small model, densely
            return sparse_modes(K, M, max_freq_hz, sparse=False)
        k = min(n - 1, 2 * k)
    keep = w2 <= w2max
    return np.sqrt(np.maximum(w2[keep], 0.0)) / (2 * np.pi), phi[:, keep]


def _dense(A: Any) -> np.ndarray:
    """A dense float copy of a sparse or dense matrix."""
    return np.asarray(A.toarray() if sp.issparse(A) else A, float)


# --------------------------------------------------------------------------- causes
@dataclass
class Change:
    """A candidate's change of the model: whole-model factors, group factors, lumped masses and springs to
    ground at nodes (kg, N/m on each mapped DOF of the node), the sensors' mass (None: the model's)."""

    k_factor: float = 1.0
    m_factor: float = 1.0
    k_groups: dict = field(default_factory=dict)
    m_groups: dict = field(default_factory=dict)
    masses: dict = field(default_factory=dict)
    springs: dict = field(default_factory=dict)
    sensor_mass_kg: float | None = None

    def key(self) -> tuple:
        """A hashable summary of the change (equal changes, equal keys)."""
        return (self.k_factor, self.m_factor, tuple(sorted(self.k_groups.items())),
                tuple(sorted(self.m_groups.items())), tuple(sorted(self.masses.items())),
                tuple(sorted(self.springs.items())), self.sensor_mass_kg)


@dataclass(frozen=True)
class FECause:
    """One row of :data:`FE_CAUSES`: the cause as the diagnosis sees it (its parameters' ranges are scaled
    to the model by ``spec_for``) and the function that applies its parameters to a :class:`Change`."""

    spec: CauseSpec
    apply: Callable[[Change, Mapping], None]
    #: what its first parameter's range is a multiple of (:meth:`FEVariants.causes`): :data:`MODEL_MASS` (kg),
    #: :data:`MODEL_STIFFNESS` (N/m); "": the range as it is
    scale: str = ""
    #: the model's own value its first parameter takes as its nominal (the unchanged model), the range's top at
    #: least twice it: :data:`SENSOR_MASS` (``[sensors] mass_kg``); "": the row's nominal
    nominal: str = ""


#: :attr:`FECause.scale`: the model's total mass (kg, the mapped translations)
MODEL_MASS = "model_mass"
#: :attr:`FECause.scale`: the median diagonal stiffness of the mapped DOFs (N/m)
MODEL_STIFFNESS = "model_stiffness"
#: :attr:`FECause.nominal`: the sensors' mass at each measured output's node (kg, ``[sensors] mass_kg``)
SENSOR_MASS = "sensor_mass_kg"


def _added_mass(c: Change, p: Mapping) -> None:
    node = str(p["point"])
    c.masses[node] = c.masses.get(node, 0.0) + float(p["mass_kg"])


def _ground_spring(c: Change, p: Mapping) -> None:
    node = str(p["point"])
    c.springs[node] = c.springs.get(node, 0.0) + float(p["stiffness_n_m"])


def _stiffness_shift(c: Change, p: Mapping) -> None:
    c.k_factor *= float(p.get("stiffness_factor", 1.0))


def _mass_scale(c: Change, p: Mapping) -> None:
    c.m_factor *= float(p["factor"])


def _group_stiffness(c: Change, p: Mapping) -> None:
    g = str(p["group"])
    c.k_groups[g] = c.k_groups.get(g, 1.0) * float(p["factor"])


def _group_mass(c: Change, p: Mapping) -> None:
    g = str(p["group"])
    c.m_groups[g] = c.m_groups.get(g, 1.0) * float(p["factor"])


def _mass_loading(c: Change, p: Mapping) -> None:
    c.sensor_mass_kg = float(p["mass_kg"])


#: The causes offered on any FE model (ranges of masses relative to the model's mass, of springs to the
#: median diagonal stiffness; :meth:`FEVariants.causes` scales them). Adding a cause: one row.
FE_CAUSES: dict[str, FECause] = {row.spec.name: row for row in (
    FECause(CauseSpec("added_mass", (ParamSpec("mass_kg", 1e-3, 1.0, nominal=0.0, unit="kg", monotone=True),), choice="point",
                      description="a lumped mass at one node (every mapped direction)",
                      advice="A mass the model lacks sits at the named node (a fixture, a block, cabling): add it "
                             "to the model as a lumped mass there, or remove it from the structure."), _added_mass,
            scale=MODEL_MASS),
    FECause(CauseSpec("ground_spring", (ParamSpec("stiffness_n_m", 1e-4, 1e2, nominal=0.0, unit="N/m", monotone=True),),
                      choice="point",
                      description="a spring to ground at one node (a support or contact the model lacks)",
                      advice="The structure is held at the named node (a support, a contact, a cable): model the "
                             "support there with the fitted stiffness, or free the structure."), _ground_spring,
            scale=MODEL_STIFFNESS),
    FECause(CauseSpec("stiffness_shift", (ParamSpec("stiffness_factor", 0.6, 1.6, monotone=True),),
                      description="the whole stiffness matrix scaled (Young's modulus, every section)",
                      advice="Every part is stiffer or softer by the same factor: update Young's modulus (or the "
                             "sections) by the fitted stiffness factor."), _stiffness_shift),
    FECause(CauseSpec("mass_scale", (ParamSpec("factor", 0.6, 1.6, monotone=True),),
                      description="the whole mass matrix scaled (density, every section)",
                      advice="Every part is heavier or lighter by the same factor: update the density by the "
                             "fitted factor (a uniform mass and a uniform stiffness change move the frequencies "
                             "alike; the FRFs' level tells them apart)."), _mass_scale),
    FECause(CauseSpec("group_stiffness", (ParamSpec("factor", 0.3, 3.0, monotone=True),), choice="group",
                      description="the stiffness between one group's DOFs scaled",
                      advice="One group of the model is stiffer or softer than modelled: check its section, "
                             "material and connections, or update its stiffness by the fitted factor."),
            _group_stiffness),
    FECause(CauseSpec("group_mass", (ParamSpec("factor", 0.3, 3.0, monotone=True),), choice="group",
                      description="the mass between one group's DOFs scaled",
                      advice="One group of the model is heavier or lighter than modelled: check its density and "
                             "attached masses, or update its mass by the fitted factor."), _group_mass),
    FECause(CauseSpec("mass_loading", (ParamSpec("mass_kg", 0.0, 0.1, nominal=None, unit="kg", log=False, monotone=True),),
                      description="the sensors' mass at every measured output's node",
                      advice="The accelerometers' mass lowers the frequencies: add the sensors' mass at their "
                             "nodes to the model ([sensors] mass_kg), or use lighter sensors."), _mass_loading,
            scale=MODEL_MASS, nominal=SENSOR_MASS),
)}


#: Ritz spaces (and nodes' static responses) kept at once: each holds a few vectors of the model's size.
KEPT_SPACES = 32
#: Full-model solutions kept at once (:meth:`FEVariants._exact`): each holds its modes at every DOF.
KEPT_EXACT = 4


#: An extra Ritz vector keeping less than this fraction of its M0-norm squared (1e-8 of the norm) outside the kept
#: modes is dropped.
SPAN_RTOL = 1e-16
#: Rounding allowed in a node's residual flexibility (of its trace): :meth:`FEVariants.first_pass` lowers it by
#: this for its upper bounds and raises it for its lower bounds.
FLEX_RTOL = 1e-9
#: Nodes of one block of :meth:`FEVariants.first_pass` (bounds the arrays: ~ nodes x frequencies x values).
FIRST_PASS_CHUNK = 128
#: A mode count above every model's (:meth:`FEVariants.first_pass` where nothing is known).
BEYOND_COUNT = 1 << 30
#: Models up to this many DOF have ``(K0 - sigma M0)^-1`` inverted densely for the residual flexibility.
DENSE_INVERSE_MAX_DOF = 2000
#: The banded selected inversion is used while ``n * bandwidth^2`` (after reverse Cuthill-McKee) stays below this;
#: above it each node's columns are solved with the sparse factorisation (slower, the same answer).
BAND_WORK_MAX = 4e9


def _eig3(a00: np.ndarray, a11: np.ndarray, a22: np.ndarray, a01: np.ndarray, a02: np.ndarray,
          a12: np.ndarray) -> np.ndarray:
    """Eigenvalues (3, ...) of the symmetric 3 x 3 matrices with these entries (arrays of one shape), by the
    trigonometric solution of the characteristic cubic (vectorised; rounding ~1e-8 of the matrix's norm)."""
    q = (a00 + a11 + a22) / 3.0
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p1 = a01 ** 2 + a02 ** 2 + a12 ** 2
    p = np.sqrt((b00 ** 2 + b11 ** 2 + b22 ** 2 + 2.0 * p1) / 6.0)
    safe = np.where(p > 0, p, 1.0)
    det = (b00 * (b11 * b22 - a12 ** 2) - a01 * (a01 * b22 - a12 * a02) + a02 * (a01 * a12 - b11 * a02))
    r = np.clip(det / (2.0 * safe ** 3), -1.0, 1.0)
    t = np.arccos(r) / 3.0
    e1 = q + 2.0 * p * np.cos(t)
    e3 = q + 2.0 * p * np.cos(t + 2.0 * np.pi / 3.0)
    return np.stack([e3, 3.0 * q - e1 - e3, e1])


def _inverse_blocks(A: sp.spmatrix, dofs: np.ndarray, solve: Callable[[np.ndarray], np.ndarray] | None
                    ) -> np.ndarray:
    """The blocks ``A^-1[d, d]`` (o, 3, 3) of a symmetric positive definite ``A`` at the DOF rows ``dofs``
    (o, 3; -1 pads, its row and column zero). Small models: the dense inverse. Else the selected inversion of
    the banded Cholesky factor after a reverse Cuthill-McKee ordering (:func:`_banded_inverse`). Too wide a
    band (``n b^2 > BAND_WORK_MAX``) or no ``solve``: the nodes' columns solved (by ``solve``, else a sparse LU)."""
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    n = int(A.shape[0])
    pad = dofs < 0
    if n <= DENSE_INVERSE_MAX_DOF:
        Zd = np.linalg.inv(_dense(A))
        idx = np.maximum(dofs, 0)
        return np.where(pad[:, :, None] | pad[:, None, :], 0.0, Zd[idx[:, :, None], idx[:, None, :]])
    A = sp.csr_matrix(A)
    perm = reverse_cuthill_mckee(A, symmetric_mode=True)
    Ap = sp.csr_matrix(A[perm][:, perm]).tocoo()
    b = int(np.max(np.abs(Ap.row - Ap.col), initial=0))
    if n * float(b) ** 2 > BAND_WORK_MAX or solve is None:
        return _solved_blocks(A, dofs, solve)
    return _banded_inverse(A, Ap, perm, b, dofs)


def _solved_blocks(A: sp.csr_matrix, dofs: np.ndarray, solve: Callable[[np.ndarray], np.ndarray] | None
                   ) -> np.ndarray:
    """:func:`_inverse_blocks` by solving ``A x = e_d`` for every DOF ``d`` of ``dofs`` (64 columns at once)."""
    n = int(A.shape[0])
    pad = dofs < 0
    flat = np.unique(dofs[~pad])
    if solve is None:
        solve = spla.splu(A.tocsc()).solve
    where = {int(d): k for k, d in enumerate(flat)}
    Zc = np.zeros((n, flat.size))
    for lo in range(0, flat.size, 64):
        part = flat[lo:lo + 64]
        E = np.zeros((n, part.size))
        E[part, np.arange(part.size)] = 1.0
        Zc[:, lo:lo + part.size] = np.asarray(solve(np.asfortranarray(E)))
    out = np.zeros((dofs.shape[0], 3, 3))
    for i, a, c in np.argwhere(~pad[:, :, None] & ~pad[:, None, :]):
        out[i, a, c] = Zc[dofs[i, c], where[int(dofs[i, a])]]
    return 0.5 * (out + out.transpose(0, 2, 1))


def _banded_inverse(A: sp.csr_matrix, Ap: sp.coo_matrix, perm: np.ndarray, b: int, dofs: np.ndarray) -> np.ndarray:
    """:func:`_inverse_blocks` by the banded Cholesky factor ``Ap = C C^T`` of ``Ap = A[perm][:, perm]`` (half-
    bandwidth ``b``), by blocks of ``s = b`` rows (``C`` is block-bidiagonal; ``Z = A^-1`` on the diagonal blocks
    and the next, from the last block: ``Z_(k+1)k = -Z_(k+1)(k+1) C_(k+1)k C_kk^-1``, ``Z_kk = C_kk^-T C_kk^-1 -
    C_kk^-T C_(k+1)k^T Z_(k+1)k``, ~n b^2 flops). Two DOFs of one node in different connected parts of ``A`` have
    ``Z = 0``; two further apart than a block (never for coupled DOFs) are bounded in the Loewner order (the
    node's block by three times its diagonal, as a positive semi-definite 3 x 3 is)."""
    from scipy.sparse.csgraph import connected_components

    n = int(A.shape[0])
    o = dofs.shape[0]
    pad = dofs < 0
    pos = np.empty(n, int)
    pos[perm] = np.arange(n)
    _, part_of = connected_components(A, directed=False)
    ab = np.zeros((b + 1, n))                           # the lower band: ab[i, j] = Ap[j + i, j]
    low = Ap.row >= Ap.col
    ab[Ap.row[low] - Ap.col[low], Ap.col[low]] = Ap.data[low]
    cb = scipy.linalg.cholesky_banded(ab, lower=True)
    rows = np.arange(b + 1)[:, None] + np.arange(n)[None, :]
    inside = rows < n
    C = sp.csr_matrix((cb[inside], (rows[inside], np.broadcast_to(np.arange(n), rows.shape)[inside])), shape=(n, n))
    s = max(b, 1)
    want = set()                                        # (p, q) permuted, p < q: the nodes' off-diagonal entries
    loose = np.zeros(o, bool)
    for i, a, c in np.argwhere(~pad[:, :, None] & ~pad[:, None, :]):
        if a < c and part_of[dofs[i, a]] == part_of[dofs[i, c]]:      # else Z = 0 between unconnected parts
            p, q = sorted((int(pos[dofs[i, a]]), int(pos[dofs[i, c]])))
            if q // s - p // s > 1:
                loose[i] = True
            else:
                want.add((p, q))
    by_block: dict[int, list[tuple[int, int]]] = {}
    for p, q in want:
        by_block.setdefault(p // s, []).append((p, q))
    diag = np.zeros(n)
    near: dict[tuple[int, int], float] = {}
    Znext: np.ndarray | None = None
    for lo in range((n - 1) // s * s, -1, -s):
        hi = min(lo + s, n)
        X = scipy.linalg.solve_triangular(C[lo:hi, lo:hi].toarray(), np.eye(hi - lo), lower=True)
        Zkk = X.T @ X
        if Znext is not None:
            B = C[hi:hi + s, lo:hi].toarray()
            Zlow = -(Znext @ B) @ X                    # Z[hi:hi+s, lo:hi]
            Zkk = Zkk - X.T @ (B.T @ Zlow)
            near.update({(p, q): float(Zlow[q - hi, p - lo]) for p, q in by_block.get(lo // s, ()) if q >= hi})
        near.update({(p, q): float(Zkk[p - lo, q - lo]) for p, q in by_block.get(lo // s, ()) if q < hi})
        diag[lo:hi] = np.diag(Zkk)
        Znext = Zkk
    out = np.zeros((o, 3, 3))
    for i, a, c in np.argwhere(~pad[:, :, None] & ~pad[:, None, :]):
        p, q = sorted((int(pos[dofs[i, a]]), int(pos[dofs[i, c]])))
        out[i, a, c] = diag[p] if a == c else near.get((p, q), 0.0)
    out[loose] = 3.0 * np.einsum("oaa,ab->oab", out[loose], np.eye(3))
    return out


def _keep(store: dict, key: Any, value: Any) -> None:
    """``store[key] = value``, the oldest entry dropped beyond ``KEPT_SPACES``."""
    while len(store) >= KEPT_SPACES:
        store.pop(next(iter(store)))
    store[key] = value


def _one(cause: str | None, params: Mapping) -> list[tuple[str, Mapping]]:
    return [] if cause is None else [(cause, params)]


def _block(A: sp.csr_matrix, dofs: np.ndarray) -> sp.csr_matrix:
    """The entries of ``A`` whose row and column both lie in ``dofs`` (the rest zero), n x n: a group's mass."""
    mask = np.zeros(A.shape[0])
    mask[dofs] = 1.0
    D = sp.diags(mask)
    return sp.csr_matrix(D @ A @ D)


def _couplings(K: sp.csr_matrix, dofs: np.ndarray) -> sp.csr_matrix:
    """A group's stiffness: the couplings ``K_ij`` between two of its DOFs (i != j) with the diagonal
    ``-sum_j K_ij`` over them, so that the group moved rigidly stores no energy in it (n x n). For a spring
    network these are exactly the springs joining two members; springs to outside DOFs and to ground stay."""
    off = _block(K, dofs)
    off = sp.csr_matrix(off - sp.diags(off.diagonal()))
    return sp.csr_matrix(off - sp.diags(np.asarray(off.sum(axis=1)).ravel()))


@dataclass
class _Space:
    """A Ritz space: the basis ``V = [phi, X]`` (the kept modes and the extra vectors, M0-orthonormal), its
    rows at the measured DOFs (signed: outputs then references), the projections of K0 and of the changed
    groups."""

    phi: np.ndarray
    X: np.ndarray
    at: np.ndarray
    K0: np.ndarray
    parts_k: dict
    parts_m: dict

    def rows(self, dofs: np.ndarray) -> np.ndarray:
        """The basis' rows at ``dofs`` (len(dofs), size)."""
        return np.hstack([self.phi[dofs], self.X[dofs]])


class FEVariants:
    """The FE model ``fe`` at the measured ``outputs`` / ``references``, changed by the causes of
    :data:`FE_CAUSES`: the protocol of :class:`analysis.diagnosis.physical.PhysicalSimulation`.
    ``max_freq_hz``: the simulated FRFs' modes reach this (Hz; default the model's ``[modes] max_freq_hz``).
    Raises :class:`FEModelError` when a measured point is not in the map."""

    def __init__(self, fe: FEModel, outputs: Sequence[str], references: Sequence[str],
                 max_freq_hz: float | None = None) -> None:
        self.fe = fe
        self.outputs = tuple(map(str, outputs))
        self.references = tuple(map(str, references))
        self._out = [fe.dof_of(p) for p in self.outputs]
        self._ref = [fe.dof_of(p) for p in self.references]
        fmax = max_freq_hz if max_freq_hz is not None else fe.max_freq_hz
        if fmax is None:
            raise FEModelError(f"{fe.source}: give [modes] max_freq_hz (the simulated FRFs' modes reach it)")
        self.max_freq_hz = float(fmax)
        self._node_dofs = fe.node_map()
        self.nodes = tuple(self._node_dofs)
        self.sensor_nodes = tuple(dict.fromkeys(_node(p) for p in self.outputs))
        self._m_total = fe.total_mass_kg()
        diag = fe.K.diagonal()[sorted(fe.dofs.values())]
        self._k_ref = float(np.median(diag[diag > 0])) if np.any(diag > 0) else 1.0
        self._groups_k = {g: _couplings(fe.K, d) for g, d in fe.groups.items()}
        self._groups_m = {g: _block(fe.M, d) for g, d in fe.groups.items()}
        self.M0 = sp.csr_matrix(fe.M + self._lumped(self.sensor_nodes, fe.sensor_mass_kg))
        self.K0 = fe.K.tocsr()
        self._nominal: tuple[np.ndarray, np.ndarray] | None = None     # (w2, Phi) up to _nominal_top
        self._nominal_top = 0.0
        self._sigma = 0.0
        self._solve: Callable[[np.ndarray], np.ndarray] | None = None
        self._static: dict[str, np.ndarray] = {}
        self._flex: dict[str, np.ndarray] = {}       # node -> residual flexibility R(sigma) (first_pass)
        self._spaces: dict[tuple, _Space] = {}
        self._memo: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
        self._expect: dict[float, int] = {}          # modes below a top found last time (the solver's first ask)
        self._exact_kept: dict[tuple, tuple[float, np.ndarray, np.ndarray]] = {}   # change -> (top, f, phi)

    # ------------------------------------------------------------------ protocol of the diagnosis
    def causes(self) -> tuple[CauseSpec, ...]:
        """The causes with the model's nodes and groups as choices and ranges scaled to the model: masses
        by its total mass, springs by the median diagonal stiffness of the mapped DOFs."""
        scales = {MODEL_MASS: self._m_total, MODEL_STIFFNESS: self._k_ref}
        nominals = {SENSOR_MASS: self.fe.sensor_mass_kg}
        out = []
        for row in FE_CAUSES.values():
            c = row.spec
            if c.choice == "group":
                if not self.fe.groups:
                    continue
                c = replace(c, options=tuple(self.fe.groups))
            elif c.choice == "point":
                c = replace(c, options=self.nodes)
            s = c.params[0]
            if row.scale:
                s = replace(s, lo=s.lo * scales[row.scale], hi=s.hi * scales[row.scale])
            if row.nominal:
                known = nominals[row.nominal]
                s = replace(s, nominal=known, hi=max(s.hi, 2 * known))
            out.append(replace(c, params=(s, *c.params[1:])))
        return tuple(out)

    def modes(self, cause: str | None, params: Mapping, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """Natural frequencies (Hz, flexible modes up to ``max_freq_hz``) and the shape products
        ``phi_o phi_r`` (n_out * n_ref, n_modes) at the measured points (C order over (o, r))."""
        return self.modes_of(_one(cause, params), max_freq_hz)

    def modes_of(self, changes: Sequence[tuple[str, Mapping]], max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`modes` changed by every ``(cause, params)`` at once, in the Ritz space of the changed parts
        (module docstring); answers are kept."""
        key = (tuple((c, tuple(sorted(p.items()))) for c, p in changes), float(max_freq_hz))
        hit = self._memo.get(key)
        if hit is not None:
            return hit
        out = self._modes_reduced(self._change(changes), max_freq_hz)
        for a in out:
            a.setflags(write=False)
        if len(self._memo) >= 20000:
            self._memo.clear()
        self._memo[key] = out
        return out

    def first_pass(self, cause: str, options: Sequence[str], values: np.ndarray, freq_hz: np.ndarray,
                   max_freq_hz: float) -> tuple[np.ndarray, np.ndarray] | None:
        """Bounds of the mode count of every node of ``options`` changed by ``cause`` (``added_mass``: kg,
        ``ground_spring``: N/m) at each of ``values``, for the first pass of a search over many nodes:
        ``(at_least, at_most)``, integer arrays (options, values, freqs) with

            at_least <= #{modes below f} <= #{modes at or below f} <= at_most

        for every ``f`` of ``freq_hz`` (Hz), the modes those of the full model changed so *and* of its Ritz
        solution (:meth:`modes`), rigid ones included. No sparse solve per node: a few small products per
        node and frequency. Other causes: None (no first pass).

        The mathematics (``E`` the node's mapped DOFs, r <= 3 columns; ``Phi``, ``Lambda`` the kept modes,
        M0-normalised, every mode of ``(K0, M0)`` up to ``c = (2 pi RITZ_FACTOR max_freq_hz)^2`` rad^2/s^2;
        a node's rows ``Psi = E^T Phi`` in 1/sqrt(kg)):

        1. Counting. For a pencil ``(K, M)`` of poles ``lambda_i`` (the unchanged eigenvalues), an added mass
           ``m EE^T`` (kg) and ``lambda > 0`` not a pole, Haynsworth's inertia formula on
           ``[[K - lambda M, E], [E^T, I/(lambda m)]]`` gives the number of changed eigenvalues below
           ``lambda``: ``N(lambda) = #{lambda_i < lambda} + #{eigenvalues of G(lambda) above 1/(lambda m)}``,
           ``G(lambda) = E^T (K - lambda M)^-1 E = sum_i psi_i psi_i^T / (lambda_i - lambda)`` (m/N, r x r).
           A spring ``k EE^T`` (N/m): ``N = #{lambda_i < lambda} + #{eigenvalues of G above -1/k} - r``.
           Both counts grow with ``G`` in the Loewner order.
        2. Upper bounds of the eigenvalues (``at_least``): the Rayleigh-Ritz solution in the kept modes and
           the residual static response ``x_r = sum_discarded phi_i psi_i^T / (lambda_i - sigma)`` (the part of
           ``(K0 - sigma M0)^-1 E`` outside the kept modes), whose projections are ``x_r^T (K0 - sigma M0) x_r =
           R(sigma)`` (below) and ``x_r^T M0 x_r = S >= 0`` (unknown), with ``sigma < 0``. The projected pencil's
           stiffness ``R + sigma S`` falls and its mass grows as ``S`` grows, so its eigenvalues are at most
           those at ``S = 0``: the kept modes with the static correction, massless, whose ``G`` is
           ``G_S = G_U + R(sigma)``, ``G_U = sum over the kept modes`` (the counting above holds for it: its
           stiffness is positive definite where its mass is singular). Its eigenvalues bound the Ritz solution in
           ``[Phi, x_r]`` from above, which bounds the full model's (Poincare) and that of any space holding
           ``[Phi, x_r]`` (:meth:`modes`: Cauchy interlacing) from above; its count is a lower bound of theirs.
        3. Lower bounds (``at_most``): the full model's ``G = G_U + R(lambda)``, ``R`` the discarded modes'
           part (``lambda_i >= c``). For ``sigma <= lambda < c`` and ``lambda_i >= c``,
           ``1 / (lambda_i - lambda) <= (c - sigma) / ((lambda_i - sigma)(c - lambda))`` (cross-multiplied:
           ``lambda_i (lambda - sigma) >= c (lambda - sigma)``), so ``R(lambda) <= R(sigma) (c - sigma) /
           (c - lambda)`` with the residual flexibility ``R(sigma) = E^T (K0 - sigma M0)^-1 E - sum_kept
           psi_i psi_i^T / (lambda_i - sigma)`` (m/N, computed once per node: :func:`_inverse_blocks`).
           ``G_L = G_U + R(sigma) (c - sigma) / (c - lambda) >= G`` counts at least the full model's
           eigenvalues below ``lambda``, and the full model's are lower bounds of the Ritz solution's. Above
           ``c`` nothing is known: ``at_most`` is then a count no model reaches.

        In the band (``lambda << c``) the two differ by ``R lambda / c``: the bounds are tight. Rounding:
        ``R(sigma)`` is lowered (upper bounds) or raised (lower bounds) by ``FLEX_RTOL`` of its trace; the
        caller widens its windows."""
        if cause not in ("added_mass", "ground_spring"):
            return None
        self._ensure_nominal(max_freq_hz)
        assert self._nominal is not None
        w2, phi = self._nominal
        c = _w2(self._nominal_top)
        sigma = self._sigma
        vals = np.asarray(values, float)
        if np.any(np.diff(vals) <= 0):
            raise ValueError("first_pass: give the values in ascending order")
        lam = _w2(1.0) * np.asarray(freq_hz, float) ** 2
        n_opt, n_val, n_q = len(options), vals.size, lam.size
        at_least = np.zeros((n_opt, n_val, n_q), np.int32)
        at_most = np.zeros((n_opt, n_val, n_q), np.int32)
        poles = np.searchsorted(w2, lam, side="left")                # kept eigenvalues below each lambda
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / (w2[:, None] - lam[None, :])                  # (n_kept, Q), s^2
            tail = (c - sigma) / (c - lam)                            # the residual's factor
        finite = np.isfinite(inv).all(axis=0)          # lambda on a pole: nothing known there
        valid = finite & (lam < c)
        spring = cause == "ground_spring"
        every = self._padded_dofs(options)                                  # (options, 3), -1: none
        flex = self._residual_flexibility(list(options), every, phi)        # (options, 3, 3)
        for lo in range(0, n_opt, FIRST_PASS_CHUNK):
            nodes = list(options[lo:lo + FIRST_PASS_CHUNK])
            dofs = every[lo:lo + len(nodes)]
            Psi = np.where(dofs[:, :, None] >= 0, phi[np.maximum(dofs, 0)], 0.0)     # (o, 3, n_kept)
            R = flex[lo:lo + len(nodes)]
            pairs = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]
            prod = np.stack([Psi[:, a] * Psi[:, b] for a, b in pairs], axis=1)       # (o, 6, n_kept)
            GU = (prod.reshape(-1, w2.size) @ np.nan_to_num(inv)).reshape(len(nodes), 6, n_q)
            Rp = np.stack([R[:, a, b] for a, b in pairs], axis=1)                    # (o, 6)
            slack = np.zeros((len(nodes), 6))
            slack[:, :3] = (FLEX_RTOL * np.einsum("oaa->o", R))[:, None] * (dofs >= 0)
            GS = GU + (Rp - slack)[:, :, None]                           # the static correction: upper bounds
            GL = GU + (Rp + slack)[:, :, None] * np.where(valid, tail, 0.0)[None, None, :]
            o_idx = np.arange(len(nodes))[None, :, None]
            q_idx = np.arange(n_q)[None, None, :]
            for G, out, side in ((GS, at_least, -1), (GL, at_most, 1)):
                e = _eig3(*(G[:, i] for i in range(6)))                # (3, o, Q), m/N
                with np.errstate(divide="ignore", invalid="ignore"):
                    if spring:  # #{e > -1/k} - 3 = -#{k >= -1/e, e < 0}: the values from the first at or past -1/e
                        first = np.where(e < 0, np.searchsorted(vals, (-1.0 / e).ravel(), "left").reshape(e.shape),
                                         n_val)
                    else:       # #{e > 1/(lambda m)} = #{m > 1/(e lambda), e > 0}
                        t = 1.0 / (e * lam[None, None, :])
                        first = np.where((e > 0) & (lam > 0)[None, None, :],
                                         np.searchsorted(vals, t.ravel(), "right").reshape(e.shape), n_val)
                # how many of the three eigenvalues count at each value: a cumulative histogram over the values
                flat = ((o_idx * (n_val + 1) + first) * n_q + q_idx).ravel()
                hist = np.bincount(flat, minlength=len(nodes) * (n_val + 1) * n_q).reshape(len(nodes), n_val + 1, n_q)
                above = np.cumsum(hist, axis=1)[:, :n_val, :]
                n = poles[None, None, :] + (-above if spring else above)
                ok: np.ndarray = np.asarray(valid if side > 0 else finite, bool)
                out[lo:lo + len(nodes)] = np.where(ok[None, None, :], n, BEYOND_COUNT if side > 0 else 0)
        return at_least, at_most

    def _padded_dofs(self, nodes: Sequence[str]) -> np.ndarray:
        """The mapped DOFs of each node (rows), padded with -1 to three."""
        out = np.full((len(nodes), 3), -1, int)
        for i, node in enumerate(nodes):
            d = self._node_dofs[node]
            if d.size > 3:
                raise FEModelError(f"node {node!r} of {self.fe.dofs_file} maps {d.size} directions; a node has at "
                                   "most three (X, Y, Z)")
            out[i, :d.size] = d
        return out

    def _residual_flexibility(self, nodes: Sequence[str], dofs: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """``R(sigma) = E^T (K0 - sigma M0)^-1 E - sum_kept psi psi^T / (lambda_i - sigma)`` (m/N) of each node
        (padded 3 x 3, zero where a node has fewer DOFs; ``dofs`` its rows, ``phi`` the kept modes); kept."""
        idx = [i for i, n in enumerate(nodes) if n not in self._flex]
        if idx:
            Z = _inverse_blocks(self.K0 - self._sigma * self.M0, dofs[idx], self._solve)
            assert self._nominal is not None
            w2 = self._nominal[0]
            d = dofs[idx]
            P = np.where(d[:, :, None] >= 0, phi[np.maximum(d, 0)], 0.0)
            kept = np.einsum("oai,obi,i->oab", P, P, 1.0 / (w2 - self._sigma))
            R = Z - kept
            for i, r in zip(idx, R):
                self._flex[nodes[i]] = r
        return np.array([self._flex[n] for n in nodes]).reshape(len(nodes), 3, 3)

    def exact_modes_of(self, changes: Sequence[tuple[str, Mapping]], max_freq_hz: float
                       ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`modes_of` on the full sparse model (no reduction)."""
        f, phi = self._exact(self._change(changes), max_freq_hz)
        return f, self._products(phi)

    def model(self, cause: str | None, params: Mapping) -> ModalModel:
        """Receptance pole-residue model (m/N) of the changed model, modes up to :attr:`max_freq_hz`, damping
        from ``[damping]``, ``meta["output_shapes"]`` (mass-normalised, 1/sqrt(kg)) at the outputs."""
        return self.model_of(_one(cause, params))

    def model_of(self, changes: Sequence[tuple[str, Mapping]]) -> ModalModel:
        """:meth:`model` changed by every ``(cause, params)`` of ``changes`` at once."""
        f, phi = self._exact(self._change(changes), self.max_freq_hz)
        lam = pole_from_fz(f, self.fe.damping_ratios(f))
        po, pr = self._shapes_at(phi)
        R = np.einsum("om,rm->orm", po, pr) / (2j * np.imag(lam))[None, None, :]
        return ModalModel(poles=lam, residues=R, quantity="receptance", residual_form="none",
                          outputs=self.outputs, references=self.references,
                          meta={"source": self.fe.source, "cause": "+".join(c for c, _ in changes) or None,
                                "parameters": dict(changes[0][1]) if len(changes) == 1 else
                                [{"effect": c, "parameters": dict(p)} for c, p in changes],
                                "output_shapes": po, "reference_shapes": pr})

    # ------------------------------------------------------------------ assembly
    def _change(self, changes: Sequence[tuple[str, Mapping]]) -> Change:
        c = Change()
        for name, params in changes:
            if name not in FE_CAUSES:
                raise FEModelError(f"unknown cause {name!r} of an FE model; the causes are {', '.join(FE_CAUSES)}")
            FE_CAUSES[name].apply(c, params)
        for node in (*c.masses, *c.springs):
            if node not in self._node_dofs:
                raise FEModelError(f"node {node!r} is not in {self.fe.dofs_file}")
        for g in (*c.k_groups, *c.m_groups):
            if g not in self.fe.groups:
                raise FEModelError(f"group {g!r} is not in {self.fe.dofs_file}; its groups are {', '.join(self.fe.groups)}")
        for node, m in c.masses.items():
            if m < 0:
                raise FEModelError(f"a mass of {m} kg at {node}: masses must be >= 0")
        return c

    def _lumped(self, nodes: Sequence[str], kg: float) -> sp.csr_matrix:
        n = self.fe.n_dof
        d = np.zeros(n)
        for node in nodes:
            d[self._node_dofs[node]] += kg
        return sp.csr_matrix(sp.diags(d))

    def matrices_of(self, changes: Sequence[tuple[str, Mapping]]) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """K (N/m) and M (kg) of the model changed by ``changes`` (sparse)."""
        return self._matrices(self._change(changes))

    def _matrices(self, c: Change) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        K = self.K0 * c.k_factor
        M = self.M0 * c.m_factor
        for g, a in c.k_groups.items():
            K = K + (a - 1.0) * c.k_factor * self._groups_k[g]
        for g, b in c.m_groups.items():
            M = M + (b - 1.0) * c.m_factor * self._groups_m[g]
        n = self.fe.n_dof
        dk, dm = np.zeros(n), np.zeros(n)
        for node, k in c.springs.items():
            dk[self._node_dofs[node]] += k
        for node, m in c.masses.items():
            dm[self._node_dofs[node]] += m
        if c.sensor_mass_kg is not None:
            for node in self.sensor_nodes:
                dm[self._node_dofs[node]] += c.sensor_mass_kg - self.fe.sensor_mass_kg
        return sp.csr_matrix(K + sp.diags(dk)), sp.csr_matrix(M + sp.diags(dm))

    def _exact(self, c: Change, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """Modes of the full sparse model changed by ``c`` up to ``max_freq_hz`` (Hz; rigid ones dropped). A
        solution up to a higher top is kept per change and cut (the same change checked and then simulated
        costs one sparse solution); the unchanged model's are the kept modes of the Ritz space when those reach."""
        key = c.key()
        got = self._exact_kept.get(key)
        if got is None and key == Change().key() and self._nominal is not None \
                and self._nominal_top >= max_freq_hz:
            w2, phi = self._nominal
            got = (self._nominal_top, np.sqrt(np.maximum(w2, 0.0)) / (2 * np.pi), phi)
        if got is None or got[0] < max_freq_hz:
            # to the simulated FRFs' top as well: the change checked and then simulated is one solution
            top = max(float(max_freq_hz), self.max_freq_hz)
            K, M = self._matrices(c)
            f, phi = sparse_modes(K, M, top, expect=self._expect.get(top, self._nominal_count(top)))
            self._expect[top] = f.size
            got = (top, f, phi)
            while len(self._exact_kept) >= KEPT_EXACT:
                self._exact_kept.pop(next(iter(self._exact_kept)))
            self._exact_kept[key] = got
        _, f, phi = got
        keep = (_w2(1.0) * f ** 2 > RIGID_W2_FRACTION * _w2(max_freq_hz)) & (f <= max_freq_hz)
        return f[keep], phi[:, keep]

    def _nominal_count(self, top: float) -> int:
        """The solver's first ask for a changed model's modes up to ``top`` (Hz): the unchanged model's count there
        and three more (a change at one node moves at most three modes across), 0 when unknown."""
        if self._nominal is None or top > self._nominal_top:
            return 0
        return int(np.sum(self._nominal[0] <= _w2(top))) + 3

    # ------------------------------------------------------------------ reduced solution
    def _ensure_nominal(self, max_freq_hz: float) -> None:
        """The unchanged model's modes up to ``RITZ_FACTOR`` times ``max_freq_hz`` (kept; solved again when
        a higher top is asked for) and the shifted factorisation for static responses."""
        top = RITZ_FACTOR * max_freq_hz
        if self._nominal is not None and top <= self._nominal_top:
            return
        sigma = -SHIFT_FRACTION ** 2 * _w2(top)
        self._solve = _shift_solver(self.K0, self.M0, sigma) if self.fe.n_dof > DENSE_MAX_DOF else None
        self._sigma = sigma
        expect = _count_below(self.K0, self.M0, _w2(top)) if self._solve is not None else 0
        f, phi = sparse_modes(self.K0, self.M0, top, solve=self._solve, sigma=sigma, expect=expect)
        self._nominal = (_w2(1.0) * f ** 2, phi)
        self._nominal_top = top
        self._static.clear()
        self._flex.clear()
        self._spaces.clear()

    def _shifted_solve(self, B: np.ndarray) -> np.ndarray:
        """``(K0 - sigma M0)^-1 B`` for the columns of ``B``."""
        if self._solve is None:
            A = _dense(self.K0) - self._sigma * _dense(self.M0)
            return np.asarray(scipy.linalg.solve(A, B, assume_a="pos"))
        return np.asarray(self._solve(np.asfortranarray(B, dtype=float)))

    def _space_key(self, c: Change) -> tuple[tuple, tuple]:
        """The Ritz space's key for the changed parts of ``c``: (changed nodes, changed groups)."""
        nodes = sorted(set(c.masses) | set(c.springs)
                       | (set(self.sensor_nodes) if c.sensor_mass_kg is not None else set()))
        groups = sorted(set(("k", g) for g in c.k_groups) | set(("m", g) for g in c.m_groups))
        return tuple(nodes), tuple(groups)

    def _extra_vectors(self, key: tuple[tuple, tuple]) -> list[np.ndarray]:
        """The extra vectors of the Ritz space ``key``: the static response to unit loads on the changed
        nodes' DOFs (with its inertia corrections), and the first-order correction of the kept modes for a
        changed group (``(K0 - sigma M0)^-1 K_g Phi``)."""
        nodes, groups = key
        vecs = []
        for node in nodes:
            if node not in self._static:
                d = self._node_dofs[node]
                E = np.zeros((self.fe.n_dof, d.size))
                E[d, np.arange(d.size)] = 1.0
                # and its inertia corrections: the next Krylov blocks (K0 - sigma M0)^-1 M0 X
                blocks = [self._shifted_solve(E)]
                for _ in range(KRYLOV_BLOCKS - 1):
                    blocks.append(self._shifted_solve(np.asarray(self.M0 @ blocks[-1])))
                _keep(self._static, node, np.column_stack(blocks))
            vecs.append(self._static[node])
        assert self._nominal is not None
        phi = self._nominal[1]
        for kind, g in groups:
            A = self._groups_k[g] if kind == "k" else self._groups_m[g]
            vecs.append(self._shifted_solve(np.asarray(A @ phi)))
        return vecs

    def _space(self, c: Change) -> _Space:
        key = self._space_key(c)
        if key in self._spaces:
            return self._spaces[key]
        vecs = self._extra_vectors(key)
        assert self._nominal is not None
        w2, phi = self._nominal
        X = np.zeros((phi.shape[0], 0))
        if vecs:
            X = np.column_stack(vecs)
            before = np.einsum("ij,ij->j", X, np.asarray(self.M0 @ X))
            X = X - phi @ (phi.T @ (self.M0 @ X))                # M0-orthogonal to the kept modes
            after = np.einsum("ij,ij->j", X, np.asarray(self.M0 @ X))
            # a vector (nearly) inside the kept modes' span leaves rounding only: dropped (it would add spurious modes)
            keep = after > SPAN_RTOL * before
            X = X[:, keep] / np.sqrt(after[keep])
            G = X.T @ (self.M0 @ X)
            s, U = np.linalg.eigh(0.5 * (G + G.T))
            ok = s > 1e-12 * max(float(s.max(initial=0.0)), 1e-300)
            X = X @ (U[:, ok] / np.sqrt(s[ok]))
            X = X - phi @ (phi.T @ (self.M0 @ X))
        # V = [phi, X]: the kept modes diagonalise K0 and the extra vectors are M0-orthogonal to them, so
        # K0 phi = M0 phi Lambda and the cross terms vanish: only the extra vectors' block is projected
        m = phi.shape[1]
        size = m + X.shape[1]
        K0r = np.zeros((size, size))
        K0r[np.arange(m), np.arange(m)] = w2
        if X.shape[1]:
            K0r[m:, m:] = X.T @ (self.K0 @ X)
        space = _Space(phi=phi, X=X, at=np.zeros((0, size)), K0=0.5 * (K0r + K0r.T), parts_k={}, parts_m={})
        space.at = np.array([sign * space.rows(np.atleast_1d(d))
                             for d, sign in self._out + self._ref]).reshape(-1, size)
        if key[1]:
            V = np.column_stack([phi, X])
            space.parts_k = {g: V.T @ (A @ V) for g, A in self._groups_k.items() if ("k", g) in key[1]}
            space.parts_m = {g: V.T @ (A @ V) for g, A in self._groups_m.items() if ("m", g) in key[1]}
        _keep(self._spaces, key, space)
        return space

    def _modes_reduced(self, c: Change, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        self._ensure_nominal(max_freq_hz)
        space = self._space(c)
        m = space.K0.shape[0]
        Kr = c.k_factor * space.K0
        Mr = c.m_factor * np.eye(m)
        for g, a in c.k_groups.items():
            Kr = Kr + (a - 1.0) * c.k_factor * space.parts_k[g]
        for g, b in c.m_groups.items():
            Mr = Mr + (b - 1.0) * c.m_factor * space.parts_m[g]
        for node, k in c.springs.items():
            rows = space.rows(self._node_dofs[node])
            Kr = Kr + k * (rows.T @ rows)
        added = dict(c.masses)
        if c.sensor_mass_kg is not None:
            for node in self.sensor_nodes:
                added[node] = added.get(node, 0.0) + c.sensor_mass_kg - self.fe.sensor_mass_kg
        for node, mass in added.items():
            rows = space.rows(self._node_dofs[node])
            Mr = Mr + mass * (rows.T @ rows)
        w2max = _w2(max_freq_hz)
        w2, Y = scipy.linalg.eigh(Kr, Mr, subset_by_value=(RIGID_W2_FRACTION * w2max, w2max))
        rows = space.at @ Y
        n_out = len(self._out)
        f = np.sqrt(w2) / (2 * np.pi)
        return f, (rows[:n_out, None, :] * rows[None, n_out:, :]).reshape(n_out * len(self._ref), -1)

    # ------------------------------------------------------------------ shapes at the measured points
    def _shapes_at(self, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed mode-shape values at the outputs (n_out, n_modes) and references (n_ref, n_modes)."""
        return (np.array([s * phi[d] for d, s in self._out]).reshape(len(self._out), -1),
                np.array([s * phi[d] for d, s in self._ref]).reshape(len(self._ref), -1))

    def _products(self, phi: np.ndarray) -> np.ndarray:
        po, pr = self._shapes_at(phi)
        return np.einsum("om,rm->orm", po, pr).reshape(len(self._out) * len(self._ref), -1)
