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

The causes (names and parameters fixed: tests, the JSON and users key on them):

=====================  ===========================================  =======================================
name                   parameters                                   change
=====================  ===========================================  =======================================
``added_mass``         ``point`` (node ``component:node``),          lumped mass on the node's translations
                       ``mass_kg``                                  and a steel cube's rotary inertia
``support_stiffness``  ``factor_translational``, ``factor_rotational``  support springs x factor
``joint_stiffness``    ``factor_translational``, ``factor_rotational``  column-beam joint springs x factor
``member_mass``        ``component``, ``factor``                     density (mass) of one member x factor
``member_stiffness``   ``component``, ``factor``                     bending stiffness EI of one member x factor
``mass_loading``       ``mass_kg`` (each accelerometer)              accelerometer mass at every output node
``stiffness_shift``    ``stiffness_factor`` (and ``factor`` =        Young's modulus x stiffness_factor (all
                       its square root, the frequency ratio)         members; springs unchanged)
=====================  ===========================================  =======================================

:class:`FrameVariants` answers the protocol of :mod:`analysis.diagnosis.physical` (``causes``,
``modes``, ``model``); it lives here because only the simulator knows the frame, and the diagnosis
sees only containers.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import scipy.linalg

from analysis.diagnosis.physical import CauseSpec, ParamSpec
from analysis.modal import ModalModel, pole_from_fz
from analysis.points import parse_point

from .config import FrameConfig
from .fem import FrameModel, ModelError, assemble_beam, member_nodes_xyz, section_properties, stamp_spring

__all__ = ["FrameVariants", "CAUSES"]

#: The physical causes and their search ranges (factors are dimensionless, masses kg).
CAUSES: tuple[CauseSpec, ...] = (
    CauseSpec("added_mass", (ParamSpec("mass_kg", 0.05, 30.0, nominal=0.0, unit="kg"),), choice="point",
              description="a mass fixed on the frame at one node (all three translations)"),
    CauseSpec("support_stiffness", (ParamSpec("factor_translational", 1e-3, 1e2),
                                    ParamSpec("factor_rotational", 1e-2, 1e2)),
              description="the base supports' springs, translational and rotational, scaled"),
    CauseSpec("joint_stiffness", (ParamSpec("factor_translational", 1e-4, 1e2),
                                  ParamSpec("factor_rotational", 1e-3, 1e2)),
              description="the column-beam joints' springs, translational and rotational, scaled"),
    CauseSpec("member_mass", (ParamSpec("factor", 0.5, 2.0),), choice="component",
              description="the mass (density or area) of one member scaled"),
    CauseSpec("member_stiffness", (ParamSpec("factor", 0.3, 2.0),), choice="component",
              description="the bending stiffness EI of one member scaled"),
    CauseSpec("mass_loading", (ParamSpec("mass_kg", 0.0, 1.0, nominal=None, unit="kg", log=False),),
              description="the accelerometers' mass at every measured output (all three translations)"),
    CauseSpec("stiffness_shift", (ParamSpec("stiffness_factor", 0.6, 1.6),),
              description="the material's Young's modulus scaled (every member; springs unchanged)"),
)


def _config(config: "FrameConfig | str | Path | None") -> FrameConfig:
    return config if isinstance(config, FrameConfig) else FrameConfig.load(config)


class FrameVariants:
    """The frame of ``config`` at the measured ``outputs`` / ``references``, split into parts.

    ``modes(cause, params, max_freq_hz)`` gives the natural frequencies (Hz) and the shape products at
    the measured points; ``model(cause, params)`` the receptance pole-residue model (m/N, all modes up
    to ``[modes] max_freq_hz``) with ``meta["output_shapes"]``, like :func:`simulator.effects.base_model`
    but with the channel set-up's accelerometer masses. ``cause=None`` is the frame as configured.
    """

    def __init__(self, config: "FrameConfig | str | Path | None", outputs: Sequence[str],
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
        self._M: dict[str, np.ndarray] = {}
        for name, comp in cfg.components.items():
            sp = section_properties(cfg.sections[comp.section])
            xyz = member_nodes_xyz(comp)
            k_all, m = assemble_beam(xyz, mat.youngs_modulus_pa, G, mat.density_kg_m3, sp, comp.roll_deg,
                                     cfg.damage.bending_factors(name, comp.n_elements))
            k_rest, _ = assemble_beam(xyz, mat.youngs_modulus_pa, G, mat.density_kg_m3,
                                      replace(sp, Iy=0.0, Iz=0.0), comp.roll_deg)
            first = 6 * self.frame.node_index[(name, 0)]
            sl = slice(first, first + k_all.shape[0])
            for store, block in ((self._K_rest, k_rest), (self._K_bend, k_all - k_rest), (self._M, m)):
                full = np.zeros((n, n))
                full[sl, sl] = block
                store[name] = full
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
        """The physical causes with their choices filled in (every node, every member)."""
        out = []
        for c in CAUSES:
            if c.choice == "point":
                c = replace(c, options=self.nodes)
            elif c.choice == "component":
                c = replace(c, options=self.components)
            elif c.name == "mass_loading":
                c = replace(c, params=(replace(c.params[0], nominal=self.sensor_mass_kg),))
            out.append(c)
        return tuple(out)

    def modes(self, cause: "str | None", params: Mapping, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """Natural frequencies (Hz, flexible modes up to ``max_freq_hz``) and the shape products
        ``phi_o phi_r`` (n_out * n_ref, n_modes) at the measured points (C order over (o, r))."""
        K, M = self.matrices(cause, params)
        w2, phi = scipy.linalg.eigh(K, M, subset_by_value=(1.0, (2 * np.pi * max_freq_hz) ** 2))
        f = np.sqrt(w2) / (2 * np.pi)
        return f, self._products(phi)

    def model(self, cause: "str | None", params: Mapping) -> ModalModel:
        """Receptance pole-residue model (m/N) of the changed frame, modes up to ``[modes] max_freq_hz``,
        damping from ``[damping]`` of the config, ``meta["output_shapes"]`` at the outputs."""
        K, M = self.matrices(cause, params)
        fmax = self.config.modes.max_freq_hz
        w2, phi = scipy.linalg.eigh(K, M, subset_by_value=(1.0, (2 * np.pi * fmax) ** 2))
        f = np.sqrt(w2) / (2 * np.pi)
        zeta = self.config.damping.ratios(f)
        lam = pole_from_fz(f, zeta)
        po, pr = self._shapes_at(phi)
        pp = np.einsum("om,rm->orm", po, pr)
        R = pp / (2j * np.imag(lam))[None, None, :]
        return ModalModel(poles=lam, residues=R, quantity="receptance", residual_form="none",
                          outputs=self.outputs, references=self.references,
                          meta={"source": "simulator.physical", "cause": cause, "parameters": dict(params),
                                "output_shapes": po})

    def refined(self, refine: int = 2) -> "FrameVariants":
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
    def matrices(self, cause: "str | None", params: Mapping) -> tuple[np.ndarray, np.ndarray]:
        """K (N/m, N m/rad) and M (kg, kg m^2) of the frame changed by ``cause`` with ``params``."""
        p = dict(params)
        E = float(p.get("stiffness_factor", 1.0)) if cause == "stiffness_shift" else 1.0
        n = self.frame.n_dof
        K, M = np.zeros((n, n)), np.zeros((n, n))
        for c in self.components:
            K += E * self._K_rest[c]
            K += E * self._bend_factor(cause, p, c) * self._K_bend[c]
            M += self._mass_factor(cause, p, c) * self._M[c]
        for kind in ("support", "joint"):
            ft, fr = 1.0, 1.0
            if cause == f"{kind}_stiffness":
                ft, fr = float(p.get("factor_translational", 1.0)), float(p.get("factor_rotational", 1.0))
            K += ft * self._springs[(kind, "translational")]
            K += fr * self._springs[(kind, "rotational")]
        sensor_mass = float(p["mass_kg"]) if cause == "mass_loading" else self.sensor_mass_kg
        for node in self.sensor_nodes:
            self._lump(M, node, sensor_mass)
        if cause == "added_mass":
            self._lump(M, str(p["point"]), float(p["mass_kg"]), rotary=True)
        return K, M

    @staticmethod
    def _bend_factor(cause: "str | None", p: dict, component: str) -> float:
        return float(p["factor"]) if cause == "member_stiffness" and p.get("component") == component else 1.0

    @staticmethod
    def _mass_factor(cause: "str | None", p: dict, component: str) -> float:
        return float(p["factor"]) if cause == "member_mass" and p.get("component") == component else 1.0

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

