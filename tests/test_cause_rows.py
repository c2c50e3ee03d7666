"""A cause's behaviour is its registry row's: a row that asks for the simulation's own value as its first parameter's
nominal (the accelerometers' mass) or for its range scaled to the model gets it, whatever its name.

Each test adds a row of a name no code knows (``cable_mass``) to the registry for the test only and checks that the
simulation's ``causes()`` gives it the row's behaviour; the existing rows' answers are those of the mass tests.
"""
from __future__ import annotations

from pathlib import Path

import pytest
from fe_chain import write_chain

from analysis.diagnosis.physical import CauseSpec, ParamSpec
from analysis.fe_model import FE_CAUSES, MODEL_MASS, FECause, FEVariants, load_fe_model
from analysis.fe_model import SENSOR_MASS as FE_SENSOR_MASS
from simulator.config import FrameConfig
from simulator.physical import CAUSES, SENSOR_MASS, FrameVariants, PhysicalCause

OUTS = ["left:9:Y", "top:4:X", "right:6:-X"]
REFS = ["right:6:-X"]


def _cable(a: object, p: object) -> None:
    """The test row's change (never applied here)."""


def _frame_row(nominal: str) -> PhysicalCause:
    return PhysicalCause(CauseSpec("cable_mass", (ParamSpec("mass_kg", 0.0, 2.0, nominal=0.5, unit="kg", log=False),
                                                  ParamSpec("spread", 0.1, 10.0))), _cable, nominal=nominal)


def test_a_frame_row_asking_for_the_sensor_mass_gets_it_as_its_nominal(monkeypatch) -> None:
    """A row with ``nominal = SENSOR_MASS`` takes the channel set-up's accelerometer mass (0 with mass loading off);
    its other parameters are left as the row gives them; the same row without it keeps its own nominal."""
    monkeypatch.setitem(CAUSES, "cable_mass", _frame_row(SENSOR_MASS))
    cfg = FrameConfig.load()
    loaded = {c.name: c for c in FrameVariants(None, OUTS, REFS).causes()}
    accel = cfg.sensors.accelerometer.mass_kg
    assert accel > 0 and cfg.sensors.mass_loading
    assert loaded["cable_mass"].params[0].nominal == pytest.approx(accel)
    assert loaded["cable_mass"].params[1] == ParamSpec("spread", 0.1, 10.0)
    # the accelerometers' own cause gets the same value from its row
    assert loaded["mass_loading"].params[0].nominal == pytest.approx(accel)
    bare = {c.name: c for c in FrameVariants(cfg.with_overrides({"sensors": {"mass_loading": False}}),
                                             OUTS, REFS).causes()}
    assert bare["cable_mass"].params[0].nominal == 0.0
    monkeypatch.setitem(CAUSES, "cable_mass", _frame_row(""))
    own = {c.name: c for c in FrameVariants(None, OUTS, REFS).causes()}
    assert own["cable_mass"].params[0].nominal == 0.5


def test_an_fe_row_scaled_to_the_model_with_the_sensor_mass_as_nominal(monkeypatch, tmp_path: Path) -> None:
    """On a user's FE model a row with ``scale = MODEL_MASS`` has its first parameter's range in multiples of the
    model's mass, and with ``nominal = SENSOR_MASS`` the sensors' mass as its nominal, the range's top at least twice
    it; the same row with neither keeps its range and nominal."""
    toml = write_chain(tmp_path, 6, zeta=0.02)
    toml.write_text(toml.read_text() + "\n[sensors]\nmass_kg = 4.0\n")
    fe = load_fe_model(toml)
    assert fe.sensor_mass_kg == 4.0 and fe.total_mass_kg() == pytest.approx(6.0)
    spec = CauseSpec("cable_mass", (ParamSpec("mass_kg", 0.01, 1.0, nominal=None, unit="kg", log=False),))
    monkeypatch.setitem(FE_CAUSES, "cable_mass", FECause(spec, lambda c, p: None, scale=MODEL_MASS,
                                                         nominal=FE_SENSOR_MASS))
    sim = FEVariants(fe, ["n:2:Z"], ["n:6:Z"], max_freq_hz=400.0)
    got = {c.name: c for c in sim.causes()}["cable_mass"].params[0]
    assert (got.lo, got.nominal) == (pytest.approx(0.06), 4.0)
    assert got.hi == pytest.approx(8.0)          # 1.0 x 6 kg, raised to twice the sensors' 4 kg
    monkeypatch.setitem(FE_CAUSES, "cable_mass", FECause(spec, lambda c, p: None))
    plain = {c.name: c for c in sim.causes()}["cable_mass"].params[0]
    assert (plain.lo, plain.hi, plain.nominal) == (0.01, 1.0, None)
