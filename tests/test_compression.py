"""The compressed pole search of large FRF sets (principal response functions) and the residue fit
of every FRF at the poles found."""
from __future__ import annotations

import numpy as np
import pytest

from analysis.compression import MIN_FRFS, principal_responses
from analysis.frf import FRFSet
from analysis.lsfd import Status, fit_lsfd, lsfd_at_poles
from analysis.modal import ModalModel, pole_from_fz, synthesize
from analysis.pipeline import fit_auto, rms_weights

F_TRUE = np.array([41.3, 88.0, 131.7, 176.2, 239.5])
Z_TRUE = np.array([0.012, 0.006, 0.009, 0.004, 0.007])


def scanned_set(n_out: int, n_f: int = 1500, noise: float = 0.0, seed: int = 3) -> tuple[FRFSet, ModalModel]:
    """A grid of ``n_out`` response points on one reference: random real-ish shapes (a little
    complexity), residual terms, accelerance over 5..300 Hz."""
    rng = np.random.default_rng(seed)
    lam = pole_from_fz(F_TRUE, Z_TRUE)
    psi = rng.normal(size=(n_out, lam.size)) * (1 + 0.03j * rng.normal(size=(n_out, lam.size)))
    R = psi[:, None, :] * (np.abs(lam) / 2j)[None, None, :]
    model = ModalModel(lam, R, quantity="accelerance", residual_form="physical",
                       upper_residual=1e-6 * (rng.normal(size=(n_out, 1)) + 1j * rng.normal(size=(n_out, 1))),
                       lower_residual=0.5 * (rng.normal(size=(n_out, 1)) + 1j * rng.normal(size=(n_out, 1))))
    frf = synthesize(model, np.linspace(5.0, 300.0, n_f))
    if noise:
        H = np.array(frf.H)
        sd = noise * np.sqrt(np.mean(np.abs(H) ** 2, axis=-1, keepdims=True))
        H += sd / np.sqrt(2) * (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape))
        frf = FRFSet(frf.freq_hz, H, quantity="accelerance")
    return frf, model


def test_noise_free_set_compresses_to_its_rank_and_the_fit_recovers_the_model():
    frf, model = scanned_set(96)
    band = (frf.freq_hz[0], frf.freq_hz[-1])
    comp = principal_responses(frf, band, rms_weights(frf, band), max_modes=12)
    assert comp is not None
    # 2 real directions per mode and 2 per complex residual term (UR, LR): the exact rank
    assert comp.n_signal == 2 * F_TRUE.size + 4
    assert comp.basis.shape == (96, comp.kept)
    np.testing.assert_allclose(comp.basis.T @ comp.basis, np.eye(comp.kept), atol=1e-12)
    fit = fit_auto(frf)
    assert fit.success, fit.problems
    assert any("principal response functions" in w for w in fit.warnings)
    res = fit.lsfd
    assert res.status == Status.FIXED_POLES
    np.testing.assert_allclose(res.freq_hz, F_TRUE, rtol=1e-10)
    np.testing.assert_allclose(res.damping, Z_TRUE, rtol=1e-8)
    # the residues of every FRF (not only of the PRFs) are the model's
    R = np.asarray(res.model.residues)
    np.testing.assert_allclose(R, np.asarray(model.residues), rtol=0, atol=1e-8 * np.max(np.abs(R)))


def test_compressed_and_full_fits_agree_on_a_noisy_set():
    frf, _ = scanned_set(MIN_FRFS, n_f=1200, noise=0.02, seed=11)
    full = fit_auto(frf, compress=False).lsfd
    comp = fit_auto(frf).lsfd
    assert comp.status == Status.FIXED_POLES and full.status != Status.FIXED_POLES
    assert comp.freq_hz.size == full.freq_hz.size == F_TRUE.size
    # the same estimates up to a small part of their standard deviation
    assert np.all(np.abs(comp.freq_hz - full.freq_hz) < 0.3 * full.freq_hz_std)
    assert np.all(np.abs(comp.damping - full.damping) < 0.3 * full.damping_std)
    # and both within a few standard deviations of the truth
    assert np.all(np.abs(comp.freq_hz - F_TRUE) < 4 * comp.freq_hz_std)
    np.testing.assert_allclose(comp.freq_hz_std, full.freq_hz_std, rtol=0.05)


def test_small_sets_are_not_compressed():
    frf, _ = scanned_set(MIN_FRFS - 1, n_f=600)
    band = (frf.freq_hz[0], frf.freq_hz[-1])
    assert principal_responses(frf, band, rms_weights(frf, band), max_modes=12) is None
    assert fit_auto(frf).lsfd.status != Status.FIXED_POLES


def test_lsfd_at_poles_is_the_lsfd_optimum_evaluated():
    frf, model = scanned_set(4, n_f=800, noise=0.01, seed=5)
    best = fit_lsfd(frf, np.asarray(model.poles) * (1 + 1e-4), band=(20.0, 280.0))
    again = lsfd_at_poles(frf, best.poles_raw, band=(20.0, 280.0))
    assert again.success and again.iterations == 0
    assert again.band == best.band
    np.testing.assert_allclose(again.sse, best.sse, rtol=1e-9)
    np.testing.assert_allclose(np.asarray(again.model.residues), np.asarray(best.model.residues), rtol=1e-7)
    np.testing.assert_allclose(again.freq_hz_std, best.freq_hz_std, rtol=1e-6)
    with pytest.raises(ValueError, match="lines"):
        lsfd_at_poles(frf, best.poles_raw, band=(1000.0, 2000.0))



def test_cmif_of_a_scanning_set_matches_the_svd():
    # many outputs per reference: the CMIF comes from the small H^H H (analysis.mif.TALL_RATIO)
    from analysis.mif import TALL_RATIO, cmif

    frf, _ = scanned_set(TALL_RATIO * 2, n_f=300, noise=0.01)
    H2 = np.concatenate([frf.H, 0.5j * frf.H[::-1]], axis=1)     # two references
    two = FRFSet(frf.freq_hz, H2, quantity="accelerance")
    s = cmif(two)
    ref = np.linalg.svd(np.moveaxis(H2, 2, 0), compute_uv=False)
    np.testing.assert_allclose(s, ref, rtol=1e-9, atol=1e-12 * ref.max())


def test_a_resonance_of_one_frf_only_is_kept():
    # a local mode (a panel seen by one point of 160): weak in the set's singular values, it must
    # still reach the PRFs (or the set be fitted whole) and be fitted
    frf, _ = scanned_set(160, n_f=1500, seed=4)
    lam = pole_from_fz(np.array([205.0]), np.array([0.003]))
    R = np.zeros((160, 1, 1), complex)
    R[17, 0, 0] = 0.2 * np.abs(lam[0]) / 2j
    H = np.array(frf.H) + synthesize(ModalModel(lam, R, quantity="accelerance", residual_form="none"), frf.freq_hz).H
    rng = np.random.default_rng(0)
    sd = 0.02 * np.sqrt(np.mean(np.abs(H) ** 2, axis=-1, keepdims=True))
    H += sd / np.sqrt(2) * (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape))
    fit = fit_auto(FRFSet(frf.freq_hz, H, quantity="accelerance"))
    assert fit.lsfd.status == Status.FIXED_POLES
    f = fit.lsfd.freq_hz
    assert np.min(np.abs(f - 205.0)) < 0.05
    assert all(np.min(np.abs(f - x)) < 0.01 * x for x in F_TRUE)
