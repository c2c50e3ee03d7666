"""Fleet statistics of resonance inspection (analysis.batch.fleet) against known truth, no Dask.

Units are made from a reference mode set by a common scale (material scatter), fit noise, and for
the defective ones a local pattern of shifts; the flags must find exactly the defective ones and
name the modes. The FE-level defects themselves (simulator [damage]) are checked at the end.
"""
from __future__ import annotations

import numpy as np
import pytest

from analysis.batch.fleet import assess_fleet, median_unit, pair_modes, robust_center_spread
from analysis.batch.unit_modes import UnitModes, modes_from_fit

REF_F = np.array([12.9, 35.1, 128.2, 160.0, 161.0, 198.8, 283.4, 413.7, 445.8, 452.7, 525.2])


def _shapes(n_modes: int, rng: np.random.Generator) -> np.ndarray:
    return rng.normal(size=(3, n_modes)) + 1j * rng.normal(size=(3, n_modes)) * 0.05


SHAPES = _shapes(REF_F.size, np.random.default_rng(0))


def _unit(freq: np.ndarray, rng: np.random.Generator, shapes: np.ndarray = SHAPES, drop: tuple = ()) -> UnitModes:
    keep = [k for k in range(freq.size) if k not in drop]
    f = freq[keep] * (1 + rng.normal(0, 1e-4, len(keep)))
    return UnitModes(freq_hz=f, damping=np.full(len(keep), 0.005), freq_std_hz=f * 1e-4,
                     damping_std=np.full(len(keep), 1e-4),
                     shapes=(shapes[:, keep] + 0.01 * rng.normal(size=(3, len(keep)))).astype(complex),
                     outputs=("a:1:X", "b:2:Y", "c:3:Z"))


def _fleet(n: int, defective: dict[int, dict[int, float]], seed: int = 1, drop: dict[int, tuple] | None = None):
    drop = drop or {}
    rng = np.random.default_rng(seed)
    units = []
    for u in range(n):
        scale = 1 + rng.uniform(-0.014, 0.014)               # modulus/density scatter: all modes alike
        f = REF_F * scale
        for k, shift in defective.get(u, {}).items():
            f[k] *= 1 + shift
        units.append(_unit(f, rng, drop=drop.get(u, ())))
    return units


def test_robust_center_spread_ignores_a_tenth_of_outliers():
    x = np.random.default_rng(2).normal(3.0, 0.5, 900)
    m, s = robust_center_spread(np.concatenate([x, np.full(100, 50.0)]))
    assert abs(m - 3.0) < 0.1 and abs(s - 0.5) < 0.1
    assert np.isnan(robust_center_spread(np.array([np.nan]))[0])


def test_pairing_follows_the_common_shift_and_skips_missing_modes():
    rng = np.random.default_rng(3)
    ref = _unit(REF_F, rng)
    # 1.5 % stiffer everywhere, mode 4 (160 Hz of the close pair) missing, a spurious mode added
    f = np.append(np.delete(REF_F, 3) * 1.015, 300.0)
    shapes = np.append(np.delete(SHAPES, 3, axis=1), rng.normal(size=(3, 1)), axis=1)
    order = np.argsort(f)
    unit = UnitModes(freq_hz=f[order], damping=np.full(f.size, 0.005), freq_std_hz=f[order] * 1e-4,
                     damping_std=np.full(f.size, 1e-4), shapes=shapes[:, order].astype(complex), outputs=ref.outputs)
    p = pair_modes(ref, unit)
    assert p.index[3] == -1                                     # the missing mode pairs with nothing
    paired = [k for k in range(REF_F.size) if k != 3]
    assert np.allclose(unit.freq_hz[p.index[paired]] / ref.freq_hz[paired], 1.015, rtol=1e-3)
    assert abs(p.common_shift - np.log(1.015)) < 1e-3
    assert np.all(p.mac[paired] > 0.9)
    assert 300.0 not in unit.freq_hz[p.index[p.index >= 0]]


def test_flags_exactly_the_defective_units_and_names_the_modes():
    defective = {4: {5: -0.02, 7: +0.01}, 17: {1: -0.03}, 33: {9: -0.012, 10: -0.008}}
    units = _fleet(60, defective, drop={8: (0,), 21: (6,)})    # two good units miss a weak mode
    names = [f"unit-{i:03d}" for i in range(len(units))]
    res = assess_fleet(units, names, [n + ".h5" for n in names])
    flagged = {u.name for u in res.units if u.flagged}
    assert flagged == {"unit-004", "unit-017", "unit-033"}
    by = {u.name: u for u in res.units}
    assert any(r.startswith("mode 6 (") and "-2.0" in r for r in by["unit-004"].reasons)
    assert any(r.startswith("mode 2 (") for r in by["unit-017"].reasons)
    assert by["unit-008"].notes and "not found" in by["unit-008"].notes[0]   # a note, not a flag
    # the reference is a good unit near the middle of the material scatter
    assert res.reference not in flagged
    assert all(m.assessed for m in res.modes)


def test_reference_fit_and_error_rows():
    units: list = _fleet(12, {2: {3: -0.03, 4: -0.03}})
    units[5] = None
    names = [f"u{i}" for i in range(12)]
    ref = _unit(REF_F, np.random.default_rng(9))
    res = assess_fleet(units, names, names, reference=ref, reference_name="golden.json",
                       errors=[None] * 5 + ["OSError: unreadable"] + [None] * 6)
    assert res.reference == "golden.json"
    assert [u.name for u in res.units if u.flagged] == ["u2"]
    bad = res.units[5]
    assert bad.status == "error" and bad.error == "OSError: unreadable" and not bad.flagged


def test_a_uniform_shift_far_outside_the_fleet_is_flagged():
    units = _fleet(40, {})
    units[7] = UnitModes(units[7].freq_hz * 1.08, units[7].damping, units[7].freq_std_hz, units[7].damping_std,
                         units[7].shapes, units[7].outputs)
    names = [f"u{i}" for i in range(40)]
    res = assess_fleet(units, names, names)
    assert [u.name for u in res.units if u.flagged] == ["u7"]
    assert "every mode" in res.units[7].reasons[0]


def test_median_unit_is_central():
    rng = np.random.default_rng(4)
    units = [_unit(REF_F * s, rng) for s in (0.98, 0.99, 1.0, 1.01, 1.02)]
    assert median_unit(units) == 2
    with pytest.raises(ValueError, match="no unit"):
        median_unit([UnitModes(*(np.zeros(0),) * 4, np.zeros((3, 0)), ("a", "b", "c"))])


def test_modes_from_fit_reads_the_fit_json_sorted():
    doc = {"outputs": ["a", "b"], "references": ["a"],
           "poles": [{"freq_hz": 20.0, "damping": 0.01, "freq_hz_std": 0.1, "damping_std": 0.001},
                     {"freq_hz": 10.0, "damping": 0.02, "freq_hz_std": 0.2, "damping_std": None}],
           "mode_shapes": [{"output": "a", "values": [[1, 0], [0, 1]]}, {"output": "b", "values": [[2, 0], [0, 2]]}]}
    m = modes_from_fit(doc)
    assert m.freq_hz.tolist() == [10.0, 20.0] and m.damping.tolist() == [0.02, 0.01]
    assert np.isnan(m.damping_std[0])
    assert np.allclose(m.shapes[:, 0], [1j, 2j]) and np.allclose(m.shapes[:, 1], [1, 2])


# ---------------------------------------------------------------------------- the defects in the FE model
def test_damage_config_changes_the_frame_locally():
    from simulator.config import ConfigError, FrameConfig
    from simulator.fem import FrameModel
    from simulator.fleet import plan_fleet, unit_overrides

    base = FrameConfig.load()
    f0 = FrameModel.from_config(base).modes(600.0).freq_hz
    same = base.with_overrides({"damage": {"cracked_elements": ["top:3"], "crack_bending_factor": [1.0]}})
    assert np.allclose(FrameModel.from_config(same).modes(600.0).freq_hz, f0, rtol=1e-12)
    for over in ({"damage": {"cracked_elements": ["top:3"], "crack_bending_factor": [0.3]}},
                 {"damage": {"soft_joints": ["right:10"], "soft_joint_factor": [0.05]}},
                 {"damage": {"loose_supports": ["left:0"], "loose_support_factor": [0.1]}}):
        f = FrameModel.from_config(base.with_overrides(over)).modes(600.0).freq_hz
        n = min(f.size, f0.size)
        assert np.all(f[:n] <= f0[:n] * (1 + 1e-9))           # softer: no mode goes up
        d = np.log(f[:n] / f0[:n])
        assert np.ptp(d) > 0.01                                   # and not all alike: a local pattern
    with pytest.raises(ConfigError, match="same length"):
        base.with_overrides({"damage": {"soft_joints": ["right:10"]}})
    with pytest.raises(ConfigError, match="not a node of any"):
        base.with_overrides({"damage": {"soft_joints": ["top:4"], "soft_joint_factor": [0.5]}})
    # the fleet plan is reproducible and its defects are what the truth says
    a, b = plan_fleet(20, 0.02, 3, seed=5), plan_fleet(20, 0.02, 3, seed=5)
    assert [u.overrides for u in a] == [u.overrides for u in b]
    bad = [u for u in a if u.defect]
    assert len(bad) == 3 and {u.defect["kind"] for u in bad} == {"soft_joint", "cracked_member", "loose_support"}
    assert all(0.98 <= v <= 1.02 for u in a for v in u.scatter.values())
    assert unit_overrides(bad[0].scatter, bad[0].defect) == bad[0].overrides
    with pytest.raises(ValueError, match="--defects"):
        plan_fleet(3, 0.02, 4)
