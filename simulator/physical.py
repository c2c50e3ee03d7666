"""The frame's physical changes as parameters: the model the physical diagnosis fits.

A physical change of the frame is a sum of scaled parts of its FE matrices, so the frame is assembled
once, split into parts, and every candidate is ``K = sum_i a_i K_i``, ``M = sum_j b_j M_j`` plus lumped
masses, followed by ``K phi = omega^2 M phi`` (:func:`scipy.linalg.eigh`, only the modes needed):

* ``K_c`` axial + torsion and ``K_c,bend`` bending stiffness of each member ``c`` (``left``, ``right``,
  ``top``), ``M_c`` its mass; the springs of the supports and joints split into their translational
  (N/m) and rotational (N m/rad) parts.
* the accelerometers of the channel set-up (mass ``[sensors.accelerometer] mass_kg`` at each output's
  node, all three translations) when ``[sensors] mass_loading`` is on: known processing, part of the
  simulation, not a discrepancy.

The causes are the rows of the registry :data:`CAUSES` (:class:`PhysicalCause`: the cause's
:class:`~analysis.diagnosis.physical.CauseSpec` and the function that applies it to an
:class:`Assembly`); names and parameters are fixed (tests, the JSON and users key on them):

=====================  ===========================================  =======================================
name                   parameters                                   change
=====================  ===========================================  =======================================
``added_mass``         ``point`` (node ``component:node``),          lumped mass on the node's translations
                       ``mass_kg``                                  and a steel cube's rotary inertia
``support_stiffness``  ``factor_translational``, ``factor_rotational``  support springs x factor
``joint_stiffness``    ``factor_translational``, ``factor_rotational``  column-beam joint springs x factor
``member_mass``        ``component``, ``factor``                     density (mass) of one member x factor
``member_stiffness``   ``component``, ``factor``                     bending stiffness EI of one member x factor
``element_stiffness``  ``element`` (``member:e``), ``factor``        bending stiffness EI of one element x factor
``mass_loading``       ``mass_kg`` (each accelerometer)              accelerometer mass at every output node
``stiffness_shift``    ``stiffness_factor`` (and ``factor`` =        Young's modulus x stiffness_factor (all
                       its square root, the frequency ratio)         members; springs unchanged)
=====================  ===========================================  =======================================

:class:`FrameVariants` answers the protocol of :mod:`analysis.diagnosis.physical` (``causes``,
``modes``, ``model``); it lives here because only the simulator knows the frame, and the diagnosis
sees only containers.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import scipy.linalg

from analysis.diagnosis.physical import CauseSpec, ParamSpec
from analysis.modal import ModalModel, pole_from_fz
from analysis.points import parse_point

from .config import FrameConfig
from .fem import FrameModel, ModelError, assemble_beam, member_nodes_xyz, section_properties, stamp_spring

__all__ = ["FrameVariants", "CAUSES", "PhysicalCause", "Assembly", "register_cause"]


@dataclass
class Assembly:
    """What a candidate changes: factors on the frame's parts and lumped masses. A cause's function
    edits it in place; :meth:`FrameVariants.matrices` then sums the scaled parts."""

    modulus: float = 1.0                                              # Young's modulus factor, every member
    bending: dict = field(default_factory=dict)                       # member -> EI factor
    element_bending: dict = field(default_factory=dict)               # "member:e" -> EI factor of that element
    mass: dict = field(default_factory=dict)                          # member -> mass factor
    springs: dict = field(default_factory=dict)                       # (kind, part) -> factor
    sensor_mass_kg: float | None = None                             # accelerometer mass (None: the config's)
    lumped: list = field(default_factory=list)                        # [(node, kg, rotary inertia?)]


@dataclass(frozen=True)
class PhysicalCause:
    """One row of the cause registry: the cause as the diagnosis sees it (:class:`CauseSpec`: name,
    parameters with their search ranges, the choice, description, advice) and the function that
    applies its parameters to an :class:`Assembly`."""

    spec: CauseSpec
    apply: Callable[[Assembly, Mapping], None]


def _added_mass(a: Assembly, p: Mapping) -> None:
    a.lumped.append((str(p["point"]), float(p["mass_kg"]), True))


def _springs(kind: str) -> Callable[[Assembly, Mapping], None]:
    def apply(a: Assembly, p: Mapping) -> None:
        for part in ("translational", "rotational"):
            a.springs[(kind, part)] = a.springs.get((kind, part), 1.0) * float(p.get(f"factor_{part}", 1.0))
    return apply


def _member_mass(a: Assembly, p: Mapping) -> None:
    c = str(p["component"])
    a.mass[c] = a.mass.get(c, 1.0) * float(p["factor"])


def _member_stiffness(a: Assembly, p: Mapping) -> None:
    c = str(p["component"])
    a.bending[c] = a.bending.get(c, 1.0) * float(p["factor"])


def _element_stiffness(a: Assembly, p: Mapping) -> None:
    e = str(p["element"])
    a.element_bending[e] = a.element_bending.get(e, 1.0) * float(p["factor"])


def _mass_loading(a: Assembly, p: Mapping) -> None:
    a.sensor_mass_kg = float(p["mass_kg"])


def _stiffness_shift(a: Assembly, p: Mapping) -> None:
    a.modulus *= float(p.get("stiffness_factor", 1.0))


#: The cause registry (factors are dimensionless, masses kg). Adding a cause: one row and its function.
CAUSES: dict[str, PhysicalCause] = {}


def register_cause(row: PhysicalCause) -> None:
    """Add a row to :data:`CAUSES` (a cause of the same name is replaced)."""
    CAUSES[row.spec.name] = row


for _row in (
    PhysicalCause(CauseSpec(
        "added_mass", (ParamSpec("mass_kg", 0.05, 30.0, nominal=0.0, unit="kg"),), choice="point",
        description="a mass fixed on the frame at one node (all three translations)",
        advice="A mass the model lacks sits at the named node (a fixture, a block, cabling): add it to the "
               "model as a lumped mass there, or remove it from the structure."), _added_mass),
    PhysicalCause(CauseSpec(
        "support_stiffness", (ParamSpec("factor_translational", 1e-3, 1e2), ParamSpec("factor_rotational", 1e-2, 1e2)),
        description="the base supports' springs, translational and rotational, scaled",
        advice="The supports are softer or stiffer than modelled: check the clamping (bolts' torque, the "
               "foundation) or update the support springs by the fitted factors."), _springs("support")),
    PhysicalCause(CauseSpec(
        "joint_stiffness", (ParamSpec("factor_translational", 1e-4, 1e2), ParamSpec("factor_rotational", 1e-3, 1e2)),
        description="the column-beam joints' springs, translational and rotational, scaled",
        advice="The column-beam joints are softer or stiffer than modelled: check the joints' bolts and "
               "welds, or update the joint springs by the fitted factors."), _springs("joint")),
    PhysicalCause(CauseSpec(
        "member_mass", (ParamSpec("factor", 0.5, 2.0),), choice="component",
        description="the mass (density or area) of one member scaled",
        advice="One member is heavier or lighter than modelled: check its section and material, or add the "
               "attached mass spread along it."), _member_mass),
    PhysicalCause(CauseSpec(
        "member_stiffness", (ParamSpec("factor", 0.3, 2.0),), choice="component",
        description="the bending stiffness EI of one member scaled",
        advice="One member bends more or less easily than modelled: check its section (second moments) and "
               "orientation, or update its EI by the fitted factor."), _member_stiffness),
    PhysicalCause(CauseSpec(
        "element_stiffness", (ParamSpec("factor", 0.02, 2.0),), choice="element",
        description="the bending stiffness EI of one element scaled (a crack or local damage)",
        advice="One short piece of a member has lost (or gained) bending stiffness: inspect the named element "
               "(between nodes e and e+1) for a crack, a notch, corrosion or a loose attachment."),
        _element_stiffness),
    PhysicalCause(CauseSpec(
        "mass_loading", (ParamSpec("mass_kg", 0.0, 1.0, nominal=None, unit="kg", log=False),),
        description="the accelerometers' mass at every measured output (all three translations)",
        advice="The accelerometers' mass lowers the frequencies: put the sensors' mass at their nodes in the "
               "model (the channel set-up's accelerometer mass), or use lighter sensors."), _mass_loading),
    PhysicalCause(CauseSpec(
        "stiffness_shift", (ParamSpec("stiffness_factor", 0.6, 1.6),),
        description="the material's Young's modulus scaled (every member; springs unchanged)",
        advice="Every member is stiffer or softer by the same factor: update Young's modulus (or every "
               "section's second moments) by the fitted stiffness factor."), _stiffness_shift),
):
    register_cause(_row)


def _one(cause: str | None, params: Mapping) -> list[tuple[str, Mapping]]:
    return [] if cause is None else [(cause, params)]


def _config(config: FrameConfig | str | Path | None) -> FrameConfig:
    return config if isinstance(config, FrameConfig) else FrameConfig.load(config)


class FrameVariants:
    """The frame of ``config`` at the measured ``outputs`` / ``references``, split into parts.

    ``modes(cause, params, max_freq_hz)`` gives the natural frequencies (Hz) and the shape products at
    the measured points; ``model(cause, params)`` the receptance pole-residue model (m/N, all modes up
    to ``[modes] max_freq_hz``) with ``meta["output_shapes"]``, like :func:`simulator.effects.base_model`
    but with the channel set-up's accelerometer masses. ``cause=None`` is the frame as configured.
    """

    def __init__(self, config: FrameConfig | str | Path | None, outputs: Sequence[str],
                 references: Sequence[str]) -> None:
        cfg = _config(config)
        self.config = cfg
        self.outputs = tuple(map(str, outputs))
        self.references = tuple(map(str, references))
        self.frame = FrameModel.from_config(cfg, supports=False)   # node map; its K, M are not used
        self._out = [self.frame.dof(p) for p in self.outputs]      # validates the points
        self._ref = [self.frame.dof(p) for p in self.references]
        n = self.frame.n_dof
        mat = cfg.material
        G = mat.youngs_modulus_pa / (2.0 * (1.0 + mat.poisson_ratio))
        self.components = tuple(cfg.components)
        self._K_rest: dict[str, np.ndarray] = {}
        self._K_bend: dict[str, np.ndarray] = {}
        self._K_elem: dict[str, np.ndarray] = {}      # "member:e" -> that element's bending stiffness
        self._M: dict[str, np.ndarray] = {}
        elements = []
        for name, comp in cfg.components.items():
            sp = section_properties(cfg.sections[comp.section])
            xyz = member_nodes_xyz(comp)
            damage = cfg.damage.bending_factors(name, comp.n_elements)
            _, m = assemble_beam(xyz, mat.youngs_modulus_pa, G, mat.density_kg_m3, sp, comp.roll_deg)
            k_rest, _ = assemble_beam(xyz, mat.youngs_modulus_pa, G, mat.density_kg_m3,
                                      replace(sp, Iy=0.0, Iz=0.0), comp.roll_deg)
            first = 6 * self.frame.node_index[(name, 0)]
            sl = slice(first, first + k_rest.shape[0])

            def full(block: np.ndarray, sl: slice = sl) -> np.ndarray:
                out = np.zeros((n, n))
                out[sl, sl] = block
                return out

            bend = np.zeros((n, n))
            for e in range(comp.n_elements):
                one = [0.0] * comp.n_elements
                one[e] = damage[e]
                k_e, _ = assemble_beam(xyz, mat.youngs_modulus_pa, G, mat.density_kg_m3, sp, comp.roll_deg, one)
                self._K_elem[f"{name}:{e}"] = full(k_e - k_rest)
                bend += self._K_elem[f"{name}:{e}"]
                elements.append(f"{name}:{e}")
            self._K_rest[name], self._K_bend[name], self._M[name] = full(k_rest), bend, full(m)
        self.elements = tuple(elements)
        self._springs = {}
        for kind, pairs, k6 in (("support", [(a, None) for a in cfg.supports.nodes], cfg.supports.stiffness),
                                ("joint", list(cfg.joints.pairs), cfg.joints.stiffness)):
            for part, axes in (("translational", slice(0, 3)), ("rotational", slice(3, 6))):
                K = np.zeros((n, n))
                k = np.zeros(6)
                k[axes] = np.asarray(k6, float)[axes]
                for a, b in pairs:
                    f = cfg.damage.spring_factor(kind, (a,) if b is None else (a, b))
                    stamp_spring(K, self.frame.node(a), None if b is None else self.frame.node(b), k * f)
                self._springs[(kind, part)] = K
        index = self.frame.node_index
        self.nodes = tuple(f"{c}:{i}" for (c, i) in sorted(index, key=lambda k: index[k]))
        sens = cfg.sensors
        self.sensor_nodes = tuple(dict.fromkeys(f"{q.component}:{q.node}" for q in map(parse_point, self.outputs)))
        self.sensor_mass_kg = float(sens.accelerometer.mass_kg) if sens.mass_loading else 0.0
        self._refined_frames: dict[int, FrameVariants] = {}

    # ------------------------------------------------------------------ protocol of the diagnosis
    def causes(self) -> tuple[CauseSpec, ...]:
        """The physical causes with their choices filled in (every node, member, element)."""
        options = {"point": self.nodes, "component": self.components, "element": self.elements}
        out = []
        for row in CAUSES.values():
            c = row.spec
            if c.choice is not None:
                c = replace(c, options=options[c.choice])
            if c.name == "mass_loading":
                c = replace(c, params=(replace(c.params[0], nominal=self.sensor_mass_kg),))
            out.append(c)
        return tuple(out)

    def modes(self, cause: str | None, params: Mapping, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """Natural frequencies (Hz, flexible modes up to ``max_freq_hz``) and the shape products
        ``phi_o phi_r`` (n_out * n_ref, n_modes) at the measured points (C order over (o, r))."""
        return self.modes_of(_one(cause, params), max_freq_hz)

    def modes_of(self, changes: Sequence[tuple[str, Mapping]], max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`modes` of the frame changed by every ``(cause, params)`` of ``changes`` at once."""
        K, M = self.matrices_of(changes)
        w2, phi = scipy.linalg.eigh(K, M, subset_by_value=(1.0, (2 * np.pi * max_freq_hz) ** 2))
        f = np.sqrt(w2) / (2 * np.pi)
        return f, self._products(phi)

    def model(self, cause: str | None, params: Mapping) -> ModalModel:
        """Receptance pole-residue model (m/N) of the changed frame, modes up to ``[modes] max_freq_hz``,
        damping from ``[damping]`` of the config, ``meta["output_shapes"]`` at the outputs."""
        return self.model_of(_one(cause, params))

    def model_of(self, changes: Sequence[tuple[str, Mapping]]) -> ModalModel:
        """:meth:`model` of the frame changed by every ``(cause, params)`` of ``changes`` at once."""
        K, M = self.matrices_of(changes)
        fmax = self.config.modes.max_freq_hz
        w2, phi = scipy.linalg.eigh(K, M, subset_by_value=(1.0, (2 * np.pi * fmax) ** 2))
        f = np.sqrt(w2) / (2 * np.pi)
        zeta = self.config.damping.ratios(f)
        lam = pole_from_fz(f, zeta)
        po, pr = self._shapes_at(phi)
        pp = np.einsum("om,rm->orm", po, pr)
        R = pp / (2j * np.imag(lam))[None, None, :]
        names = "+".join(c for c, _ in changes) or None
        return ModalModel(poles=lam, residues=R, quantity="receptance", residual_form="none",
                          outputs=self.outputs, references=self.references,
                          meta={"source": "simulator.physical", "cause": names,
                                "parameters": dict(changes[0][1]) if len(changes) == 1 else
                                [{"effect": c, "parameters": dict(p)} for c, p in changes],
                                "output_shapes": po})

    def points(self) -> tuple[str, ...]:
        """Every measurable point of the frame: each node in each direction (``component:node:X``...)."""
        return tuple(f"{n}:{d}" for n in self.nodes for d in ("X", "Y", "Z"))

    def at_points(self, outputs: Sequence[str], references: Sequence[str]) -> FrameVariants:
        """The same frame (same configuration, same accelerometers) at other measured points."""
        other = FrameVariants(self.config, outputs, references)
        other.sensor_nodes, other.sensor_mass_kg = self.sensor_nodes, self.sensor_mass_kg
        return other

    def refined(self, refine: int = 2) -> FrameVariants:
        """The same frame with every member's elements ``refine`` times finer, at the same measured
        points (their labels mapped to the finer mesh's nodes); built once per ``refine``."""
        if refine in self._refined_frames:
            return self._refined_frames[refine]
        cfg = self.config
        fine = cfg.with_overrides({
            "components": {c: {"n_elements": refine * comp.n_elements} for c, comp in cfg.components.items()},
            "supports": {"nodes": [self._refined(n, refine) for n in cfg.supports.nodes]},
            "joints": {"pairs": [[self._refined(a, refine), self._refined(b, refine)] for a, b in cfg.joints.pairs]}})
        frame = FrameVariants(fine, [self._refined(p, refine) for p in self.outputs],
                              [self._refined(p, refine) for p in self.references])
        self._refined_frames[refine] = frame
        return frame

    def converged_below_hz(self, tolerance: float = 0.002, refine: int = 2) -> float:
        """Frequency (Hz) below which the FE model's natural frequencies have converged with the mesh:
        every mode of the frame with each member's elements ``refine`` times finer (:meth:`refined`)
        lies within ``tolerance`` (relative) of this model's; the limit lies halfway between the last
        mode that does and the first that does not. A measurement is compared with the simulation only
        below it."""
        top = 2 * self.config.modes.max_freq_hz
        f0 = self.modes(None, {}, top)[0]
        f1 = self.refined(refine).modes(None, {}, top)[0]
        n = min(f0.size, f1.size)
        bad = np.flatnonzero(np.abs(f1[:n] / f0[:n] - 1) > tolerance)
        if not bad.size:
            return float(f0[n - 1]) if n else top
        k = int(bad[0])
        return float(0.5 * (f0[k - 1] + f0[k])) if k > 0 else float(0.5 * f0[0])

    def refined_model(self, refine: int = 2) -> ModalModel:
        """The receptance model of :meth:`refined` under this model's point labels: held against
        :meth:`model` it shows the simulation's own discretisation error (the model-form floor below which
        a measured difference is not evidence of a physical change)."""
        m = self.refined(refine).model(None, {})
        return replace(m, outputs=self.outputs, references=self.references)

    @staticmethod
    def _refined(node: str, refine: int) -> str:
        parts = str(node).split(":")
        return ":".join([parts[0], str(refine * int(parts[1])), *parts[2:]])

    # ------------------------------------------------------------------ assembly
    def matrices(self, cause: str | None, params: Mapping) -> tuple[np.ndarray, np.ndarray]:
        """K (N/m, N m/rad) and M (kg, kg m^2) of the frame changed by ``cause`` with ``params``."""
        return self.matrices_of(_one(cause, params))

    def matrices_of(self, changes: Sequence[tuple[str, Mapping]]) -> tuple[np.ndarray, np.ndarray]:
        """K and M of the frame changed by every ``(cause, params)`` of ``changes`` (registry rows of
        :data:`CAUSES` applied in turn to one :class:`Assembly`)."""
        a = Assembly()
        for cause, params in changes:
            if cause not in CAUSES:
                raise ModelError(f"unknown physical cause {cause!r}; the registry has {', '.join(CAUSES)}")
            CAUSES[cause].apply(a, params)
        n = self.frame.n_dof
        K, M = np.zeros((n, n)), np.zeros((n, n))
        E = a.modulus
        for c in self.components:
            K += E * self._K_rest[c]
            K += E * a.bending.get(c, 1.0) * self._K_bend[c]
            M += a.mass.get(c, 1.0) * self._M[c]
        for e, f in a.element_bending.items():
            if e not in self._K_elem:
                raise ModelError(f"element {e!r} is not on the frame; its elements are {', '.join(self.elements)}")
            c = e.partition(":")[0]
            K += E * a.bending.get(c, 1.0) * (float(f) - 1.0) * self._K_elem[e]
        for key, spring in self._springs.items():
            K += a.springs.get(key, 1.0) * spring
        sensor_mass = self.sensor_mass_kg if a.sensor_mass_kg is None else a.sensor_mass_kg
        for node in self.sensor_nodes:
            self._lump(M, node, sensor_mass)
        for node, mass, rotary in a.lumped:
            self._lump(M, node, mass, rotary=rotary)
        return K, M

    def _lump(self, M: np.ndarray, node: str, mass_kg: float, rotary: bool = False) -> None:
        """A lumped mass (kg) on the node's translations; with ``rotary`` also the rotary inertia of a
        compact steel block of that mass centred on the node, ``m a^2 / 6`` (kg m^2) about each axis
        with ``a = (m / rho)^(1/3)`` the side of a cube of the frame's density."""
        if mass_kg < 0:
            raise ModelError(f"a mass of {mass_kg} kg at {node}: masses must be >= 0")
        first = 6 * self.frame.node(node)
        dofs = first + np.arange(3)
        M[dofs, dofs] += mass_kg
        if rotary:
            a = (mass_kg / self.config.material.density_kg_m3) ** (1.0 / 3.0)
            rot = first + np.arange(3, 6)
            M[rot, rot] += mass_kg * a * a / 6.0

    def _shapes_at(self, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed mode-shape values at the outputs (n_out, n_modes) and references (n_ref, n_modes)."""
        return (np.array([s * phi[d] for d, s in self._out]), np.array([s * phi[d] for d, s in self._ref]))

    def _products(self, phi: np.ndarray) -> np.ndarray:
        po, pr = self._shapes_at(phi)
        return np.einsum("om,rm->orm", po, pr).reshape(len(self._out) * len(self._ref), -1)

