"""The accelerometers' mass named when the simulation is an FRF file, from a driving point.

The data come from a generator that shares nothing with the catalogue: a chain of lumped masses and
springs with a damping matrix, solved per frequency line (``(K + j w C - w^2 M)^-1``); the sensors'
mass is added to M at the measured outputs. The diagnosis sees only the FRFs of the chain without the
sensors (the "simulation file") and those with them (the "measurement").
"""
from __future__ import annotations

import numpy as np
import pytest

from analysis.diagnosis import diagnose
from analysis.diagnosis.entry import driving_point_shapes
from analysis.frf import FRFSet
from analysis.modal import ModalModel, pole_from_fz

MASSES = np.array([2.0, 1.5, 1.0, 1.2])          # kg
SPRINGS = np.array([4e5, 3e5, 2e5, 2.5e5])        # N/m, the first to ground
FREQ = np.linspace(5.0, 250.0, 1600)


def chain_frfs(outputs: list[int], reference: int, sensor_kg: float, seed: int) -> FRFSet:
    """Accelerance of the chain at ``outputs`` from ``reference`` (DOF indices), each output carrying
    ``sensor_kg``; complex noise of 0.1 % of |H| per line."""
    n = MASSES.size
    K = np.zeros((n, n))
    for i, k in enumerate(SPRINGS):
        K[i, i] += k
        if i > 0:
            K[i - 1, i - 1] += k
            K[i - 1, i] -= k
            K[i, i - 1] -= k
    M = np.diag(MASSES.copy())
    C = 2e-5 * K + 1.5 * M                          # Rayleigh damping, not the catalogue's modal form
    M[outputs, outputs] += sensor_kg                # a sensor adds mass, no damping
    w = 2 * np.pi * FREQ
    H = np.empty((len(outputs), 1, FREQ.size), complex)
    for k, wk in enumerate(w):
        x = np.linalg.solve(K + 1j * wk * C - wk ** 2 * M, np.eye(n)[:, reference])
        H[:, 0, k] = -wk ** 2 * x[outputs]
    rng = np.random.default_rng(seed)
    H *= 1 + 1e-3 * (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)) / np.sqrt(2)
    return FRFSet(freq_hz=FREQ, H=H, quantity="accelerance", outputs=tuple(f"chain:{i}:X" for i in outputs),
                  references=(f"chain:{reference}:X",), unit="(m/s^2)/N")


def test_driving_point_scales_residues_to_mass_normalised_shapes() -> None:
    phi = np.array([[0.5, -0.3], [0.4, 0.6], [-0.2, 0.7]])          # 1/sqrt(kg), outputs x modes
    lam = pole_from_fz(np.array([40.0, 90.0]), np.array([0.01, 0.02]))
    for quantity, p in (("receptance", 0), ("accelerance", 2)):
        R = (phi[:, None, :] * phi[None, [1], :]) / (2j * lam.imag) * lam ** p
        model = ModalModel(poles=lam, residues=R, quantity=quantity, residual_form="none",
                           outputs=("a:0:X", "a:1:X", "a:2:X"), references=("a:1:X",))
        got = driving_point_shapes(model)
        assert got is not None
        np.testing.assert_allclose(np.abs(got), np.abs(phi), rtol=1e-12)
        np.testing.assert_allclose(got[:, 0] * got[1, 0], phi[:, 0] * phi[1, 0], rtol=1e-12)


def test_mass_at_one_sensor_or_all_is_exact_in_a_complete_modal_space() -> None:
    """With every mode of a 3-mass chain in the model and its shapes at every mass, the re-analysis of
    ``mass_loading`` is the eigen-solution of the chain with the mass added: frequencies and residues."""
    from scipy.linalg import eigh

    from analysis.diagnosis.effects import EFFECTS
    from analysis.modal import natural_freq_hz

    K = np.array([[7e5, -3e5, 0.0], [-3e5, 5e5, -2e5], [0.0, -2e5, 2e5]])
    M = np.diag([2.0, 1.5, 1.0])
    labels = ("c:0:X", "c:1:X", "c:2:X")

    def model(mass: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        w2, phi = eigh(K, mass)
        lam = 1j * np.sqrt(w2)
        return lam, phi[:, None, :] * phi[None, [1], :] / (2j * lam.imag)

    lam, R = model(M)
    base = ModalModel(poles=lam, residues=R * lam ** 2, quantity="accelerance", residual_form="none",
                      outputs=labels, references=("c:1:X",), meta={"output_shapes": eigh(K, M)[1]})
    for sensor, added in (("c:2:X", np.diag([0.0, 0.0, 0.4])), ("all", 0.25 * np.eye(3))):
        got = EFFECTS["mass_loading"].apply(base, {"mass_kg": float(added.max()), "sensor": sensor})
        want_lam, want_R = model(M + added)
        np.testing.assert_allclose(natural_freq_hz(got.poles), natural_freq_hz(want_lam), rtol=1e-10)
        np.testing.assert_allclose(got.residues, want_R * want_lam ** 2, rtol=1e-8, atol=1e-12 * np.abs(want_R).max())


@pytest.mark.parametrize("sensor_kg, seed", [(0.06, 1), (0.12, 2)])
def test_sensor_mass_named_from_an_frf_file_with_a_driving_point(sensor_kg: float, seed: int) -> None:
    outputs, ref = [1, 2, 3], 1
    sim = chain_frfs(outputs, ref, 0.0, seed + 100)
    meas = chain_frfs(outputs, ref, sensor_kg, seed)
    d = diagnose(meas, sim, effects=["mass_loading", "stiffness_shift", "damping_change", "missing_mode"])
    assert d.verdict == "mass_loading", d.causes[:3]
    assert d.named[0]["parameters"]["mass_kg"] == pytest.approx(sensor_kg, rel=0.25)


def test_without_a_driving_point_the_diagnosis_says_what_is_missing() -> None:
    outputs, ref = [1, 2, 3], 0
    d = diagnose(chain_frfs(outputs, ref, 0.1, 3), chain_frfs(outputs, ref, 0.0, 4), effects=["mass_loading"])
    assert "mass_loading" in d.skipped
    assert "driving point" in d.skipped["mass_loading"]
    assert d.verdict != "mass_loading"
