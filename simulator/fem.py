"""Finite-element model of the steel frame: 3D Euler-Bernoulli beams, 6 DOF per node.

Symbols and conventions
-----------------------
Each node carries ``(u_x, u_y, u_z, theta_x, theta_y, theta_z)`` in global axes (m, rad).
A two-node element of length ``L`` (m) with Young's modulus ``E`` (Pa), shear modulus
``G = E / (2 (1 + nu))``, density ``rho`` (kg/m^3), area ``A`` (m^2), second moments
``I_y``, ``I_z`` (m^4, about the local y and z axes), torsion constant ``J`` (m^4) and polar
moment ``I_p = I_y + I_z`` has, in local axes (x along the element):

* axial ``EA/L [[1, -1], [-1, 1]]``, torsion ``GJ/L [[1, -1], [-1, 1]]``;
* bending in the local x-y plane (``v``, ``theta_z = dv/dx``) and the x-z plane
  (``w``, ``theta_y = -dw/dx``) with the cubic Hermite stiffness
  ``EI/L^3 [[12, 6L, -12, 6L], [6L, 4L^2, -6L, 2L^2], ...]`` on (deflection, slope);
* consistent mass ``rho A L / 420 [[156, 22L, 54, -13L], ...]`` for bending,
  ``rho A L / 6 [[2, 1], [1, 2]]`` axial and ``rho I_p L / 6 [[2, 1], [1, 2]]`` torsion.

Global matrices are ``T^T k T`` with ``T = blockdiag(R, R, R, R)`` and ``R`` the 3x3 rotation whose
rows are the local axes in global coordinates. Springs (supports to ground, joints between two
nodes) add ``k`` on the diagonal (and ``-k`` off-diagonal for joints) of their DOFs.

The undamped eigenproblem ``K phi = omega^2 M phi`` is solved with ``scipy.linalg.eigh``; shapes are
mass-normalised (``phi^T M phi = 1``). Damping is modal (proportional): each mode gets a ratio
``zeta_r`` from the configuration (a list per mode, or Rayleigh ``alpha / (2 omega) + beta omega / 2``).

Receptance between DOFs ``i`` and ``j`` (m/N):

    H_ij(w) = sum_r phi_ir phi_jr / (omega_r^2 - w^2 + 2 j zeta_r omega_r w)

and mobility/accelerance are ``(jw)^p H_ij`` (p = 1, 2). In pole-residue form,
``lambda_r = -zeta_r omega_r + j omega_r sqrt(1 - zeta_r^2)`` and ``R_ijr = phi_ir phi_jr / (2 j omega_d,r)``.
"""
from __future__ import annotations

import logging
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from dataclasses import replace as _replace

import numpy as np
import scipy.linalg

from analysis.frf import QUANTITIES, QUANTITY_POWER, QUANTITY_UNIT, FRFSet
from analysis.modal import ModalModel, pole_from_fz
from analysis.points import Point, parse_point

from .config import ComponentConfig, FrameConfig, SectionConfig
from .errors import ModelError

__all__ = [
    "SectionProperties",
    "section_properties",
    "beam_stiffness_local",
    "beam_mass_local",
    "rotation_matrix",
    "assemble_beam",
    "element_matrices",
    "member_nodes_xyz",
    "stamp_spring",
    "FrameModel",
    "ModeSet",
    "ModelError",
]

logger = logging.getLogger(__name__)

_POWER = QUANTITY_POWER


@dataclass(frozen=True)
class SectionProperties:
    """Cross-section properties: area A (m^2), I_y, I_z (m^4, about local y and z), torsion constant J (m^4)."""

    A: float
    Iy: float
    Iz: float
    J: float

    @property
    def Ip(self) -> float:
        """Polar second moment I_y + I_z (m^4), used for the torsional inertia."""
        return self.Iy + self.Iz


def _rect_torsion_constant(a: float, b: float) -> float:
    """Saint-Venant torsion constant of an a x b rectangle (a >= b), Roark's approximation.

    J = a b^3 (1/3 - 0.21 (b/a) (1 - b^4 / (12 a^4))).
    """
    a, b = max(a, b), min(a, b)
    return a * b ** 3 * (1.0 / 3.0 - 0.21 * (b / a) * (1.0 - b ** 4 / (12.0 * a ** 4)))


def section_properties(sec: SectionConfig) -> SectionProperties:
    """Properties of a section: ``rect`` (width along local y, depth along local z, m), ``rhs``
    (hollow rectangle with wall thickness t, thin-walled Bredt torsion constant) or ``explicit``."""
    if sec.shape == "rect":
        b, h = sec.width_m, sec.depth_m
        return SectionProperties(A=b * h, Iy=b * h ** 3 / 12.0, Iz=h * b ** 3 / 12.0, J=_rect_torsion_constant(b, h))
    if sec.shape == "rhs":
        b, h, t = sec.width_m, sec.depth_m, sec.wall_m
        bi, hi = b - 2 * t, h - 2 * t
        A = b * h - bi * hi
        Iy = (b * h ** 3 - bi * hi ** 3) / 12.0
        Iz = (h * b ** 3 - hi * bi ** 3) / 12.0
        # Bredt: J = 4 A_m^2 t / perimeter_m, mid-line area and perimeter
        Am = (b - t) * (h - t)
        J = 4.0 * Am ** 2 * t / (2.0 * ((b - t) + (h - t)))
        return SectionProperties(A=A, Iy=Iy, Iz=Iz, J=J)
    return SectionProperties(A=sec.area_m2, Iy=sec.iy_m4, Iz=sec.iz_m4, J=sec.j_m4)


def _hermite_stiffness(EI: float, L: float) -> np.ndarray:
    """Cubic Hermite bending stiffness on (deflection1, slope1, deflection2, slope2)."""
    return EI / L ** 3 * np.array(
        [
            [12.0, 6 * L, -12.0, 6 * L],
            [6 * L, 4 * L ** 2, -6 * L, 2 * L ** 2],
            [-12.0, -6 * L, 12.0, -6 * L],
            [6 * L, 2 * L ** 2, -6 * L, 4 * L ** 2],
        ]
    )


def _hermite_mass(m_per_len: float, L: float) -> np.ndarray:
    """Consistent bending mass on (deflection1, slope1, deflection2, slope2)."""
    return m_per_len * L / 420.0 * np.array(
        [
            [156.0, 22 * L, 54.0, -13 * L],
            [22 * L, 4 * L ** 2, 13 * L, -3 * L ** 2],
            [54.0, 13 * L, 156.0, -22 * L],
            [-13 * L, -3 * L ** 2, -22 * L, 4 * L ** 2],
        ]
    )


# local DOF indices of the two bending planes; slope sign: theta_z = +dv/dx, theta_y = -dw/dx
_XY = np.array([1, 5, 7, 11])
_XZ = np.array([2, 4, 8, 10])
_S_XZ = np.array([1.0, -1.0, 1.0, -1.0])


def beam_stiffness_local(E: float, G: float, sp: SectionProperties, L: float) -> np.ndarray:
    """12x12 local stiffness (N/m, N m/rad) of a 3D Euler-Bernoulli element; see module docstring."""
    if L <= 0:
        raise ModelError(f"element length must be > 0 m, got {L}")
    k = np.zeros((12, 12))
    for (a, b), c in (((0, 6), E * sp.A / L), ((3, 9), G * sp.J / L)):
        k[np.ix_([a, b], [a, b])] += c * np.array([[1.0, -1.0], [-1.0, 1.0]])
    k[np.ix_(_XY, _XY)] += _hermite_stiffness(E * sp.Iz, L)
    k[np.ix_(_XZ, _XZ)] += _S_XZ[:, None] * _hermite_stiffness(E * sp.Iy, L) * _S_XZ[None, :]
    return k


def beam_mass_local(rho: float, sp: SectionProperties, L: float) -> np.ndarray:
    """12x12 local consistent mass (kg, kg m^2) of a 3D element; see module docstring."""
    m = np.zeros((12, 12))
    pair = np.array([[2.0, 1.0], [1.0, 2.0]]) / 6.0
    m[np.ix_([0, 6], [0, 6])] += rho * sp.A * L * pair
    m[np.ix_([3, 9], [3, 9])] += rho * sp.Ip * L * pair
    mb = _hermite_mass(rho * sp.A, L)
    m[np.ix_(_XY, _XY)] += mb
    m[np.ix_(_XZ, _XZ)] += _S_XZ[:, None] * mb * _S_XZ[None, :]
    return m


def rotation_matrix(p1: np.ndarray, p2: np.ndarray, roll_deg: float = 0.0) -> np.ndarray:
    """3x3 rotation R (rows = local x, y, z in global axes) of an element from p1 to p2 (m).

    Local x runs p1 -> p2. Local y = (v_ref x x) normalised, with v_ref = global Z, or global X
    when the element is (nearly) parallel to Z; local z = x cross y. Then the section is rolled by
    ``roll_deg`` about local x (positive from y towards z).
    """
    d = np.asarray(p2, float) - np.asarray(p1, float)
    L = float(np.linalg.norm(d))
    if L == 0:
        raise ModelError("element with coincident end points: check the component coordinates")
    ex = d / L
    ref = np.array([0.0, 0.0, 1.0]) if abs(ex[2]) < 0.99 else np.array([1.0, 0.0, 0.0])
    ey = np.cross(ref, ex)
    ey /= np.linalg.norm(ey)
    ez = np.cross(ex, ey)
    c, s = np.cos(np.radians(roll_deg)), np.sin(np.radians(roll_deg))
    ey, ez = c * ey + s * ez, -s * ey + c * ez
    return np.vstack([ex, ey, ez])


def _transform(R: np.ndarray) -> np.ndarray:
    T = np.zeros((12, 12))
    for b in range(4):
        T[3 * b:3 * b + 3, 3 * b:3 * b + 3] = R
    return T


def assemble_beam(
    coords: np.ndarray, E: float, G: float, rho: float, sp: SectionProperties, roll_deg: float = 0.0,
    bending_factors: Sequence[float] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Global K, M (6 n_nodes square) of a straight chain of elements through ``coords`` (n_nodes, 3) m.

    ``bending_factors`` (one per element, default all 1) scale each element's bending stiffness
    E*Iy and E*Iz (local damage such as a crack); its mass is unchanged."""
    n = coords.shape[0]
    K = np.zeros((6 * n, 6 * n))
    M = np.zeros((6 * n, 6 * n))
    for e, (k, m) in enumerate(element_matrices(coords, E, G, rho, sp, roll_deg, bending_factors)):
        sl = slice(6 * e, 6 * e + 12)
        K[sl, sl] += k
        M[sl, sl] += m
    return K, M


def element_matrices(
    coords: np.ndarray, E: float, G: float, rho: float, sp: SectionProperties, roll_deg: float = 0.0,
    bending_factors: Sequence[float] | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each element's global 12x12 stiffness (N/m, N m/rad) and mass (kg, kg m^2) along the chain of
    nodes ``coords`` (n_nodes, 3) m, on the DOFs of its two nodes; ``bending_factors`` as in
    :func:`assemble_beam`."""
    out = []
    for e in range(coords.shape[0] - 1):
        L = float(np.linalg.norm(coords[e + 1] - coords[e]))
        T = _transform(rotation_matrix(coords[e], coords[e + 1], roll_deg))
        f = 1.0 if bending_factors is None else float(bending_factors[e])
        sp_e = sp if f == 1.0 else _replace(sp, Iy=sp.Iy * f, Iz=sp.Iz * f)
        out.append((T.T @ beam_stiffness_local(E, G, sp_e, L) @ T, T.T @ beam_mass_local(rho, sp, L) @ T))
    return out


def member_nodes_xyz(comp: ComponentConfig) -> np.ndarray:
    """Coordinates (n_elements + 1, 3) m of a member's nodes, evenly from ``start_m`` to ``end_m``."""
    start, end = np.asarray(comp.start_m, float), np.asarray(comp.end_m, float)
    t = np.linspace(0.0, 1.0, comp.n_elements + 1)
    return start[None, :] + t[:, None] * (end - start)[None, :]


def stamp_spring(K: np.ndarray, node_a: int, node_b: int | None, k6: Sequence[float] | np.ndarray) -> None:
    """Add six springs ``k6`` (3 x N/m, 3 x N m/rad) to ``K`` in place: from node ``node_a`` to ground
    (``node_b`` None) or between nodes ``node_a`` and ``node_b`` (``+k`` on both diagonals, ``-k``
    between them)."""
    k = np.asarray(k6, float)
    da = 6 * node_a + np.arange(6)
    K[da, da] += k
    if node_b is not None:
        db = 6 * node_b + np.arange(6)
        K[db, db] += k
        K[da, db] -= k
        K[db, da] -= k


@dataclass(frozen=True)
class ModeSet:
    """Modes of the frame: natural frequencies ``freq_hz`` (Hz), damping ratios ``damping`` (-),
    mass-normalised ``shapes`` (n_dof, n_modes) in 1/sqrt(kg) (translations) units."""

    freq_hz: np.ndarray
    damping: np.ndarray
    shapes: np.ndarray

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter((self.freq_hz, self.damping, self.shapes))

    @property
    def omega(self) -> np.ndarray:
        """Natural angular frequencies (rad/s)."""
        return 2 * np.pi * self.freq_hz

    @property
    def poles(self) -> np.ndarray:
        """Upper-half-plane poles lambda_r (rad/s)."""
        return pole_from_fz(self.freq_hz, self.damping)


class FrameModel:
    """The assembled frame: K, M, DOF map, modes and analytic FRFs.

    Build with :meth:`from_config`. ``added_masses`` maps point labels (or node keys
    ``component:node``) to lumped translational masses (kg), e.g. accelerometers.
    """

    def __init__(
        self,
        K: np.ndarray,
        M: np.ndarray,
        node_index: dict[tuple[str, int], int],
        node_coords: np.ndarray,
        cfg: FrameConfig,
    ) -> None:
        self.K = K
        self.M = M
        self.node_index = dict(node_index)
        self.node_coords = node_coords
        self.config = cfg
        self._modes: ModeSet | None = None

    # ------------------------------------------------------------------ building
    @classmethod
    def from_config(
        cls,
        cfg: FrameConfig,
        added_masses: dict[str, float] | None = None,
        *,
        supports: bool = True,
    ) -> FrameModel:
        """Assemble the frame from a :class:`FrameConfig`.

        ``added_masses``: {point or ``component:node``: kg}; lumped masses on the three translations.
        ``supports=False`` drops the base springs (free-free frame, six rigid-body modes).
        """
        mat = cfg.material
        G = mat.youngs_modulus_pa / (2.0 * (1.0 + mat.poisson_ratio))
        blocks_K, blocks_M, node_index, coords = [], [], {}, []
        offset = 0
        for name, comp in cfg.components.items():
            sp = section_properties(cfg.sections[comp.section])
            xyz = member_nodes_xyz(comp)
            k, m = assemble_beam(xyz, mat.youngs_modulus_pa, G, mat.density_kg_m3, sp, comp.roll_deg,
                                 cfg.damage.bending_factors(name, comp.n_elements))
            blocks_K.append(k)
            blocks_M.append(m)
            for i in range(comp.n_elements + 1):
                node_index[(name, i)] = offset + i
            coords.append(xyz)
            offset += comp.n_elements + 1
        K = scipy.linalg.block_diag(*blocks_K)
        M = scipy.linalg.block_diag(*blocks_M)
        model = cls(K, M, node_index, np.vstack(coords), cfg)
        if supports:
            for node in cfg.supports.nodes:
                f = cfg.damage.spring_factor("support", (node,))
                k6 = cfg.nonlinear.spring_stiffness((node,), cfg.supports.stiffness)
                model._add_ground_spring(node, [k * f for k in k6])
        for a, b in cfg.joints.pairs:
            f = cfg.damage.spring_factor("joint", (a, b))
            k6 = cfg.nonlinear.spring_stiffness((a, b), cfg.joints.stiffness)
            model._add_joint_spring(a, b, [k * f for k in k6])
        for label, mass in (added_masses or {}).items():
            model._add_lumped_mass(label, mass)
        return model

    def node(self, key: str) -> int:
        """Index of the node ``component:node`` (a point label's direction, if any, is ignored)."""
        parts = str(key).split(":")
        try:
            comp, node = parts[0], int(parts[1])
        except (IndexError, ValueError):
            raise ModelError(f"bad node key {key!r}: expected component:node, e.g. 'left:0'") from None
        if (comp, node) not in self.node_index:
            raise ModelError(f"node {comp}:{node} does not exist; {self._node_help()}")
        return self.node_index[(comp, node)]

    def _node_help(self) -> str:
        comps: dict[str, int] = {}
        for (c, i) in self.node_index:
            comps[c] = max(comps.get(c, 0), i)
        return "nodes are " + ", ".join(f"{c}:0..{n}" for c, n in comps.items())

    def _add_ground_spring(self, node: str, k6: Sequence[float]) -> None:
        stamp_spring(self.K, self.node(node), None, k6)

    def _add_joint_spring(self, a: str, b: str, k6: Sequence[float]) -> None:
        stamp_spring(self.K, self.node(a), self.node(b), k6)

    def _add_lumped_mass(self, label: str, mass_kg: float) -> None:
        if mass_kg < 0:
            raise ModelError(f"added mass at {label} is {mass_kg} kg; masses must be >= 0")
        dofs = 6 * self.node(label) + np.arange(3)
        self.M[dofs, dofs] += mass_kg
        self._modes = None

    # ------------------------------------------------------------------ queries
    @property
    def n_dof(self) -> int:
        return self.K.shape[0]

    def dof(self, point: str | Point) -> tuple[int, int]:
        """(global DOF index, sign) of a point label ``component:node:direction``."""
        p = parse_point(point)
        if (p.component, p.node) not in self.node_index:
            raise ModelError(f"point {point} is not on the frame; {self._node_help()}")
        return 6 * self.node_index[(p.component, p.node)] + p.axis, p.sign

    def total_mass(self) -> float:
        """Translational mass (kg) seen by a rigid translation along X: r^T M r."""
        r = np.zeros(self.n_dof)
        r[0::6] = 1.0
        return float(r @ self.M @ r)

    def eigen(self) -> tuple[np.ndarray, np.ndarray]:
        """All undamped modes: (omega^2 (rad/s)^2 ascending, mass-normalised shapes (n_dof, n_dof))."""
        w2, phi = scipy.linalg.eigh(self.K, self.M)
        return w2, phi

    def modes(self, max_freq_hz: float | None = None) -> ModeSet:
        """Modes up to ``max_freq_hz`` (default from the config ``[modes] max_freq_hz``).

        Returns a :class:`ModeSet` (unpacks as ``freq_hz, damping, shapes``). Shapes are mass-normalised;
        each shape's sign is fixed so that its largest-magnitude DOF is positive (deterministic).
        Rigid-body modes (omega^2 <= 0 numerically) are returned with frequency 0 Hz.
        """
        fmax = self.config.modes.max_freq_hz if max_freq_hz is None else float(max_freq_hz)
        if self._modes is None or max_freq_hz is not None:
            w2, phi = self.eigen()
            f = np.sqrt(np.clip(w2, 0.0, None)) / (2 * np.pi)
            keep = f <= fmax
            f, phi = f[keep], phi[:, keep]
            idx = np.argmax(np.abs(phi), axis=0)
            phi = phi * np.sign(phi[idx, np.arange(phi.shape[1])])[None, :]
            zeta = self.config.damping.ratios(f)
            ms = ModeSet(freq_hz=f, damping=zeta, shapes=phi)
            for a in (ms.freq_hz, ms.damping, ms.shapes):
                a.setflags(write=False)
            if max_freq_hz is not None:
                return ms
            self._modes = ms
        return self._modes

    def shape_at(self, points: Sequence[str], modes: ModeSet | None = None) -> np.ndarray:
        """Mode shape values (n_points, n_modes) at signed point directions."""
        ms = self.modes() if modes is None else modes
        rows = [self.dof(p) for p in points]
        return np.array([s * ms.shapes[d] for d, s in rows]).reshape(len(rows), ms.shapes.shape[1])

    def analytic_frf(
        self,
        outputs: Sequence[str],
        references: Sequence[str],
        freq_hz: np.ndarray,
        quantity: str = "accelerance",
    ) -> FRFSet:
        """The exact FRF of the (truncated) modal model; the truth used in tests.

        H_ij(w) = (jw)^p sum_r phi_ir phi_jr / (omega_r^2 - w^2 + 2 j zeta_r omega_r w), p = 0, 1, 2 for
        receptance (m/N), mobility ((m/s)/N), accelerance ((m/s^2)/N); ``freq_hz`` in Hz.
        """
        if quantity not in QUANTITIES:
            raise ModelError(f"quantity {quantity!r} is not one of {QUANTITIES}")
        ms = self.modes()
        f = np.asarray(freq_hz, dtype=float)
        w = 2 * np.pi * f
        wr = ms.omega
        po = self.shape_at(outputs, ms)
        pr = self.shape_at(references, ms)
        den = wr[:, None] ** 2 - w[None, :] ** 2 + 2j * ms.damping[:, None] * wr[:, None] * w[None, :]
        H = np.einsum("om,rm,mk->ork", po, pr, 1.0 / den) * ((1j * w) ** _POWER[quantity])[None, None, :]
        return FRFSet(freq_hz=f, H=H, quantity=quantity, outputs=tuple(map(str, outputs)),
                      references=tuple(map(str, references)), unit=QUANTITY_UNIT[quantity],
                      meta={"source": "simulator.fem analytic"})

    def modal_model(
        self, outputs: Sequence[str], references: Sequence[str], quantity: str = "accelerance"
    ) -> ModalModel:
        """Exact pole-residue model of the (truncated) analytic FRFs in the form ``quantity``.

        Receptance: ``R_ijr = phi_ir phi_jr / (2 j omega_d,r)`` at ``lambda_r`` (rad/s), no residual terms.
        Because ``R + conj(R) = 0`` and ``2 Re(R lambda) = phi_i phi_j``, the identity
        ``(jw)^2 / (jw - lambda) = jw + lambda + lambda^2 / (jw - lambda)`` gives exactly

        * mobility: residues ``lambda_r R_ijr``, no residual terms;
        * accelerance: residues ``lambda_r^2 R_ijr`` plus the constant ``sum_r phi_ir phi_jr``
          (the mass line of the kept modes), returned as ``upper_residual`` with
          ``residual_form="paper"`` (basis 1, 1/w^2; ``lower_residual`` = 0).

        ``analysis.modal.synthesize`` of the result equals :meth:`analytic_frf` to rounding.
        Rigid-body (0 Hz) modes are excluded.
        """
        if quantity not in QUANTITIES:
            raise ModelError(f"quantity {quantity!r} is not one of {QUANTITIES}")
        ms = self.modes()
        flex = ms.freq_hz > 0
        lam = ms.poles[flex]
        wd = np.imag(lam)
        po = self.shape_at(outputs, ms)[:, flex]
        pr = self.shape_at(references, ms)[:, flex]
        pp = np.einsum("om,rm->orm", po, pr)
        p = _POWER[quantity]
        R = pp / (2j * wd)[None, None, :] * (lam ** p)[None, None, :]
        kw: dict = {"residual_form": "none"}
        if quantity == "accelerance":
            kw = {"residual_form": "paper", "upper_residual": pp.sum(axis=2).astype(complex),
                  "lower_residual": np.zeros(pp.shape[:2], dtype=complex)}
        return ModalModel(poles=lam, residues=R, quantity=quantity, outputs=tuple(map(str, outputs)),
                          references=tuple(map(str, references)),
                          meta={"source": "simulator.fem", "n_modes": int(lam.size)}, **kw)
