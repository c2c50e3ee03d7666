"""Every damage the simulator can make has a cause of the diagnosis that expresses it, at every place.

The simulator's damage kinds are the lists of places of the frame's ``[damage]`` table
(:class:`simulator.config.DamageConfig`) and the defect kinds of a production fleet
(:data:`simulator.fleet.DEFECT_KINDS`). For each kind, at every place the simulator accepts, the frame
assembled from the damaged configuration must equal the unchanged frame changed by the diagnosis' cause
(:data:`simulator.physical.DAMAGE_CAUSES`), and the place must be one of the cause's options (what the
diagnosis searches and names). A new damage kind without a cause, or a cause that loses a place, fails here.
"""
from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest

from simulator.config import DamageConfig, FrameConfig
from simulator.fem import FrameModel, ModelError
from simulator.fleet import DEFECT_KINDS, plan_fleet
from simulator.physical import DAMAGE_CAUSES, FrameVariants, damage_changes

OUTS = ["left:9:Y", "top:4:X", "right:4:-Z"]
REFS = ["top:4:Z"]


def _places(cfg: FrameConfig, places_field: str) -> list[str]:
    """Every place the simulator accepts in the ``[damage]`` list ``places_field``."""
    if places_field == "cracked_elements":
        return [f"{c}:{e}" for c, comp in cfg.components.items() for e in range(comp.n_elements)]
    if places_field == "soft_joints":
        return [str(n) for pair in cfg.joints.pairs for n in pair]
    if places_field == "loose_supports":
        return [str(n) for n in cfg.supports.nodes]
    raise AssertionError(f"[damage] {places_field}: the test does not know its places; add them here and a row "
                         f"of simulator.physical.DAMAGE_CAUSES")


def _assert_expressed(base: FrameConfig, damaged: FrameConfig, fv: FrameVariants) -> list[tuple[str, dict]]:
    """The damaged frame's K and M equal the unchanged frame changed by the causes of its damage, and each
    cause's place is among the cause's options; returns the changes."""
    changes = damage_changes(damaged.damage)
    assert changes, f"damage {damaged.damage} gives no change of any cause"
    options = {c.name: (c.choice, c.options) for c in fv.causes()}
    for cause, params in changes:
        choice, opts = options[cause]
        place = params[choice]
        # the option the diagnosis names for this place (a joint by the first node of its pair)
        named = next((a for a, b in base.joints.pairs if place in (a, b)), place) if choice == "joint" else place
        assert named in opts, f"{cause} cannot name {place!r}: its options are {opts}"
    masses = {":".join(p.split(":")[:2]): base.sensors.accelerometer.mass_kg for p in OUTS}
    ref = FrameModel.from_config(damaged, masses)
    K, M = fv.matrices_of(changes)
    np.testing.assert_allclose(K, ref.K, rtol=0, atol=1e-9 * np.abs(ref.K).max())
    np.testing.assert_allclose(M, ref.M, rtol=0, atol=1e-12 * np.abs(ref.M).max())
    return changes


def test_every_damage_field_has_a_cause() -> None:
    """Each list of places of ``[damage]`` has a row of DAMAGE_CAUSES and each row names a list and its factors."""
    names = {f.name for f in fields(DamageConfig)}
    covered = set(DAMAGE_CAUSES) | {row[0] for row in DAMAGE_CAUSES.values()}
    assert names == covered, f"[damage] fields without a cause: {sorted(names - covered)}; " \
                             f"rows without a field: {sorted(covered - names)}"


@pytest.mark.parametrize("places_field", sorted(DAMAGE_CAUSES))
def test_each_damage_kind_at_every_place_is_a_cause(places_field: str) -> None:
    base = FrameConfig.load()
    fv = FrameVariants(base, OUTS, REFS)
    factors_field = DAMAGE_CAUSES[places_field][0]
    for place in _places(base, places_field):
        damaged = base.with_overrides({"damage": {places_field: [place], factors_field: [0.1]}})
        _assert_expressed(base, damaged, fv)


def test_two_damages_at_once_are_the_two_causes() -> None:
    base = FrameConfig.load()
    damaged = base.with_overrides({"damage": {"loose_supports": ["right:0"], "loose_support_factor": [0.25],
                                              "soft_joints": ["top:0"], "soft_joint_factor": [0.05]}})
    changes = _assert_expressed(base, damaged, FrameVariants(base, OUTS, REFS))
    assert sorted(c for c, _ in changes) == ["joint_stiffness", "support_stiffness"]


@pytest.mark.parametrize("kind", sorted(DEFECT_KINDS))
def test_each_fleet_defect_kind_is_a_cause(kind: str) -> None:
    """A fleet's defective units (every defect kind, at the places the fleet draws) are causes of the diagnosis."""
    base = FrameConfig.load()
    fv = FrameVariants(base, OUTS, REFS)
    units = plan_fleet(8, scatter=0.0, defects=8, seed=3, kinds=(kind,))
    for u in units:
        _assert_expressed(base, base.with_overrides(u.overrides), fv)


def test_a_place_that_is_not_on_the_frame_is_refused() -> None:
    fv = FrameVariants(None, OUTS, REFS)
    with pytest.raises(ModelError, match="not a support of the frame"):
        fv.matrices("support_stiffness", {"support": "top:3", "factor_rotational": 0.5})
    with pytest.raises(ModelError, match="not a joint of the frame"):
        fv.matrices("joint_stiffness", {"joint": "left:3", "factor_rotational": 0.5})


def test_all_places_equal_every_place_at_once() -> None:
    """``all`` (the default when no place is given) is every support changed by the same factors."""
    fv = FrameVariants(None, OUTS, REFS)
    p = {"factor_translational": 0.3, "factor_rotational": 0.2}
    K_all, _ = fv.matrices("support_stiffness", {"support": "all", **p})
    K_default, _ = fv.matrices("support_stiffness", p)
    K_each, _ = fv.matrices_of([("support_stiffness", {"support": s, **p}) for s in fv.places["support"]])
    np.testing.assert_array_equal(K_all, K_default)
    np.testing.assert_allclose(K_all, K_each, rtol=0, atol=1e-12 * np.abs(K_all).max())
