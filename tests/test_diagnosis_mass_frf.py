"""A sensor's mass on a simulation given as FRFs: the fixed part of the FRFs moves with the modes.

Exact data, made by another model than the mass formula: a chain of ten lumped masses and springs
(fixed at both ends) solved per line, ``(K + j w C - w^2 M)^-1``, with Rayleigh damping; the band holds
its first four modes, the other six lie above it. The simulation is the chain's FRFs to one driving
point; its modal model is what an LSFD fit of them in accelerance makes (in-band poles, constant residual
terms), as for a simulation read from a file. The measurement is the chain with a mass added at one
output, as a heavy accelerometer would be.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import eigh

from analysis.diagnosis.compare import line_weights
from analysis.diagnosis.effects import predict
from analysis.diagnosis.entry import model_with_correction
from analysis.diagnosis.mass_frf import FRFMassLoading
from analysis.frf import FRFSet
from analysis.lsfd import fit_lsfd
from analysis.modal import ModalModel, transfer

MASSES = np.array([1.0, 1.3, 0.9, 1.2, 1.0, 0.8, 1.1, 1.4, 0.9, 1.0])     # kg
SPRINGS = np.array([4e5, 3e5, 5e5, 3.5e5, 4.5e5, 3e5, 4e5, 5e5, 3.5e5, 4e5, 3e5])   # N/m, ends to ground
OUTS, DRIVE = [1, 3, 4, 7, 8], 3                    # chain masses measured; the hammer at mass 3
LABELS = tuple(f"chain:{i}:X" for i in OUTS)


def _chain(extra_kg: float = 0.0, at: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = MASSES.size
    K = np.zeros((n, n))
    for i, k in enumerate(SPRINGS):
        for a in (i - 1, i):
            if 0 <= a < n:
                K[a, a] += k
        if 1 <= i < n:
            K[i - 1, i] -= k
            K[i, i - 1] -= k
    M = np.diag(MASSES).copy()
    C = 2e-6 * K + 0.5 * M
    M[at, at] += extra_kg
    return K, C, M


def _frfs(freq: np.ndarray, extra_kg: float = 0.0, at: int = 0, quantity: str = "accelerance") -> FRFSet:
    K, C, M = _chain(extra_kg, at)
    H = np.empty((len(OUTS), 1, freq.size), complex)
    for k, w in enumerate(2 * np.pi * freq):
        x = np.linalg.solve(K + 1j * w * C - w ** 2 * M, np.eye(MASSES.size)[:, DRIVE])
        H[:, 0, k] = x[OUTS] * (-(w ** 2) if quantity == "accelerance" else 1.0)
    unit = "(m/s^2)/N" if quantity == "accelerance" else "m/N"
    return FRFSet(freq_hz=freq, H=H, quantity=quantity, outputs=LABELS, references=(f"chain:{DRIVE}:X",), unit=unit)


def _setup() -> tuple[np.ndarray, FRFSet, object, np.ndarray]:
    K, _, M = _chain()
    fn = np.sqrt(eigh(K, M, eigvals_only=True)) / (2 * np.pi)
    freq = np.linspace(0.3 * fn[0], 0.5 * (fn[3] + fn[4]), 1200)          # four modes in the band
    sim = _frfs(freq)
    _, C, _ = _chain()
    w2, V = eigh(K, M)
    zeta = np.einsum("ir,ij,jr->r", V, C, V) / (2 * np.sqrt(w2))
    start = np.sqrt(w2[:4]) * (-zeta[:4] * 1.3 + 1j)                       # a fit's start, not the answer
    fit = fit_lsfd(sim, start, residual_form="physical")
    return freq, sim, fit.model, fn


def _relative_error(freq: np.ndarray, base: object, extra: float, at: int) -> float:
    """The loaded chain against the prediction with the true mass, over the mass's own effect (weighted)."""
    measured = _frfs(freq, extra, at)
    label = f"chain:{at}:X"
    H = predict(base, freq, "accelerance", [{"effect": "mass_loading", "mass_kg": extra, "sensor": label}]).H
    unloaded = predict(base, freq, "accelerance").H
    w = line_weights(measured)
    return float(np.sum(w * np.abs(measured.H - H) ** 2) / np.sum(w * np.abs(measured.H - unloaded) ** 2))


def test_a_mass_at_the_driving_point_is_exact_on_the_simulated_frfs() -> None:
    freq, sim, fitted, _ = _setup()
    base = model_with_correction(fitted, sim)
    # every receptance the mass needs is in the file: the loaded chain is reproduced, the modes above the
    # band and whatever the fit misses included
    assert _relative_error(freq, base, 0.5, DRIVE) < 1e-18


def test_a_heavy_sensor_away_from_the_driving_point_leaves_a_small_part_of_its_effect() -> None:
    freq, sim, fitted, _ = _setup()
    base = model_with_correction(fitted, sim)
    for at in (1, 7):                                       # 4 % of the chain's mass at one sensor
        assert _relative_error(freq, base, 0.45, at) < 1e-2


def test_the_refitted_model_holds_the_simulated_frfs_and_the_next_mode() -> None:
    freq, sim, fitted, fn = _setup()
    base = model_with_correction(fitted, sim)
    corr = base.meta["frf_correction"]
    same = sim.as_quantity(corr.quantity)                           # the correction is in the simulated FRFs' form
    assert np.median(np.abs(corr.H) / np.abs(same.H)) < 3e-3         # the fixed part is small
    assert base.meta.get("above_band_modes") == 1
    assert fn[3] * 1.0 < base.freq_hz[-1] < fn[6]                    # a pseudo-mode above the band, where modes are


def test_a_grid_of_masses_solved_together_is_each_solved_alone() -> None:
    """Grids of masses loading one output, two outputs, every output and none, in blocks smaller than a grid:
    each row as :meth:`FRFMassLoading.loaded` gives it alone."""
    K, C, M = _chain()
    w2, V = eigh(K, M)
    zeta = np.einsum("ir,ij,jr->r", V, C, V) / (2 * np.sqrt(w2))
    lam = np.sqrt(w2) * (-zeta + 1j * np.sqrt(1 - zeta ** 2))
    phi = V[OUTS]
    model = ModalModel(poles=lam, residues=phi[:, None, :] * V[[DRIVE]][None] / (2j * lam.imag), quantity="receptance",
                       residual_form="none", outputs=LABELS, references=(f"chain:{DRIVE}:X",),
                       meta={"output_shapes": phi})
    freq = np.linspace(0.0, 300.0, 301)
    frf = FRFSet(freq_hz=freq, H=transfer(model, 2j * np.pi * freq), quantity="receptance", outputs=LABELS,
                 references=model.references)
    loading = FRFMassLoading(model, frf)
    grid = np.linspace(0.0, 0.6, 5)[:, None]                            # kg; the first row loads nothing
    one, both = np.eye(len(OUTS))[1], np.eye(len(OUTS))[0] + np.eye(len(OUTS))[3]
    ms = np.vstack([grid * one, grid[1:] * both, np.full((1, len(OUTS)), 0.3)])
    together = loading.loaded_H(ms, block=2)
    for m, H in zip(ms[1:], together[1:]):
        assert np.abs(H - frf.H).max() > 0
        np.testing.assert_allclose(H, loading.loaded(m).H, rtol=1e-13, atol=0)
    np.testing.assert_array_equal(together[0], frf.H)
