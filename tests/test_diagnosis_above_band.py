"""The mode just above the band of an FRF-file simulation, as a pseudo-mode that a sensor's mass moves.

Exact data: a chain of lumped masses and springs (fixed at both ends) solved per line,
``(K + j w C - w^2 M)^-1`` with a light Rayleigh damping matrix; its fourth mode lies just above the
band. The simulation's modal model holds the in-band modes only (exact, from the chain's eigenvectors);
the measurement is the chain with a sensor's mass added at one output.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.linalg import eigh

from analysis.diagnosis.above_band import with_above_band_mode
from analysis.diagnosis.compare import line_weights
from analysis.diagnosis.effects import predict
from analysis.diagnosis.entry import model_with_correction
from analysis.frf import FRFSet
from analysis.modal import ModalModel

MASSES = np.array([1.0, 1.4, 0.8, 1.1, 0.9, 1.3])      # kg
SPRINGS = np.array([3e5, 2e5, 4e5, 2.5e5, 3.5e5, 2e5, 3e5])   # N/m, the first and last to ground
OUTS, REF = [0, 2, 3, 5], 0
LABELS = tuple(f"chain:{i}:X" for i in OUTS)


def _chain(extra_kg: float = 0.0, at: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = MASSES.size
    K = np.zeros((n, n))
    for i, k in enumerate(SPRINGS):
        for a, b in ((i - 1, i - 1), (i, i)):
            if 0 <= a < n:
                K[a, b] += k
        if 1 <= i < n:
            K[i - 1, i] -= k
            K[i, i - 1] -= k
    M = np.diag(MASSES)
    C = 4e-7 * K + 0.2 * np.diag(MASSES)         # the physical damping; a sensor adds mass only
    M = M.copy()
    M[at, at] += extra_kg
    return K, C, M


def _receptance(freq: np.ndarray, extra_kg: float = 0.0) -> FRFSet:
    K, C, M = _chain(extra_kg)
    H = np.empty((len(OUTS), 1, freq.size), complex)
    for k, w in enumerate(2 * np.pi * freq):
        x = np.linalg.solve(K + 1j * w * C - w ** 2 * M, np.eye(MASSES.size)[:, REF])
        H[:, 0, k] = x[OUTS]
    return FRFSet(freq_hz=freq, H=H, quantity="receptance", outputs=LABELS, references=(LABELS[REF],), unit="m/N")


def _in_band_model(top_hz: float) -> tuple[ModalModel, np.ndarray]:
    """The chain's modes below ``top_hz`` as a receptance pole-residue model, and every natural frequency (Hz)."""
    K, C, M = _chain()
    w2, V = eigh(K, M)
    wn = np.sqrt(w2)
    zeta = np.einsum("ir,ij,jr->r", V, C, V) / (2 * wn)
    keep = wn / (2 * np.pi) < top_hz
    lam = wn[keep] * (-zeta[keep] + 1j * np.sqrt(1 - zeta[keep] ** 2))
    phi = V[:, keep]
    R = phi[OUTS][:, None, :] * phi[[REF]][None, :, :] / (2j * lam.imag)
    return ModalModel(poles=lam, residues=R, quantity="receptance", residual_form="none", outputs=LABELS,
                      references=(LABELS[REF],)), wn / (2 * np.pi)


def test_the_pseudo_mode_lies_at_the_next_mode_and_the_mass_moves_it_as_the_chain_does() -> None:
    _, fn = _in_band_model(1e9)
    top = 0.97 * fn[3]                                    # the band ends 3 % below the fourth mode
    freq = np.linspace(0.05 * top, top, 900)
    model, _ = _in_band_model(top)
    sim = _receptance(freq)
    grown = with_above_band_mode(model, sim, line_weights(sim))
    assert grown.meta.get("above_band_modes") == 1 and grown.poles.size == model.poles.size + 1
    assert abs(grown.freq_hz[-1] / fn[3] - 1) < 2e-3     # the next mode, not somewhere above the band

    extra = 0.12                                         # kg at output chain:2:X, 10 % of the chain's mass
    measured = _receptance(freq, extra)
    loaded = [{"effect": "mass_loading", "mass_kg": extra, "sensor": "chain:2:X"}]
    w = line_weights(measured)

    def err(base: ModalModel) -> float:
        H = predict(base, freq, "receptance", loaded).H
        return float(np.sum(w * np.abs(measured.H - H) ** 2) / np.sum(w * np.abs(measured.H - sim.H) ** 2))

    with_mode = err(model_with_correction(model, sim, refit=False))
    without = err(model_with_correction(model, sim, above_band=False, refit=False))
    # the chain's loaded FRFs are matched to a small fraction of the mass's own effect; without the mode
    # above the band the mass moves its tail only as a static flexibility, which leaves several times more
    assert with_mode < 0.005
    assert without > 2 * with_mode
    assert err(model_with_correction(model, sim)) < 0.005          # refitted in receptance (the default)


def test_no_pseudo_mode_without_a_driving_point_or_without_a_tail() -> None:
    _, fn = _in_band_model(1e9)
    top = 0.97 * fn[3]
    freq = np.linspace(0.05 * top, top, 900)
    model, _ = _in_band_model(top)
    sim = _receptance(freq)
    other = replace(model, references=("chain:9:X",))
    assert with_above_band_mode(other, replace(sim, references=("chain:9:X",)), line_weights(sim)) is other
    full, _ = _in_band_model(1e9)                         # every mode: nothing is left above the band
    complete = with_above_band_mode(full, sim, line_weights(sim))
    assert complete.poles.size == full.poles.size and "above_band_modes" not in complete.meta
