"""The diagnosis with the simulation as an FRF file, on FRF sets made by a generator that shares no
code with it (``benchmarks/accuracy/frf_beam_cases.py``: a continuous pinned beam solved by dynamic
stiffness, hysteretic and dashpot damping, sensors as point masses, UFF 58 written with pyuff). A few
cases of the benchmark ``bench_diagnosis_frf_files.py``: a mass at one sensor named at that sensor
through the driving point, and a test without a driving point that says which point to measure."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from benchmark_modules import load_benchmark

from analysis.diagnosis import diagnose

beam = load_benchmark("accuracy/frf_beam_cases.py")
CASES = beam.draw_cases()
# the effects a sensor's mass competes with (the full catalogue runs in the benchmark)
EFFECTS = ["mass_loading", "stiffness_shift", "damping_change", "sensitivity_error", "missing_mode"]


def test_generator_beam_is_the_continuous_pinned_beam() -> None:
    """The segment's dynamic stiffness tends to the static beam stiffness as omega -> 0, and the beam's
    resonances are the pinned-pinned beam's ``n^2 pi / (2 L^2) sqrt(EI / rho A)``."""
    EI, rhoA, h = 300.0, 2.5, 0.3
    static = EI / h ** 3 * np.array([[12, 6 * h, -12, 6 * h], [6 * h, 4 * h * h, -6 * h, 2 * h * h],
                                     [-12, -6 * h, 12, -6 * h], [6 * h, 2 * h * h, -6 * h, 4 * h * h]])
    np.testing.assert_allclose(beam.segment_stiffness(EI, rhoA, 1e-3, h), static, rtol=1e-8, atol=1e-8 * static.max())
    b = beam.Beam(length=1.2, EI=EI, rhoA=rhoA, eta=1e-4, dashpot_at=0.5, dashpot=0.0)
    for fn in beam.pinned_frequencies(b, 3):
        f = np.linspace(0.98 * fn, 1.02 * fn, 401)
        H = np.abs(beam.beam_accelerance(b, (0.37,), 0.37, f)[0])
        assert f[int(np.argmax(H))] == pytest.approx(fn, rel=2e-4)


@pytest.mark.parametrize("index", [3])
def test_mass_at_one_sensor_from_an_frf_file_with_a_driving_point(index: int, tmp_path: Path) -> None:
    case = CASES[index]
    assert case.family == "mass_one"
    sim, meas = beam.write_case(case, tmp_path)
    d = diagnose(meas, sim, effects=EFFECTS)
    assert d.verdict == "mass_loading", d.causes[:3]
    got = d.named[0]["parameters"]
    assert got["sensor"] == f"n:{case.truth['sensor'] + 1}:Z"
    assert got["mass_kg"] == pytest.approx(case.truth["mass_kg"], rel=0.25)


def test_without_a_driving_point_the_verdict_names_the_point_to_measure(tmp_path: Path) -> None:
    case = next(c for c in CASES if c.family == "mass_one_nodp")
    sim, meas = beam.write_case(case, tmp_path)
    d = diagnose(meas, sim, effects=EFFECTS)
    hammer = f"n:{beam.node_numbers(case)[1]}:Z"
    assert d.verdict != "mass_loading"
    assert "driving point" in d.skipped["mass_loading"] and hammer in d.skipped["mass_loading"]
    if d.verdict != "none":
        assert hammer in d.reason and "driving point" in d.reason
