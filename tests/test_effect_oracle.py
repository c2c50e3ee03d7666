"""The diagnosis' registries own their rows: every row has its level and its test-oracle row
(``simulator.effect_oracle``), each physical range names a parameter the row really has, and the
range-edge veto is read from the rows."""
from __future__ import annotations

import numpy as np
import pytest

from analysis.diagnosis.effect_types import LEVELS
from analysis.diagnosis.effects import EFFECTS, predict
from analysis.diagnosis.timedata import TIME_EFFECTS
from simulator.effect_oracle import (
    DRAW_RANGES,
    FRF_ORACLE,
    TIME_DRAW_RANGES,
    TIME_ORACLE,
    TIME_TOLERANCES,
    TOLERANCES,
    draw_effect,
    draw_time_effect,
    primary_error,
    time_primary_error,
)
from simulator.effects import base_model

OUTS = ["left:9:Y", "top:4:X", "right:6:-X"]
REFS = ["right:6:-X"]


def test_every_registry_row_has_its_oracle_row_and_the_reverse() -> None:
    assert set(FRF_ORACLE) == set(EFFECTS)
    assert set(DRAW_RANGES) == set(TOLERANCES) == set(EFFECTS)
    assert set(TIME_ORACLE) == set(TIME_EFFECTS)
    assert set(TIME_DRAW_RANGES) == set(TIME_TOLERANCES) == set(TIME_EFFECTS)
    assert all(r.tolerance >= 0 and r.draws for r in [*FRF_ORACLE.values(), *TIME_ORACLE.values()])


def test_every_row_carries_its_level() -> None:
    from simulator.physical import CAUSES

    assert {e.level for e in EFFECTS.values()} == {"frf"}
    assert {e.level for e in TIME_EFFECTS.values()} == {"time"}
    assert {c.spec.level for c in CAUSES.values()} == {"physical"}
    assert set(LEVELS) == {"frf", "physical", "time"}


@pytest.fixture(scope="module")
def base():
    return base_model(None, OUTS, REFS, max_freq_hz=800.0)


@pytest.mark.parametrize("name", list(EFFECTS))
def test_each_draw_is_an_effect_its_row_applies_and_its_own_error_is_zero(name: str, base) -> None:
    f = np.arange(3.0, 200.0, 0.5)
    eff = draw_effect(name, np.random.default_rng(7), base, f)
    assert eff["effect"] == name
    H = predict(base, f, "accelerance", [eff], outputs=OUTS, references=REFS).H
    assert np.all(np.isfinite(H)) and H.shape == (len(OUTS), len(REFS), f.size)
    params = {k: v for k, v in eff.items() if k != "effect"}
    assert primary_error(eff, params) == 0.0
    # a range a row declares names a parameter the effect really has
    assert all(r.name in params for r in EFFECTS[name].ranges)
    # drawn inside its physical range: a drawn effect is never vetoed as at the edge
    assert EFFECTS[name].at_range_edge(params, (float(f[0]), float(f[-1]))) == ""


@pytest.mark.parametrize("name", list(TIME_EFFECTS))
def test_each_time_draw_is_scored_zero_against_itself(name: str) -> None:
    eff = draw_time_effect(name, np.random.default_rng(3))
    assert eff["effect"] == name
    assert time_primary_error(eff, eff, 8) == 0.0


def test_the_range_edge_veto_comes_from_the_rows() -> None:
    band = (10.0, 500.0)
    assert EFFECTS["damping_change"].at_range_edge({"factor": 10.0}) == "the damping factor"
    assert EFFECTS["damping_change"].at_range_edge({"factor": 0.1}) == "the damping factor"
    assert EFFECTS["damping_change"].at_range_edge({"factor": 2.0}) == ""
    assert EFFECTS["sensitivity_error"].at_range_edge({"gains": {"a": 1.0, "b": -3.0}}) == "a channel's gain"
    assert EFFECTS["sensitivity_error"].at_range_edge({"gains": {"a": 1.2}}) == ""
    assert EFFECTS["local_resonator"].at_range_edge({"frequency_hz": 500.0}, band) == "the resonator's own frequency"
    assert EFFECTS["local_resonator"].at_range_edge({"frequency_hz": 500.0}) == ""     # no band: no range
    assert EFFECTS["stiffness_shift"].at_range_edge({"factor": 10.0}) == ""            # no range declared
