"""The fleet's scatter in a flagged unit's diagnosis (:mod:`analysis.batch.scatter`): each unit's common
frequency factor from the modes the fleet finds normal in it, and the SIM seen at that factor."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from analysis.batch.fleet import assess_fleet, pair_modes
from analysis.batch.scatter import ScaledSimulation, normal_centre, scaled, unit_frequency_factors
from analysis.batch.unit_modes import UnitModes
from analysis.modal import ModalModel, pole_from_fz, synthesize


class Chain:
    """A 3-mass spring chain as a physical simulation: the cause ``spring`` scales the middle spring."""

    outputs = ("a:1:X", "a:2:X", "a:3:X")
    references = ("a:1:X",)

    def __init__(self, stiffness: float = 1.0) -> None:
        self.stiffness = stiffness
        self.asked: list[float] = []

    def causes(self) -> tuple:
        return ()

    def _eig(self, params: dict) -> tuple[np.ndarray, np.ndarray]:
        k = 4e4 * self.stiffness * np.array([1.0, float(params.get("factor", 1.0)), 1.0])
        K = np.array([[k[0] + k[1], -k[1], 0], [-k[1], k[1] + k[2], -k[2]], [0, -k[2], k[2]]])
        w2, phi = scipy.linalg.eigh(K, np.diag([1.0, 2.0, 1.5]))
        return np.sqrt(w2) / (2 * np.pi), phi

    def modes(self, cause: str | None, params: dict, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        self.asked.append(max_freq_hz)
        f, phi = self._eig(params)
        keep = f <= max_freq_hz
        return f[keep], (phi[:, None, :] * phi[None, :1, :]).reshape(3, -1)[:, keep]

    def model(self, cause: str | None, params: dict) -> ModalModel:
        f, phi = self._eig(params)
        lam = pole_from_fz(f, 0.01)
        R = phi[:, None, :] * phi[None, :1, :] / (2j * lam.imag)[None, None, :]
        return ModalModel(poles=lam, residues=R, quantity="receptance", outputs=self.outputs,
                          references=self.references)

    def first_pass(self, *args: object) -> None:       # a method the scaled simulation cannot scale
        raise AssertionError("not to be called")


def test_a_scaled_simulation_is_the_same_frame_with_its_stiffness_times_the_factor_squared():
    s = 1.013
    plain, stiff = ScaledSimulation(Chain(), s), Chain(stiffness=s ** 2)
    f, P = plain.modes("spring", {"factor": 0.6}, 1e4)
    f2, P2 = stiff.modes("spring", {"factor": 0.6}, 1e4)
    np.testing.assert_allclose(f, f2, rtol=1e-12)
    np.testing.assert_allclose(P, P2, rtol=1e-12)
    # the band asked for is the scaled frame's: a mode just above max_freq_hz / s stays out
    top = float(f[1]) * 0.999
    assert plain.modes("spring", {"factor": 0.6}, top)[0].size == 1
    lines = np.linspace(5.0, 60.0, 400)
    np.testing.assert_allclose(synthesize(plain.model("spring", {"factor": 0.6}), lines).H,
                               synthesize(stiff.model("spring", {"factor": 0.6}), lines).H, rtol=1e-9)
    # a model in accelerance form is scaled as the stiffer frame's accelerance
    accel = plain._scaled_model(_accelerance(Chain().model(None, {})))
    np.testing.assert_allclose(synthesize(accel, lines).H,
                               synthesize(_accelerance(stiff.model(None, {})), lines).H, rtol=1e-9)
    assert not hasattr(plain, "first_pass")             # not offered: its bounds would be the unscaled frame's
    assert plain.outputs == Chain.outputs


def _accelerance(m: ModalModel) -> ModalModel:
    """A receptance model's modes in accelerance form (residues times lambda^2, no residual terms)."""
    from dataclasses import replace

    return replace(m, residues=np.asarray(m.residues) * np.asarray(m.poles)[None, None, :] ** 2, quantity="accelerance")


def test_scaled_leaves_an_frf_file_and_a_factor_of_one_alone():
    sim = Chain()
    assert scaled(sim, 1.0) is sim
    assert scaled(Path("golden.h5"), 1.02) == Path("golden.h5")
    assert isinstance(scaled(sim, 1.02), ScaledSimulation)
    with pytest.raises(ValueError, match="factor"):
        ScaledSimulation(sim, 0.0)


def test_the_normal_centre_leaves_out_the_modes_a_defect_moved():
    # five modes at the unit's scatter (+0.30 %, each within the fleet's 0.02 % spread), six moved by a defect
    rng = np.random.default_rng(3)
    normal = 0.003 + 0.0001 * rng.standard_normal(5)
    moved = np.array([-0.021, -0.014, -0.009, -0.006, -0.004, -0.002])
    shift = np.concatenate([moved[:3], normal, moved[3:]])
    centre, size = normal_centre(shift, np.full(shift.size, 0.0002))
    assert size == 5
    assert centre == pytest.approx(float(np.mean(normal)), abs=5e-5)
    assert abs(float(np.median(shift)) - 0.003) > 0.003          # the median is the defect's, not the scatter's
    assert normal_centre(np.full(4, np.nan), np.full(4, 0.001)) == (0.0, 0)


def _unit(f: np.ndarray) -> UnitModes:
    nan = np.full(f.size, np.nan)
    shapes = np.eye(f.size, dtype=complex) + 0.05                 # distinct shapes: every MAC pairs its own
    return UnitModes(freq_hz=f, damping=np.full(f.size, 0.01), freq_std_hz=1e-5 * f, damping_std=nan,
                     shapes=shapes, outputs=tuple(f"a:{i}:X" for i in range(f.size)))


def _fleet(scatter: np.ndarray, defect: np.ndarray | None = None, wrong: float | None = None):
    f0 = np.array([12.0, 35.0, 50.0, 128.0, 160.0, 199.0, 284.0, 440.0, 454.0, 520.0, 610.0])
    rng = np.random.default_rng(7)
    units = [_unit(f0 * g * (1 + 0.0002 * rng.standard_normal(f0.size))) for g in scatter]
    if defect is not None:
        units.append(_unit(f0 * 1.006 * np.exp(defect)))
    if wrong is not None:
        units.append(_unit(f0 * wrong))
    names = [f"unit-{i + 1:03d}" for i in range(len(units))]
    return _unit(f0 * 0.998), units, assess_fleet(units, names, [n + ".h5" for n in names])


def test_a_units_factor_is_its_scatter_not_its_defect_and_stays_within_the_fleets():
    scatter = 1 + np.linspace(-0.01, 0.01, 9)
    moved = np.zeros(11)
    moved[[0, 1, 3, 4, 6, 7]] = [-0.02, -0.012, -0.03, -0.008, -0.016, -0.025]   # a defect moves six of 11 modes
    sim, units, fleet = _fleet(scatter, moved, wrong=1.08)
    ref = units[[u.name for u in fleet.units].index(fleet.reference)]
    factors = unit_frequency_factors(sim, ref, fleet)
    flags = {u.name: u.flagged for u in fleet.units}
    assert flags["unit-010"] and flags["unit-011"] and not any(flags[f"unit-{i:03d}"] for i in range(1, 10))
    # the good units: their own factor against the SIM (built 0.2 % below the fleet's design)
    np.testing.assert_allclose(factors[:9], scatter / 0.998, rtol=3e-4)
    # the defective unit: its scatter (x1.006), where the median over its modes is the defect's
    assert factors[9] == pytest.approx(1.006 / 0.998, rel=3e-4)
    assert abs(np.exp(pair_modes(sim, units[9]).common_shift) - 1.006 / 0.998) > 0.005
    # a unit off as a whole beyond the fleet's scatter keeps the excess to be diagnosed
    assert 1.01 / 0.998 < factors[10] < 1.04 / 0.998


def test_without_enough_good_units_the_sim_is_taken_as_it_is():
    sim, units, fleet = _fleet(1 + np.array([-0.01, 0.0, 0.01]), wrong=1.08)
    ref = units[[u.name for u in fleet.units].index(fleet.reference)]
    assert unit_frequency_factors(sim, ref, fleet) == [1.0] * 4
