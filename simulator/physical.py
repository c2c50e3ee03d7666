"""The frame's physical changes as parameters: the model the physical diagnosis fits.

A physical change of the frame is a sum of scaled parts of its FE matrices, so the frame is assembled
once, split into parts (each a block on the few DOFs it touches, :class:`simulator.ritz.Part`), and
every candidate is ``K = sum_i a_i K_i``, ``M = sum_j b_j M_j`` plus lumped masses, followed by
``K phi = omega^2 M phi`` for the modes needed. A candidate changes only a few parts, so its modes are
solved in a Rayleigh-Ritz space built for those parts (:mod:`simulator.ritz`: ~0.2-0.6 ms instead of
~3 ms for the full eigenproblem, natural frequencies equal to the full model's to 1e-6);
:meth:`FrameVariants.exact_modes_of` solves the full model (``reduced = False``: always);
:meth:`FrameVariants.modes_jac_of` adds the derivatives of the frequencies and shape products with respect to
the parameters (the fits' exact Jacobians), and :meth:`FrameVariants.on_top` is the frame with some changes
made part of its nominal (a search on top of a first cause):

* ``K_c`` axial + torsion and ``K_c,bend`` bending stiffness of each member ``c`` (``left``, ``right``,
  ``top``), ``M_c`` its mass; the springs of the supports and joints split into their translational
  (N/m) and rotational (N m/rad) parts.
* the same member split by property, for a change of its section (``member_section``): its axial (E A)
  and torsion (G J) stiffness, its bending about local y (E I_y, the x-z plane) and about local z (E I_z),
  the rotary inertia of its mass (rho I_p) and, per element, the bending about y (a crack on a member of
  another section). Summed with equal factors they are the grouped parts; a change that leaves the section
  alone never touches them, so every other cause's answers are those of the grouped parts.
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
                       ``mass_kg``, ``inertia_factor``,             and a rotary inertia about each axis:
                       ``inertia_x``, ``inertia_y``, ``inertia_z``  a steel cube's of that mass x
                                                                    inertia_factor x the axis' factor
``support_stiffness``  ``support`` (``all`` or one support node),   the support's (every support's) springs
                       ``factor_translational``, ``factor_rotational``  x factor
``joint_stiffness``    ``joint`` (``all`` or one joint, named by    the joint's (every joint's) column-beam
                       its pair's first node), factors as above     springs x factor
``member_mass``        ``component``, ``factor``                     density (mass) of one member x factor
``member_stiffness``   ``component``, ``factor``                     bending stiffness EI of one member x factor
``member_section``     ``component`` (a member of a ``rect`` or     the member's section of width x
                       ``rhs`` section), ``width_factor``,          width_factor, depth x depth_factor: area,
                       ``depth_factor``                             I_y, I_z, J and I_p by
                                                                    :func:`simulator.fem.section_properties`
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

import copy
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from analysis.diagnosis.physical import CauseSpec, ParamSpec
from analysis.modal import ModalModel, pole_from_fz
from analysis.points import parse_point

from .config import DamageConfig, FrameConfig, SectionConfig, check_fe_memory
from .fem import FrameModel, ModelError, SectionProperties, element_matrices, member_nodes_xyz, section_properties, stamp_spring
from .ritz import Part, ReducedSpace, RitzReduction, lowest_modes

__all__ = ["FrameVariants", "CAUSES", "PhysicalCause", "Assembly", "register_cause", "DIAGNOSIS_BYTES_PER_DOF2",
           "check_diagnosis_size", "ALL_PLACES", "DAMAGE_CAUSES", "damage_changes", "SIZED_MEMBERS", "SENSOR_MASS"]


@dataclass
class Assembly:
    """What a candidate changes: factors on the frame's parts and lumped masses. A cause's function
    edits it in place; :meth:`FrameVariants.matrices` then sums the scaled parts."""

    modulus: float = 1.0                                              # Young's modulus factor, every member
    bending: dict = field(default_factory=dict)                       # member -> EI factor
    element_bending: dict = field(default_factory=dict)               # "member:e" -> EI factor of that element
    mass: dict = field(default_factory=dict)                          # member -> mass factor
    section: dict = field(default_factory=dict)                       # member -> (width, depth) factors of its
                                                                      # section (rect / rhs)
    springs: dict = field(default_factory=dict)                       # (kind, part, place) -> factor (place
                                                                      # None: every support / joint)
    sensor_mass_kg: float | None = None                             # accelerometer mass (None: the config's)
    lumped: list = field(default_factory=list)                        # [(node, kg, rotary inertia about X,
                                                                      # Y, Z as multiples of a steel cube's;
                                                                      # None: none)]


@dataclass(frozen=True)
class PhysicalCause:
    """One row of the cause registry: the cause as the diagnosis sees it (:class:`CauseSpec`: name,
    parameters with their search ranges, the choice, description, advice) and the function that
    applies its parameters to an :class:`Assembly`."""

    spec: CauseSpec
    apply: Callable[[Assembly, Mapping], None]
    #: the set of options its choice takes when not the one named as the choice (every node, member, element,
    #: support or joint): :data:`SIZED_MEMBERS`; the choice's parameter keeps its name (``component``)
    options: str = ""
    #: the frame's own value its first parameter takes as its nominal (the unchanged frame), when not the row's:
    #: :data:`SENSOR_MASS` (the accelerometers' mass of the channel set-up, 0 without mass loading)
    nominal: str = ""


def _added_mass(a: Assembly, p: Mapping) -> None:
    every = float(p.get("inertia_factor", 1.0))
    a.lumped.append((str(p["point"]), float(p["mass_kg"]), tuple(every * float(p.get(f"inertia_{x}", 1.0)) for x in "xyz")))


#: The choice of the spring causes: every support / joint at once, or the one named.
ALL_PLACES = "all"


def _springs(kind: str) -> Callable[[Assembly, Mapping], None]:
    """The springs of one support or joint (``p[kind]``, a node) or of all (``"all"``, or no choice given)."""
    def apply(a: Assembly, p: Mapping) -> None:
        place = p.get(kind, ALL_PLACES)
        where = None if place == ALL_PLACES else str(place)
        for part in ("translational", "rotational"):
            key = (kind, part, where)
            a.springs[key] = a.springs.get(key, 1.0) * float(p.get(f"factor_{part}", 1.0))
    return apply


def _member_mass(a: Assembly, p: Mapping) -> None:
    c = str(p["component"])
    a.mass[c] = a.mass.get(c, 1.0) * float(p["factor"])


def _member_stiffness(a: Assembly, p: Mapping) -> None:
    c = str(p["component"])
    a.bending[c] = a.bending.get(c, 1.0) * float(p["factor"])


def _member_section(a: Assembly, p: Mapping) -> None:
    c = str(p["component"])
    w, d = a.section.get(c, (1.0, 1.0))
    a.section[c] = (w * float(p.get("width_factor", 1.0)), d * float(p.get("depth_factor", 1.0)))


def _element_stiffness(a: Assembly, p: Mapping) -> None:
    e = str(p["element"])
    a.element_bending[e] = a.element_bending.get(e, 1.0) * float(p["factor"])


def _mass_loading(a: Assembly, p: Mapping) -> None:
    a.sensor_mass_kg = float(p["mass_kg"])


def _stiffness_shift(a: Assembly, p: Mapping) -> None:
    a.modulus *= float(p.get("stiffness_factor", 1.0))


#: The sets of options a cause's choice may take beyond those named as the choice (``point``, ``component``,
#: ``element``, ``support``, ``joint``): the members whose section has a width and a depth (:attr:`PhysicalCause.options`).
SIZED_MEMBERS = "sized_members"

#: The frame's own values a cause's first parameter may take as its nominal (:attr:`PhysicalCause.nominal`): the
#: accelerometers' mass (kg) at each output when ``[sensors] mass_loading`` is on, else 0.
SENSOR_MASS = "sensor_mass_kg"

#: The cause registry (factors are dimensionless, masses kg). Adding a cause: one row and its function. A
#: parameter that adds only a mass or only a stiffness as it grows (a positive semi-definite part times a growing
#: coefficient) moves each natural frequency one way only: ``monotone`` (the search bounds a choice by it); a
#: section's width or depth adds both at once and is not.
CAUSES: dict[str, PhysicalCause] = {}


def register_cause(row: PhysicalCause) -> None:
    """Add a row to :data:`CAUSES` (a cause of the same name is replaced)."""
    CAUSES[row.spec.name] = row


for _row in (
    PhysicalCause(CauseSpec(
        "added_mass", (ParamSpec("mass_kg", 0.05, 30.0, nominal=0.0, unit="kg", monotone=True),
                       ParamSpec("inertia_factor", 0.1, 30.0, requires="mass_kg", monotone=True),
                       *(ParamSpec(f"inertia_{x}", 0.005, 50.0, requires="mass_kg", monotone=True) for x in "xyz")),
        choice="point",
        description="a mass fixed on the frame at one node (all three translations), with the rotary inertia of "
                    "a steel cube of that mass about each axis X, Y, Z times inertia_factor and that axis' "
                    "inertia_x, inertia_y, inertia_z (a plate or a bar: more about some axes, less about others)",
        advice="A mass the model lacks sits at the named node (a fixture, a block, cabling): add it to the "
               "model as a lumped mass there, or remove it from the structure."), _added_mass),
    PhysicalCause(CauseSpec(
        "support_stiffness", (ParamSpec("factor_translational", 1e-3, 1e2, monotone=True),
                             ParamSpec("factor_rotational", 1e-3, 1e2, monotone=True)),
        choice="support",
        description="the base supports' springs (all, or the one named), translational and rotational, scaled",
        advice="The named support (all: every support) is softer or stiffer than modelled: check its clamping "
               "(bolts' torque, the foundation) or update its springs by the fitted factors."), _springs("support")),
    PhysicalCause(CauseSpec(
        "joint_stiffness", (ParamSpec("factor_translational", 1e-4, 1e2, monotone=True),
                           ParamSpec("factor_rotational", 1e-3, 1e2, monotone=True)),
        choice="joint",
        description="the column-beam joints' springs (all, or the one named by a node of its pair), translational "
                    "and rotational, scaled",
        advice="The named column-beam joint (all: every joint) is softer or stiffer than modelled: check its bolts "
               "and welds, or update its springs by the fitted factors."), _springs("joint")),
    PhysicalCause(CauseSpec(
        "member_mass", (ParamSpec("factor", 0.5, 2.0, monotone=True),), choice="component",
        description="the mass (density or area) of one member scaled",
        advice="One member is heavier or lighter than modelled: check its section and material, or add the "
               "attached mass spread along it."), _member_mass),
    PhysicalCause(CauseSpec(
        "member_stiffness", (ParamSpec("factor", 0.3, 2.0, monotone=True),), choice="component",
        description="the bending stiffness EI of one member scaled",
        advice="One member bends more or less easily than modelled: check its section (second moments) and "
               "orientation, or update its EI by the fitted factor."), _member_stiffness),
    PhysicalCause(CauseSpec(
        # not monotone: a wider or deeper bar adds mass and stiffness at once (a frequency may go either way).
        # The range sets the search's starting grid (5 points per factor): on 0.5-2 its points lie 26 % apart
        # and a change of 10 % in one side (its second moment's 37 %) was missed from every start in 6 of 40
        # noise-free frames drawn in 0.7-1.43; on 0.6-1.6 (18 % apart) in 1 of 40
        "member_section", (ParamSpec("width_factor", 0.6, 1.6), ParamSpec("depth_factor", 0.6, 1.6)),
        choice="component",
        description="one member made of another bar: its section's width (along the member's local y) and depth "
                    "(local z) scaled, and with them its area (axial stiffness and mass), both second moments "
                    "(each bending plane on its own), its torsion constant and the rotary inertia of its mass "
                    "(a hollow rhs section: its outer width and depth, the wall kept; members of an explicit "
                    "section have no width and depth and are not options)",
        advice="One member is of another bar than modelled: measure its section (width and depth) and check it "
               "against the drawing, or model it with the fitted width and depth."), _member_section,
        options=SIZED_MEMBERS),
    PhysicalCause(CauseSpec(
        "element_stiffness", (ParamSpec("factor", 0.02, 2.0, monotone=True),), choice="element",
        description="the bending stiffness EI of one element scaled (a crack or local damage)",
        advice="One short piece of a member has lost (or gained) bending stiffness: inspect the named element "
               "(between nodes e and e+1) for a crack, a notch, corrosion or a loose attachment."),
        _element_stiffness),
    PhysicalCause(CauseSpec(
        "mass_loading", (ParamSpec("mass_kg", 0.0, 1.0, nominal=None, unit="kg", log=False, monotone=True),),
        description="the accelerometers' mass at every measured output (all three translations)",
        advice="The accelerometers' mass lowers the frequencies: put the sensors' mass at their nodes in the "
               "model (the channel set-up's accelerometer mass), or use lighter sensors."), _mass_loading,
        nominal=SENSOR_MASS),
    PhysicalCause(CauseSpec(
        "stiffness_shift", (ParamSpec("stiffness_factor", 0.6, 1.6, monotone=True),),
        description="the material's Young's modulus scaled (every member; springs unchanged)",
        advice="Every member is stiffer or softer by the same factor: update Young's modulus (or every "
               "section's second moments) by the fitted stiffness factor."), _stiffness_shift),
):
    register_cause(_row)


#: The section shapes with a width and a depth (:func:`simulator.fem.section_properties`): the members
#: ``member_section`` can change.
_SIZED_SHAPES = ("rect", "rhs")


#: The frame's ``[damage]`` table (:class:`simulator.config.DamageConfig`) in the causes' words: each list of
#: places -> (its list of factors, the cause that expresses one such damage, the cause's choice that names the
#: place, the cause's parameters the damage's factor sets). Every kind of damage the simulator can make has a
#: row (``tests/test_damage_causes.py`` walks the table and the fleet's defect kinds).
DAMAGE_CAUSES: dict[str, tuple[str, str, str, tuple[str, ...]]] = {
    "cracked_elements": ("crack_bending_factor", "element_stiffness", "element", ("factor",)),
    "soft_joints": ("soft_joint_factor", "joint_stiffness", "joint", ("factor_translational", "factor_rotational")),
    "loose_supports": ("loose_support_factor", "support_stiffness", "support",
                       ("factor_translational", "factor_rotational")),
}


def damage_changes(damage: DamageConfig) -> list[tuple[str, dict]]:
    """The damage of a frame's ``[damage]`` table as changes ``[(cause, params)]`` of the causes
    (:data:`DAMAGE_CAUSES`): one change per damaged place, its factor (-) on the cause's parameters."""
    out: list[tuple[str, dict]] = []
    for places_field, (factors_field, cause, choice, params) in DAMAGE_CAUSES.items():
        for place, factor in zip(getattr(damage, places_field), getattr(damage, factors_field)):
            out.append((cause, {choice: str(place), **{p: float(factor) for p in params}}))
    return out


#: Candidates' modes kept (:meth:`FrameVariants.modes_of`), the least recently used dropped first: a batch worker's
#: simulation serves every flagged unit of a fleet, and the candidates every unit asks (a screen's grid points) stay
#: while each unit's own come and go.
_MEMO_SIZE = 20000
#: Candidates' modes with their derivatives kept (:meth:`FrameVariants.modes_jac_of`), the least recently used
#: dropped first: the folds of a cross-validation all start from the whole fit's optimum, each asking the same
#: derivatives there.
_JAC_MEMO_SIZE = 256
#: Frames with changes applied as their nominal (:meth:`FrameVariants.on_top`) kept before the store is emptied:
#: each holds four matrices of the frame's size (its K, M, nominal modes and Cholesky factor: 32 bytes per squared
#: degree of freedom) and its reduced spaces; counted in :data:`DIAGNOSIS_BYTES_PER_DOF2`.
#: A search on top of a first cause uses one at a time.
_TOPS_KEPT = 2


def _keep(store: dict, key: tuple, value: Any, size: int) -> None:
    """``store[key] = value`` as the most recently used (last), the least recently used dropped beyond ``size``."""
    store.pop(key, None)
    while len(store) >= size:
        store.pop(next(iter(store)))
    store[key] = value


def _differences(after: Mapping, before: Mapping, h: float) -> dict:
    """The nonzero ``(after - before) / h`` of two coefficient maps (a key missing from one: 0 there)."""
    if after.keys() == before.keys():
        return {q: d for q, a in after.items() if (d := (a - before[q]) / h)}
    return {q: d for q in after.keys() | before.keys() if (d := (after.get(q, 0.0) - before.get(q, 0.0)) / h)}


def _summed(parts: Mapping, coefficients: Mapping) -> np.ndarray:
    """``sum_q c_q parts[q]`` over the (nonempty) ``coefficients``."""
    items = iter(coefficients.items())
    q, c = next(items)
    out = c * parts[q]
    for q, c in items:
        out += c * parts[q]
    return out


def _part(dofs: np.ndarray, block: np.ndarray) -> Part:
    """A part on ``dofs`` trimmed to the DOFs where ``block`` is nonzero."""
    nz = np.flatnonzero(np.any(block != 0, axis=0) | np.any(block != 0, axis=1))
    return Part(np.asarray(dofs)[nz], block[np.ix_(nz, nz)])


#: bytes per squared degree of freedom of the configured model that a diagnosis holds at its peak: the
#: model's parts and matrices with its nominal modes, the copy with every member's elements twice as fine
#: (:meth:`FrameVariants.refined`: four times the squares) that judges the mesh's convergence, the frames on
#: top of first causes (:data:`_TOPS_KEPT`, each with its matrices and modes), and on each frame one reduced
#: space per set of changed parts (its projected matrices only, :class:`simulator.ritz.ReducedSpace`: a
#: number of spaces that grows with the frame's nodes and elements, each of a size set by the modes wanted,
#: not by the frame). Measured (every option's space on the frame and on top of three first causes, the
#: finer copy solved; tracemalloc's peak): 654 and 453 B at 354 and 690 degrees of freedom (the default
#: frame's elements x 2 and x 4), i.e. ~241 B per squared and ~146 kB per degree of freedom: within 400 B
#: from ~900 degrees of freedom on (below, the whole is under ~340 MB); a single eigenproblem takes
#: :data:`simulator.config.FE_BYTES_PER_DOF2`.
DIAGNOSIS_BYTES_PER_DOF2 = 400


def check_diagnosis_size(config: FrameConfig) -> None:
    """Refuse (:class:`simulator.config.ConfigError`, naming the largest accepted total of elements) a
    frame whose diagnosis (:data:`DIAGNOSIS_BYTES_PER_DOF2`) does not fit in the memory one computation
    may use now, before anything of it is built."""
    check_fe_memory(config, DIAGNOSIS_BYTES_PER_DOF2,
                    "a diagnosis (the model, its twice finer copy and their eigenproblems)")


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
        # the frame split into parts (module docstring): K = E sum k_p K_p, M = sum m_q M_q
        self._kparts: dict[tuple, Part] = {}
        self._mparts: dict[tuple, Part] = {}
        elements = []
        #: each member of a rect or rhs section -> its section and the section's properties (member_section)
        self._sections: dict[str, tuple[SectionConfig, SectionProperties]] = {}
        for name, comp in cfg.components.items():
            sec = cfg.sections[comp.section]
            sp = section_properties(sec)
            if sec.shape in _SIZED_SHAPES:
                self._sections[name] = (sec, sp)
            xyz = member_nodes_xyz(comp)
            damage = cfg.damage.bending_factors(name, comp.n_elements)

            def elements_of(s: SectionProperties, bending: Sequence[float] | None = None,
                            xyz: np.ndarray = xyz, roll: float = comp.roll_deg) -> list:
                return element_matrices(xyz, mat.youngs_modulus_pa, G, mat.density_kg_m3, s, roll, bending)

            full = elements_of(sp, damage)
            rest = elements_of(replace(sp, Iy=0.0, Iz=0.0))
            # the grouped parts split by property (a section change scales each on its own): the axial stiffness
            # (its rest the torsion), the bending about local y (its rest in the bending that about z), the
            # rotary inertia of the mass (rho I_p; its rest the translational mass)
            axial = elements_of(replace(sp, Iy=0.0, Iz=0.0, J=0.0))
            about_y = elements_of(replace(sp, Iz=0.0), damage)
            rotary = elements_of(replace(sp, A=0.0))
            first = 6 * self.frame.node_index[(name, 0)]
            size = 6 * (comp.n_elements + 1)
            k_rest, k_bend, m, k_axial, k_y, m_rot = (np.zeros((size, size)) for _ in range(6))
            for e, ((k_e, m_e), (r_e, _), (a_e, _), (y_e, _), (_, mr_e)) in enumerate(
                    zip(full, rest, axial, about_y, rotary)):
                sl = slice(6 * e, 6 * e + 12)
                k_rest[sl, sl] += r_e
                k_bend[sl, sl] += k_e - r_e
                m[sl, sl] += m_e
                k_axial[sl, sl] += a_e
                k_y[sl, sl] += y_e - r_e
                m_rot[sl, sl] += mr_e
                self._kparts[("elem", f"{name}:{e}")] = _part(first + 6 * e + np.arange(12), k_e - r_e)
                self._kparts[("elem_y", f"{name}:{e}")] = _part(first + 6 * e + np.arange(12), y_e - r_e)
                elements.append(f"{name}:{e}")
            dofs = first + np.arange(size)
            self._kparts[("rest", name)] = _part(dofs, k_rest)
            self._kparts[("bend", name)] = _part(dofs, k_bend)
            self._mparts[("mass", name)] = _part(dofs, m)
            self._kparts[("axial", name)] = _part(dofs, k_axial)
            self._kparts[("torsion", name)] = _part(dofs, k_rest - k_axial)
            self._kparts[("bend_y", name)] = _part(dofs, k_y)
            self._kparts[("bend_z", name)] = _part(dofs, k_bend - k_y)
            self._mparts[("mass_rot", name)] = _part(dofs, m_rot)
        self.elements = tuple(elements)
        #: the members whose section has a width and a depth (the options of member_section)
        self.sized_members = tuple(self._sections)
        #: the places of the spring causes' choice: each support by its node, each joint by its pair's first node
        self.places: dict[str, tuple[str, ...]] = {
            "support": tuple(str(a) for a in cfg.supports.nodes), "joint": tuple(str(a) for a, _ in cfg.joints.pairs)}
        #: every node that names a place (a joint by either node of its pair) -> the place
        self._place_of: dict[str, dict[str, str]] = {
            "support": {a: a for a in self.places["support"]},
            "joint": {str(x): str(a) for a, b in cfg.joints.pairs for x in (a, b)}}
        for kind, pairs, k6 in (("support", [(a, None) for a in cfg.supports.nodes], cfg.supports.stiffness),
                                ("joint", list(cfg.joints.pairs), cfg.joints.stiffness)):
            for part, axes in (("translational", slice(0, 3)), ("rotational", slice(3, 6))):
                k = np.zeros(6)
                k[axes] = np.asarray(k6, float)[axes]
                for a, b in pairs:
                    K = np.zeros((n, n))
                    f = cfg.damage.spring_factor(kind, (a,) if b is None else (a, b))
                    stamp_spring(K, self.frame.node(a), None if b is None else self.frame.node(b), k * f)
                    self._kparts[("spring", kind, part, str(a))] = _part(np.arange(n), K)
        self._spring_keys = tuple(key for key in self._kparts if key[0] == "spring")
        #: every member's coefficients of an unchanged assembly, in :meth:`_coefficients`' order (copied per call)
        self._member_k = {key: 1.0 for c in self.components for key in (("rest", c), ("bend", c))}
        self._member_m = {("mass", c): 1.0 for c in self.components}
        index = self.frame.node_index
        self.nodes = tuple(f"{c}:{i}" for (c, i) in sorted(index, key=lambda k: index[k]))
        sens = cfg.sensors
        self.sensor_nodes = tuple(dict.fromkeys(f"{q.component}:{q.node}" for q in map(parse_point, self.outputs)))
        self.sensor_mass_kg = float(sens.accelerometer.mass_kg) if sens.mass_loading else 0.0
        self._node_set = frozenset(self.nodes)
        for node in self.nodes:
            first = 6 * self.frame.node(node)
            self._mparts[("lump", node)] = Part(first + np.arange(3), np.eye(3))
            for i, axis in enumerate("xyz"):
                self._mparts[("rot", node, axis)] = Part(first + np.array([3 + i]), np.eye(1))
        self._refined_frames: dict[int, FrameVariants] = {}
        #: candidates' modes by Rayleigh-Ritz reduction (:mod:`simulator.ritz`); False: the full model
        self.reduced = True
        #: changes applied before every candidate's (:meth:`on_top`): part of this frame's nominal
        self._base: list[tuple[str, dict]] = []
        self._tops: dict[str, FrameVariants] = {}
        self._set_nominal()

    def _set_nominal(self) -> None:
        """The unchanged frame's coefficients and matrices (with the accelerometers); the reduced spaces
        and the kept answers start afresh."""
        self._nominal = self._coefficients([])
        self._K0 = self._assemble(self._kparts, self._nominal[1])
        self._M0 = self._assemble(self._mparts, self._nominal[2])
        self._ritz: RitzReduction | None = None
        self._spaces: dict[tuple, tuple[ReducedSpace | None, np.ndarray | None]] = {}
        self._memo: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
        self._jac_memo: dict[tuple, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}

    # ------------------------------------------------------------------ protocol of the diagnosis
    def causes(self) -> tuple[CauseSpec, ...]:
        """The physical causes with their choices filled in (every node, member, element)."""
        options = {"point": self.nodes, "component": self.components, "element": self.elements,
                   **{kind: (ALL_PLACES, *places) for kind, places in self.places.items()},
                   SIZED_MEMBERS: self.sized_members}
        nominals = {SENSOR_MASS: self.sensor_mass_kg}
        out = []
        for row in CAUSES.values():
            c = row.spec
            if c.choice is not None:
                c = replace(c, options=options[row.options or c.choice],
                            every=ALL_PLACES if c.choice in self.places else None)
            if row.nominal:
                c = replace(c, params=(replace(c.params[0], nominal=nominals[row.nominal]), *c.params[1:]))
            out.append(c)
        return tuple(out)

    def on_top(self, first: Sequence[tuple[str, Mapping]]) -> FrameVariants:
        """This frame with the changes ``first`` applied as its nominal: its ``modes_of(changes)`` are this
        frame's ``modes_of(first + changes)``, with the Ritz bases built on the changed frame, so a candidate
        needs only the basis of its own parts (a crack searched on top of a uniform stiffness change: ~54
        unknowns instead of ~107 for the springs' static responses the uniform change brings). Built once per
        ``first`` (the last :data:`_TOPS_KEPT` kept)."""
        if not first:
            return self
        key = repr([(c, sorted(dict(p).items())) for c, p in first])
        top = self._tops.get(key)
        if top is None:
            top = copy.copy(self)
            top._base = [*self._base, *((c, dict(p)) for c, p in first)]
            top._tops, top._refined_frames = {}, {}
            top._set_nominal()
            if len(self._tops) >= _TOPS_KEPT:
                self._tops.clear()
            self._tops[key] = top
        return top

    def modes(self, cause: str | None, params: Mapping, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """Natural frequencies (Hz, flexible modes up to ``max_freq_hz``) and the shape products
        ``phi_o phi_r`` (n_out * n_ref, n_modes) at the measured points (C order over (o, r))."""
        return self.modes_of(_one(cause, params), max_freq_hz)

    def modes_of(self, changes: Sequence[tuple[str, Mapping]], max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`modes` of the frame changed by every ``(cause, params)`` of ``changes`` at once: by
        Rayleigh-Ritz reduction on a basis for the changed parts (:mod:`simulator.ritz`) when
        :attr:`reduced`, else (and when the basis would not be much smaller) the full model. The answers
        are kept: a candidate asked again is not solved again."""
        key = (tuple((c, tuple(sorted(p.items()))) for c, p in changes), float(max_freq_hz), self.reduced)
        hit = self._memo.get(key)
        if hit is not None:
            _keep(self._memo, key, hit, _MEMO_SIZE)     # the latest used last: the least recently used go first
            return hit
        out = self._modes_reduced(changes, max_freq_hz) if self.reduced and changes else None
        if out is None:
            out = self.exact_modes_of(changes, max_freq_hz)
        for a in out:
            a.setflags(write=False)
        _keep(self._memo, key, out, _MEMO_SIZE)
        return out

    def exact_modes_of(self, changes: Sequence[tuple[str, Mapping]], max_freq_hz: float
                       ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`modes_of` on the full FE model (no reduction)."""
        K, M = self.matrices_of(changes)
        w2, phi = lowest_modes(K, M, (2 * np.pi * max_freq_hz) ** 2)
        f = np.sqrt(w2) / (2 * np.pi)
        return f, self._products(phi)

    def _space_for(self, dk: Mapping, dm: Mapping, n_modes: int | None
                   ) -> tuple[ReducedSpace | None, np.ndarray | None]:
        """The reduced space of the parts ``dk`` / ``dm`` with ``n_modes`` nominal modes (None: the whole model,
        :meth:`simulator.ritz.RitzReduction.whole`), built once, and its basis at the measured points, signed:
        outputs then references (None, None: the full model is solved)."""
        skey = (frozenset(dk), frozenset(dm), n_modes)
        if n_modes is None:                 # the whole model (matrices of the frame's size): the last one kept
            self._spaces = {k: v for k, v in self._spaces.items() if k[2] is not None or k == skey}
        if skey not in self._spaces:
            assert self._ritz is not None
            kp, mp = {q: self._kparts[q] for q in dk}, {q: self._mparts[q] for q in dm}
            pts = self._out + self._ref
            rows = [d for d, _ in pts]
            space = self._ritz.whole(kp, mp, rows) if n_modes is None else self._ritz.space(kp, mp, n_modes, rows)
            at = None if space is None else np.array([s for _, s in pts], float)[:, None] * space.at
            self._spaces[skey] = (space, at)
        return self._spaces[skey]

    def _modes_reduced(self, changes: Sequence[tuple[str, Mapping]], max_freq_hz: float
                       ) -> tuple[np.ndarray, np.ndarray] | None:
        """:meth:`modes_of` in the Ritz space of the changed parts; None when there is none worth using."""
        scale, k, m = self._coefficients(changes)
        dk, dm = self._changed(k, m)
        w2_max = (2 * np.pi * max_freq_hz) ** 2
        if self._ritz is None:
            self._ritz = RitzReduction(self._K0, self._M0)
        space, at = self._space_for(dk, dm, self._ritz.n_modes(w2_max / scale))
        if space is None or at is None:
            return None
        w2, rows = space.eigen_at(dk, dm, scale, w2_max, at)
        n_out = len(self._out)
        f = np.sqrt(w2) / (2 * np.pi)
        return f, (rows[:n_out, None, :] * rows[None, n_out:, :]).reshape(n_out * len(self._ref), -1)

    #: relative step of the forward differences of the parts' coefficients (:meth:`modes_jac_of`): their
    #: error ~1e-7 relative (a rotary inertia's mass^(5/3)), exact for the factors (linear)
    _COEFFICIENT_STEP = 1e-7

    def modes_jac_of(self, changes: Sequence[tuple[str, Mapping]], max_freq_hz: float,
                     wrt: Sequence[tuple[int, str]]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """:meth:`modes_of` with the derivatives of the natural frequencies (Hz per unit of the parameter)
        and of the shape products with respect to the parameters ``wrt`` (``(i, name)``: parameter ``name`` of
        ``changes[i]``): ``(f, P, df, dP)``, ``df`` (n_modes, n_wrt), ``dP`` (n_products, n_modes, n_wrt); None
        without changes. A candidate solved on the full model (not :attr:`reduced`, or no reduced space small
        enough) is differentiated in the basis of every nominal mode, the same way. The answers are kept (the last
        :data:`_JAC_MEMO_SIZE`, read-only): a candidate asked again is not solved again.

        In the Ritz space of every part the parameters move (:mod:`simulator.ritz`), the candidate is
        ``(s K, M)`` with ``K = K0 + sum k_p K_p``, ``M = M0 + sum m_q M_q``; the coefficients ``s, k, m``
        are algebraic in the parameters (their derivatives by central differences of
        :meth:`_coefficients`, exact to ~1e-7). With ``y_i`` M-normalised and ``G = Y^T dK Y``,
        ``H = Y^T dM Y``: ``d lambda_i = G_ii - lambda_i H_ii`` and ``d y_i = sum_(k != i) y_k (G_ki -
        lambda_i H_ki) / (lambda_i - lambda_k) - H_ii y_i / 2`` (the modal expansion, complete in the
        reduced space), ``omega^2 = s lambda``."""
        if not changes:
            return None
        key = (tuple((c, tuple(sorted(p.items()))) for c, p in changes), float(max_freq_hz), self.reduced,
               tuple(wrt))
        hit = self._jac_memo.pop(key, None)
        if hit is None:
            hit = self._modes_jac(changes, max_freq_hz, wrt)
            for a in hit:
                a.setflags(write=False)
        _keep(self._jac_memo, key, hit, _JAC_MEMO_SIZE)
        return hit

    def _modes_jac(self, changes: Sequence[tuple[str, Mapping]], max_freq_hz: float,
                   wrt: Sequence[tuple[int, str]]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`modes_jac_of` solved (not kept)."""
        scale, k, m = self._coefficients(changes)
        dk, dm = self._changed(k, m)
        derivs = []
        for i, name in wrt:
            cause, params = changes[i]
            v = float(params[name])
            h = self._COEFFICIENT_STEP * max(abs(v), 1e-3)
            moved = list(changes)
            moved[i] = (cause, {**params, name: v + h})
            s1, k1, m1 = self._coefficients(moved)
            derivs.append(((s1 - scale) / h, _differences(k1, k, h), _differences(m1, m, h)))
        kset = {q: dk.get(q, 0.0) for q in [*dk, *(q for _, a, _ in derivs for q in a) ]}
        mset = {q: dm.get(q, 0.0) for q in [*dm, *(q for _, _, b in derivs for q in b)]}
        w2_max = (2 * np.pi * max_freq_hz) ** 2
        if self._ritz is None:
            self._ritz = RitzReduction(self._K0, self._M0)
        space, at = self._space_for(kset, mset, self._ritz.n_modes(w2_max / scale)) if self.reduced else (None, None)
        if space is None or at is None:
            space, at = self._space_for(kset, mset, None)
        assert space is not None and at is not None
        lam, Y = space.eigen_all(dk, dm)
        w2 = scale * lam
        keep = np.flatnonzero((w2 > 1.0) & (w2 < w2_max))
        Yk = Y[:, keep]
        lk = lam[keep]
        cols = np.arange(keep.size)
        gap = lk[None, :] - lam[:, None]                        # (r, kept): lambda_i - lambda_k
        gap[keep, cols] = np.inf                                # a mode's own term and equal eigenvalues: none
        gap[gap == 0.0] = np.inf
        inv_gap = 1.0 / gap
        f = np.sqrt(w2[keep]) / (2 * np.pi)
        df = np.empty((keep.size, len(wrt)))
        AY = at @ Y                                             # the Ritz vectors at the measured points
        drows = np.empty((AY.shape[0], keep.size, len(wrt)))
        for j, (ds, dkj, dmj) in enumerate(derivs):
            G = Y.T @ (_summed(space.kparts, dkj) @ Yk) if dkj else np.zeros((lam.size, keep.size))
            if dmj:
                H = Y.T @ (_summed(space.mparts, dmj) @ Yk)
                hii = H[keep, cols]
                dlam = G[keep, cols] - lk * hii
                C = (G - lk[None, :] * H) * inv_gap
                C[keep, cols] = -0.5 * hii
            else:                                               # a stiffness alone: H = 0
                dlam = G[keep, cols]
                C = G * inv_gap
            df[:, j] = (ds * lk + scale * dlam) / (8 * np.pi ** 2 * f)
            drows[:, :, j] = AY @ C
        rows = AY[:, keep]
        n_out, n_ref = len(self._out), len(self._ref)
        P = (rows[:n_out, None, :] * rows[None, n_out:, :]).reshape(n_out * n_ref, -1)
        dP = (drows[:n_out, None] * rows[None, n_out:, :, None]
              + rows[:n_out, None, :, None] * drows[None, n_out:]).reshape(n_out * n_ref, keep.size, len(wrt))
        return f, P, df, dP

    def model(self, cause: str | None, params: Mapping) -> ModalModel:
        """Receptance pole-residue model (m/N) of the changed frame, modes up to ``[modes] max_freq_hz``,
        damping from ``[damping]`` of the config, ``meta["output_shapes"]`` at the outputs."""
        return self.model_of(_one(cause, params))

    def model_of(self, changes: Sequence[tuple[str, Mapping]]) -> ModalModel:
        """:meth:`model` of the frame changed by every ``(cause, params)`` of ``changes`` at once."""
        K, M = self.matrices_of(changes)
        fmax = self.config.modes.max_freq_hz
        w2, phi = lowest_modes(K, M, (2 * np.pi * fmax) ** 2)
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
        other._set_nominal()
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
        scale, k, m = self._coefficients(changes)
        dk, dm = self._changed(k, m)
        K, M = self._K0.copy(), self._M0.copy()
        for key, c in dk.items():
            self._kparts[key].add_to(K, c)
        for key, c in dm.items():
            self._mparts[key].add_to(M, c)
        return scale * K, M

    def _coefficients(self, changes: Sequence[tuple[str, Mapping]]) -> tuple[float, dict, dict]:
        """The frame changed by ``changes`` as coefficients of its parts: ``K = scale sum_p k_p K_p``,
        ``M = sum_q m_q M_q`` (``scale`` the modulus factor; the springs' coefficients are divided by it)."""
        a = Assembly()
        for cause, params in [*self._base, *changes]:
            if cause not in CAUSES:
                raise ModelError(f"unknown physical cause {cause!r}; the registry has {', '.join(CAUSES)}")
            CAUSES[cause].apply(a, params)
        E = a.modulus
        k: dict[tuple, float] = self._member_k.copy()
        m: dict[tuple, float] = self._member_m.copy()
        for c, b in a.bending.items():            # a member's factors (one that is not the frame's: none)
            if ("bend", c) in k:
                k[("bend", c)] = b
        for c, mc in a.mass.items():
            if ("mass", c) in m:
                m[("mass", c)] = mc
        ratios: dict[str, tuple[float, float, float, float, float]] = {}
        for c, (w, d) in a.section.items():
            ratios[c] = r_area, r_j, r_iy, r_iz, r_ip = self._section_ratios(c, w, d)
            b, mc = a.bending.get(c, 1.0), a.mass.get(c, 1.0)
            # the new section's part of each property, as changes of the grouped parts (unchanged: none)
            for piece, coefficient in ((("axial", c), r_area - 1.0), (("torsion", c), r_j - 1.0),
                                       (("bend_y", c), b * (r_iy - 1.0)), (("bend_z", c), b * (r_iz - 1.0))):
                if coefficient:
                    k[piece] = coefficient
            m[("mass", c)] = mc * r_area
            if r_ip != r_area:
                m[("mass_rot", c)] = mc * (r_ip - r_area)
        for e, f in a.element_bending.items():
            if ("elem", e) not in self._kparts:
                raise ModelError(f"element {e!r} is not on the frame; its elements are {', '.join(self.elements)}")
            c = e.partition(":")[0]
            crack = a.bending.get(c, 1.0) * (float(f) - 1.0)
            if c in ratios:       # on a member of another section: each bending plane's own second moment
                r_iy, r_iz = ratios[c][2:4]
                k[("elem", e)] = crack * r_iz
                if r_iy != r_iz:
                    k[("elem_y", e)] = crack * (r_iy - r_iz)
            else:
                k[("elem", e)] = crack
        k.update(self._spring_coefficients(a.springs, E))
        sensor_mass = self.sensor_mass_kg if a.sensor_mass_kg is None else a.sensor_mass_kg
        lumped = [(node, sensor_mass, None) for node in self.sensor_nodes] + list(a.lumped)
        for node, mass, rotary in lumped:
            if mass < 0:
                raise ModelError(f"a mass of {mass} kg at {node}: masses must be >= 0")
            node = node if node in self._node_set else self.nodes[self.frame.node(node)]  # validates, names
            m[("lump", node)] = m.get(("lump", node), 0.0) + mass
            if rotary is not None:
                # a compact steel block centred on the node: m a^2 / 6 about each axis, a = (m / rho)^(1/3),
                # times each axis' factor (a plate or a bar of the same mass has more about some axes)
                side = (mass / self.config.material.density_kg_m3) ** (1.0 / 3.0)
                for axis, factor in zip("xyz", rotary):
                    m[("rot", node, axis)] = m.get(("rot", node, axis), 0.0) + float(factor) * mass * side * side / 6.0
        return E, k, m

    def _spring_coefficients(self, springs: Mapping, E: float) -> dict:
        """The springs' coefficients of an assembly whose spring factors are ``springs`` (``(kind, part, where)``:
        ``where`` None for every place of the kind), divided by the modulus factor ``E``."""
        if not springs:                           # every spring unchanged: 1.0 * 1.0 / E
            return dict.fromkeys(self._spring_keys, 1.0 / E)
        local: dict[tuple, float] = {}
        for (kind, part, where), f in springs.items():
            if where is not None:
                place = self._place_of[kind].get(where)
                if place is None:
                    raise ModelError(f"{where!r} is not a {kind} of the frame; its {kind}s are "
                                     f"{', '.join(self.places[kind])} (or {ALL_PLACES!r})")
                local[(kind, part, place)] = local.get((kind, part, place), 1.0) * float(f)
        out = {}
        for key in self._spring_keys:
            kind, part, place = key[1:]
            out[key] = springs.get((kind, part, None), 1.0) * local.get((kind, part, place), 1.0) / E
        return out

    def _section_ratios(self, member: str, width: float, depth: float) -> tuple[float, float, float, float, float]:
        """The section of ``member`` with its width and depth times ``width``, ``depth`` (rhs: its outer ones,
        the wall kept), by :func:`simulator.fem.section_properties`: its area, torsion constant, second moments
        about local y and z and polar moment, each relative to the configured section's (-)."""
        if member not in self._sections:
            shape = self.config.sections[self.config.components[member].section].shape \
                if member in self.config.components else None
            raise ModelError(f"member_section of {member!r}: " + (
                f"its section is {shape!r}, which has no width and depth to scale; the cause applies to members "
                f"of a {' or '.join(map(repr, _SIZED_SHAPES))} section ({', '.join(self.sized_members) or 'none'})"
                if shape is not None else f"not a member of the frame; its members are {', '.join(self.components)}"))
        if width <= 0 or depth <= 0:
            raise ModelError(f"member_section of {member!r}: width and depth factors must be > 0, got {width}, {depth}")
        sec, sp = self._sections[member]
        new = section_properties(replace(sec, width_m=sec.width_m * width, depth_m=sec.depth_m * depth))
        return new.A / sp.A, new.J / sp.J, new.Iy / sp.Iy, new.Iz / sp.Iz, new.Ip / sp.Ip

    def _changed(self, k: dict, m: dict) -> tuple[dict, dict]:
        """The coefficients' changes from the unchanged frame's (only the parts that change)."""
        _, k0, m0 = self._nominal
        dk = {key: c - c0 for key, c in k.items() if c != (c0 := k0.get(key, 0.0))}
        dm = {key: c - c0 for key, c in m.items() if c != (c0 := m0.get(key, 0.0))}
        dm.update({key: -c for key, c in m0.items() if key not in m})
        return dk, dm

    def _assemble(self, parts: dict, coefficients: dict) -> np.ndarray:
        A = np.zeros((self.frame.n_dof, self.frame.n_dof))
        for key, c in coefficients.items():
            parts[key].add_to(A, c)
        return A

    def _shapes_at(self, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed mode-shape values at the outputs (n_out, n_modes) and references (n_ref, n_modes)."""
        return (np.array([s * phi[d] for d, s in self._out]), np.array([s * phi[d] for d, s in self._ref]))

    def _products(self, phi: np.ndarray) -> np.ndarray:
        po, pr = self._shapes_at(phi)
        return np.einsum("om,rm->orm", po, pr).reshape(len(self._out) * len(self._ref), -1)

