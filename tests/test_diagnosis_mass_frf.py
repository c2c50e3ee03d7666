"""Masses added to the FRFs of a simulation given as FRFs (:mod:`analysis.diagnosis.mass_frf`), against a
chain of lumped masses solved with the masses in its mass matrix."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.linalg import eigh

from analysis.diagnosis.mass_frf import FRF_MASSES_KEY, FRFMassLoading, add_frf_masses, uses_frf_masses
from analysis.frf import FRFSet, convert_quantity
from analysis.modal import ModalModel, transfer

K = np.array([[7e5, -3e5, 0.0, 0.0], [-3e5, 5e5, -2e5, 0.0], [0.0, -2e5, 4.5e5, -2.5e5], [0.0, 0.0, -2.5e5, 2.5e5]])
M = np.diag([2.0, 1.5, 1.0, 1.2])                      # kg
ALPHA, BETA = 1.5, 2e-5                                 # proportional damping C = ALPHA M + BETA K (modal)
OUTS, REF = [0, 1, 2], 1                                # DOF 1 is the driving point; DOF 3 is not measured
LABELS = tuple(f"c:{i}:X" for i in OUTS)
FREQ = np.linspace(0.0, 250.0, 401)                     # Hz, with the 0 Hz line


def chain_accelerance(added_kg: np.ndarray) -> np.ndarray:
    """Accelerance (n_out, 1, n_f) of the chain with ``added_kg`` (kg) at the outputs."""
    Ma = M.copy()
    Ma[OUTS, OUTS] += added_kg
    H = np.empty((len(OUTS), 1, FREQ.size), complex)
    for k, w in enumerate(2 * np.pi * FREQ):
        x = np.linalg.solve(K + 1j * w * (ALPHA * M + BETA * K) - w ** 2 * Ma, np.eye(4)[:, REF])
        H[:, 0, k] = -w ** 2 * x[OUTS]
    return H


def simulation() -> tuple[ModalModel, FRFSet]:
    """The chain's modal model (every mode, mass-normalised shapes at the outputs) as a simulation read from
    FRFs, and its FRFs (accelerance)."""
    w2, phi = eigh(K, M)
    wn = np.sqrt(w2)
    zeta = ALPHA / (2 * wn) + BETA * wn / 2
    lam = -zeta * wn + 1j * wn * np.sqrt(1 - zeta ** 2)
    R = phi[OUTS][:, None, :] * phi[[REF]][None, :, :] / (2j * lam.imag)
    model = ModalModel(poles=lam, residues=R, quantity="receptance", residual_form="none", outputs=LABELS,
                       references=(LABELS[REF],), meta={"output_shapes": phi[OUTS], "frf_correction": None})
    H = convert_quantity(transfer(model, 2j * np.pi * FREQ), FREQ, "receptance", "accelerance")
    return model, FRFSet(freq_hz=FREQ, H=H, quantity="accelerance", outputs=LABELS, references=(LABELS[REF],))


def test_masses_added_to_the_frfs_are_the_chain_solved_with_them() -> None:
    model, frf = simulation()
    assert uses_frf_masses(model)
    np.testing.assert_allclose(frf.H[..., 1:], chain_accelerance(np.zeros(3))[..., 1:], rtol=1e-9)
    for added in (np.array([0.0, 0.3, 0.0]), np.array([0.2, 0.0, 0.5]), np.full(3, 0.25)):
        masses = tuple((float(kg), np.eye(3)[i] > 0) for i, kg in enumerate(added) if kg > 0)
        loaded = add_frf_masses(replace(model, meta={**model.meta, FRF_MASSES_KEY: masses}), frf)
        np.testing.assert_allclose(loaded.H[..., 1:], chain_accelerance(added)[..., 1:], rtol=1e-8)
        np.testing.assert_array_equal(loaded.H[..., 0], frf.H[..., 0])      # a mass does nothing at 0 Hz


def test_a_grid_of_masses_solved_together_is_each_solved_alone() -> None:
    """Rows loading different outputs (and none), more rows than one block: each row as :meth:`loaded`."""
    model, frf = simulation()
    loading = FRFMassLoading(model, frf)
    rng = np.random.default_rng(3)
    ms = rng.uniform(0.0, 1.0, (7, 3)) * (rng.uniform(size=(7, 3)) > 0.4)
    ms[0] = 0.0
    together = loading.loaded_H(ms, block=2)
    for m, H in zip(ms, together):
        np.testing.assert_allclose(H, loading.loaded(m).H, rtol=1e-13, atol=0)
    np.testing.assert_array_equal(together[0], frf.H)


def test_a_mass_at_the_driving_point_is_exact_on_the_files_frfs_without_every_mode() -> None:
    """The model without the chain's highest mode (the file's FRFs still have it): the receptances the mass
    needs are the file's own through the driving point, so the result is still the chain with the mass."""
    model, frf = simulation()
    truncated = replace(model, poles=model.poles[:3], residues=model.residues[..., :3],
                        meta={**model.meta, "output_shapes": model.meta["output_shapes"][:, :3]})
    added = np.array([0.0, 0.4, 0.0])
    loaded = FRFMassLoading(truncated, frf).loaded(added)
    np.testing.assert_allclose(loaded.H[..., 1:], chain_accelerance(added)[..., 1:], rtol=1e-8)
    assert not np.allclose(FRFMassLoading(truncated, replace(frf, H=convert_quantity(
        transfer(truncated, 2j * np.pi * FREQ), FREQ, "receptance", "accelerance"))).loaded(added).H[..., 1:],
        chain_accelerance(added)[..., 1:], rtol=1e-3)                  # the model's FRFs alone are not enough
