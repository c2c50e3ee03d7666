"""The LSFD's optional stopping rule ``sdtol`` (the step still to go in standard deviations) and the
Householder kernel's T factor, against FRFs synthesised from known models with seeded noise."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from analysis._lsfd_kernels import householder_project
from analysis.frf import FRFSet
from analysis.lsfd import fit_lsfd
from analysis.modal import ModalModel, pole_from_fz, synthesize

FN = np.array([14.0, 31.0, 32.5, 57.0, 83.0])
ZETA = np.array([0.012, 0.02, 0.015, 0.006, 0.01])
FREQ = np.linspace(8.0, 100.0, 700)


def noisy_set(noise: float, seed: int = 3) -> tuple[FRFSet, np.ndarray]:
    """Three FRFs of a five-mode model with complex Gaussian noise of ``noise`` x each FRF's RMS
    (no noise for 0); returns the set and the true poles (rad/s)."""
    rng = np.random.default_rng(seed)
    lam = pole_from_fz(FN, ZETA)
    psi = rng.normal(size=(3, lam.size)) + 0.2j * rng.normal(size=(3, lam.size))
    R = (psi * 1j * np.abs(lam))[:, None, :]
    frf = synthesize(ModalModel(lam, R, quantity="accelerance", residual_form="none"), FREQ)
    rms = np.sqrt(np.mean(np.abs(frf.H) ** 2, axis=-1, keepdims=True))
    H = frf.H + noise * rms * (rng.normal(size=frf.H.shape) + 1j * rng.normal(size=frf.H.shape)) / np.sqrt(2)
    return replace(frf, H=H), lam


def start_poles(lam: np.ndarray) -> np.ndarray:
    """The true poles moved by 1 % in frequency and 30 % in damping, alternately up and down."""
    s = np.where(np.arange(lam.size) % 2 == 0, 1.0, -1.0)
    return lam.real * (1 + 0.3 * s) + 1j * lam.imag * (1 - 0.01 * s)


def test_sdtol_stops_within_a_hundredth_of_a_standard_deviation() -> None:
    """On noisy data the fit with ``sdtol=0.01`` takes fewer iterations than the one run to
    ``ftol``, says why it stopped, and its poles lie within 0.05 standard deviations of the strict fit's."""
    frf, lam = noisy_set(0.02)
    strict = fit_lsfd(frf, start_poles(lam), residual_form="none")
    quick = fit_lsfd(frf, start_poles(lam), residual_form="none", sdtol=0.01)
    assert strict.success and quick.success, (strict.message, quick.message)
    assert quick.iterations < strict.iterations
    assert "standard deviations" in quick.message
    assert np.max(np.abs(quick.freq_hz - strict.freq_hz) / strict.freq_hz_std) < 0.05
    assert np.max(np.abs(quick.damping - strict.damping) / strict.damping_std) < 0.05


@pytest.mark.parametrize("method", ["lm", "gn"])
def test_sdtol_keeps_noise_free_recovery_to_round_off(method: str) -> None:
    """Noise-free data: S (and with it the standard deviations) fall to round-off, so the rule
    still lets the iteration recover the true poles to near machine precision."""
    frf, lam = noisy_set(0.0)
    res = fit_lsfd(frf, start_poles(lam), residual_form="none", method=method, sdtol=0.01)
    assert res.success, res.message
    got = res.poles_raw[np.argsort(res.poles_raw.imag)]
    assert np.max(np.abs(got - lam) / np.abs(lam)) < 1e-9


def test_sdtol_rejects_bad_values() -> None:
    frf, lam = noisy_set(0.0)
    with pytest.raises(ValueError, match="sdtol"):
        fit_lsfd(frf, lam, sdtol=-1.0)


@pytest.mark.parametrize("identity_first", [False, True])
def test_householder_t_factor_with_and_without_identity_reflectors(identity_first: bool) -> None:
    """``householder_project`` gives the explicit orthonormal basis' projections whether the T
    factor comes from its inverse (every tau > 0) or column by column (a reflector that is the
    identity, tau = 0: a basis column with nothing below its diagonal)."""
    rng = np.random.default_rng(8)
    A = rng.normal(size=(200, 7)) @ np.diag(np.logspace(0, 3, 7))
    if identity_first:
        A[:, 0] = 0.0
        A[0, 0] = 2.5
    E, Y = rng.normal(size=(200, 4)), rng.normal(size=(200, 3))
    h, tau = np.linalg.qr(A, mode="raw")
    assert (tau[0] == 0) == identity_first
    QtY, G, EtR, S = householder_project(h, tau, E, Y)
    Q, _ = np.linalg.qr(A)
    PE, r = E - Q @ (Q.T @ E), Y - Q @ (Q.T @ Y)
    assert np.allclose(np.abs(QtY), np.abs(Q.T @ Y), rtol=0, atol=1e-12)
    assert np.allclose(G, PE.T @ PE, rtol=1e-12, atol=1e-11)
    assert np.allclose(EtR, E.T @ r, rtol=1e-12, atol=1e-11)
    assert S == pytest.approx(float(np.sum(r * r)), rel=1e-12)
