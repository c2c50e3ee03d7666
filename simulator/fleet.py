"""A production fleet of frames: manufacturing scatter and a few defective units.

Each unit is the default frame (``simulator/frame.toml``) with its own material and spring values,
each drawn uniformly within +-``scatter`` (a fraction) of the nominal value:

- Young's modulus and density of the steel (one value per unit: a batch of material);
- the six stiffnesses of the joints and of the supports (one factor each per unit: the assembly).

``defects`` units (chosen at random) also carry ONE physical defect, written in the config's
``[damage]`` table so the finite-element model itself is changed (not a formula on the FRFs):

- ``soft_joint``: one column-to-beam joint keeps ``factor`` (0.05..0.2) of its spring stiffnesses;
- ``cracked_member``: one element (``element``, ``component:e``) keeps ``factor`` (0.3..0.6) of its
  bending stiffness, a crack as a local loss of bending stiffness;
- ``loose_support``: one base support keeps ``factor`` (0.1..0.3) of its spring stiffnesses.

Everything is drawn from one seed, so the same arguments give the same fleet. This module only
plans (config overrides and the truth); ``simulator.cli_fleet`` captures each unit through the
simulated analyser.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .config import FrameConfig, overrides_to_toml

__all__ = ["DEFECT_KINDS", "UnitSpec", "plan_fleet", "unit_overrides", "fleet_folder_conflict",
           "recorded_plan"]

#: defect kind -> (range of its factor, what it is)
DEFECT_KINDS: dict[str, tuple[tuple[float, float], str]] = {
    "soft_joint": ((0.05, 0.2), "a column-to-beam joint keeps this fraction of its spring stiffnesses"),
    "cracked_member": ((0.3, 0.6), "one element keeps this fraction of its bending stiffness (a crack)"),
    "loose_support": ((0.1, 0.3), "a base support keeps this fraction of its spring stiffnesses"),
}


@dataclass(frozen=True)
class UnitSpec:
    """One unit of the fleet: its name, the capture seed, the scatter factors (-) and its defect."""

    name: str
    seed: int
    scatter: dict[str, float]
    defect: dict[str, Any] | None = None
    overrides: dict[str, Any] = field(default_factory=dict, repr=False)

    def truth(self, file: str) -> dict[str, Any]:
        """This unit's entry of ``truth.json``."""
        return {"name": self.name, "file": file, "defect": self.defect, "scatter": self.scatter}


def unit_overrides(scatter: dict[str, float], defect: dict[str, Any] | None,
                   base: FrameConfig | None = None) -> dict[str, Any]:
    """Config overrides (shaped like frame.toml) of a unit with these scatter factors and defect."""
    cfg = base or FrameConfig.load()
    over: dict[str, Any] = {
        "material": {"youngs_modulus_pa": cfg.material.youngs_modulus_pa * scatter["modulus"],
                     "density_kg_m3": cfg.material.density_kg_m3 * scatter["density"]},
        "joints": {"stiffness": [k * scatter["joint_stiffness"] for k in cfg.joints.stiffness]},
        "supports": {"stiffness": [k * scatter["support_stiffness"] for k in cfg.supports.stiffness]},
    }
    if defect is not None:
        kind, f = defect["kind"], float(defect["factor"])
        if kind == "soft_joint":
            over["damage"] = {"soft_joints": [defect["joint"]], "soft_joint_factor": [f]}
        elif kind == "cracked_member":
            over["damage"] = {"cracked_elements": [defect["element"]], "crack_bending_factor": [f]}
        elif kind == "loose_support":
            over["damage"] = {"loose_supports": [defect["support"]], "loose_support_factor": [f]}
        else:
            raise ValueError(f"unknown defect kind {kind!r}; known: {', '.join(DEFECT_KINDS)}")
    return over


def _defect(kind: str, rng: np.random.Generator, cfg: FrameConfig) -> dict[str, Any]:
    lo, hi = DEFECT_KINDS[kind][0]
    factor = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
    if kind == "soft_joint":
        pair = cfg.joints.pairs[int(rng.integers(len(cfg.joints.pairs)))]
        return {"kind": kind, "joint": str(pair[0]), "factor": factor}
    if kind == "loose_support":
        return {"kind": kind, "support": str(cfg.supports.nodes[int(rng.integers(len(cfg.supports.nodes)))]),
                "factor": factor}
    comp = str(rng.choice(sorted(cfg.components)))
    n = cfg.components[comp].n_elements
    # a crack away from the member's ends (the joints and supports are their own defects)
    return {"kind": kind, "element": f"{comp}:{int(rng.integers(1, n - 1))}", "factor": factor}


def plan_fleet(units: int, scatter: float = 0.02, defects: int = 0, seed: int = 0,
               kinds: tuple[str, ...] = tuple(DEFECT_KINDS)) -> list[UnitSpec]:
    """The fleet's units ``unit-001`` ... : scatter within +-``scatter`` (fraction, e.g. 0.02 for 2 %)
    and ``defects`` defective units, their kinds taken in turn from ``kinds`` at random places."""
    if units < 1:
        raise ValueError(f"--units {units}: a fleet needs at least one unit")
    if not 0 <= defects <= units:
        raise ValueError(f"--defects {defects}: give 0..{units} (no more defective units than units)")
    if not 0 <= scatter < 0.5:
        raise ValueError(f"--scatter {100 * scatter:g} %: give a percentage in 0..50")
    unknown = [k for k in kinds if k not in DEFECT_KINDS]
    if unknown or not kinds:
        raise ValueError(f"defect kinds {unknown or '(none)'}: choose from {', '.join(DEFECT_KINDS)}")
    rng = np.random.default_rng(seed)
    cfg = FrameConfig.load()
    width = max(3, len(str(units)))
    bad = set(rng.choice(units, size=defects, replace=False).tolist()) if defects else set()
    order = list(rng.permutation(sorted(bad)))
    kind_of = {int(u): kinds[i % len(kinds)] for i, u in enumerate(order)}
    out = []
    for u in range(units):
        sc = {k: float(1.0 + rng.uniform(-scatter, scatter))
              for k in ("modulus", "density", "joint_stiffness", "support_stiffness")}
        defect = _defect(kind_of[u], rng, cfg) if u in kind_of else None
        out.append(UnitSpec(name=f"unit-{u + 1:0{width}d}", seed=int(rng.integers(1, 2 ** 31 - 1)), scatter=sc,
                            defect=defect, overrides=unit_overrides(sc, defect, cfg)))
    return out


def fleet_folder_conflict(out_dir: str | Path, specs: list[UnitSpec]) -> str | None:
    """Why the recordings already in ``out_dir`` are not units of the fleet ``specs`` (None when
    they all are): a unit recorded with another config (other ``--units``, ``--scatter``,
    ``--defects`` or ``--seed``), or a recording the plan does not hold. Completing such a folder
    would write a ``truth.json`` that does not describe its recordings."""
    out = Path(out_dir)
    planned = {s.name: s for s in specs}
    for h5 in sorted(out.glob("unit-*.h5")):
        name = h5.stem
        spec = planned.get(name)
        if spec is None:
            return f"{h5.name} is not a unit of this fleet of {len(specs)}"
        cfg = out / "configs" / f"{name}.toml"
        try:
            recorded = cfg.read_text(encoding="utf-8")
        except OSError:
            return f"{h5.name} has no config {cfg} to tell which unit it is"
        if recorded != overrides_to_toml(spec.overrides):
            return f"{h5.name} was recorded from another unit config than this plan's {name}"
    return None


def recorded_plan(out_dir: str | Path) -> str:
    """The options a fleet folder was made with, as its ``truth.json`` records them ('' when unknown)."""
    try:
        truth = json.loads((Path(out_dir) / "truth.json").read_text(encoding="utf-8"))
        units = truth.get("units", [])
        defects = truth.get("defects", sum(u.get("defect") is not None for u in units))
        return (f"--units {len(units)} --defects {defects} --scatter {truth['scatter_pct']:g} "
                f"--seed {truth['seed']}" + (f" --hits {truth['hits']}" if "hits" in truth else ""))
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return ""
