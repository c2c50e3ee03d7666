"""Tests of analysis.uncertainty: propagation to (f, zeta), Fisher information, Cramer-Rao bound."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from analysis.lsfd import fit_lsfd
from analysis.modal import ModalModel, damping_ratio, natural_freq_hz, pole_from_fz, synthesize
from analysis.uncertainty import covariance_from_normal, crlb_poles, fisher_information, fz_covariance, fz_jacobian, fz_std

FREQ = np.linspace(10.0, 60.0, 300)


def small_model(n_out: int = 2, n_ref: int = 1, residual_form: str = "physical", seed: int = 0) -> ModalModel:
    rng = np.random.default_rng(seed)
    lam = pole_from_fz(np.array([20.0, 35.0, 36.4]), np.array([0.01, 0.008, 0.012]))
    R = (rng.normal(size=(n_out, n_ref, 3)) + 1j * rng.normal(size=(n_out, n_ref, 3))) * 50
    ur = None if residual_form == "none" else 1e-5 * (1 + 1j) * np.ones((n_out, n_ref))
    lr = None if residual_form == "none" else 1e3 * (1 - 2j) * np.ones((n_out, n_ref))
    return ModalModel(lam, R, quantity="accelerance", residual_form=residual_form, upper_residual=ur,
                      lower_residual=lr)


def test_fz_jacobian_matches_finite_differences() -> None:
    lam = pole_from_fz(np.array([12.0, 80.0]), np.array([0.02, 0.3]))
    G = fz_jacobian(lam)
    for r, p in enumerate(lam):
        for i, dp in enumerate((1.0, 1.0j)):
            h = 1e-6 * abs(p)
            fp, fm = p + h * dp, p - h * dp
            df = (natural_freq_hz(np.array([fp])) - natural_freq_hz(np.array([fm])))[0] / (2 * h)
            dz = (damping_ratio(np.array([fp])) - damping_ratio(np.array([fm])))[0] / (2 * h)
            assert G[r, 0, i] == pytest.approx(df, rel=1e-6)
            assert G[r, 1, i] == pytest.approx(dz, rel=1e-6)


def test_fz_std_of_isotropic_pole_covariance() -> None:
    """cov(sigma, omega) = s^2 I: f = |lambda|/2pi has std s/2pi exactly (gradient of unit norm / 2pi);
    zeta has std s omega / |lambda|^2 * sqrt(omega^2 + sigma^2) / |lambda| = s / |lambda|."""
    lam = pole_from_fz(np.array([10.0, 50.0]), np.array([0.05, 0.01]))
    s = 0.3
    fs, zs = fz_std(lam, s ** 2 * np.eye(4))
    assert np.allclose(fs, s / (2 * np.pi))
    assert np.allclose(zs, s * np.abs(lam.imag) / np.abs(lam) ** 2)
    c = fz_covariance(lam, s ** 2 * np.eye(4))
    assert c.shape == (4, 4) and np.allclose(c, c.T)
    with pytest.raises(ValueError, match="cov_poles"):
        fz_std(lam, np.eye(3))


def test_fisher_jacobian_matches_finite_differences_of_synthesis() -> None:
    """The analytic Fisher matrix equals J^T J / (noise_var / 2) with J from finite differences of
    the synthesised FRFs with respect to every real parameter."""
    model = small_model(n_out=2, n_ref=1)
    noise_var = 0.5
    F = fisher_information(model, FREQ, noise_var)
    m = 3
    cols = []

    def synth(poles, R, ur, lr):
        mm = replace(model, poles=poles, residues=R, upper_residual=ur, lower_residual=lr)
        H = synthesize(mm, FREQ).H.reshape(-1, FREQ.size)
        return np.concatenate([np.concatenate([h.real, h.imag]) for h in H])

    def fd(fun, x0, h):
        return (fun(x0 + h) - fun(x0 - h)) / (2 * h)

    lam = model.poles
    for r in range(m):
        for dp in (1.0, 1.0j):
            h = 1e-7 * abs(lam[r])
            cols.append(fd(lambda e, r=r, dp=dp: synth(lam + np.eye(m)[r] * e * dp, model.residues, model.upper_residual,
                                           model.lower_residual), 0.0, h))
    for o in range(2):
        for r in range(m):
            for dp in (1.0, 1.0j):
                E = np.zeros_like(model.residues)
                E[o, 0, r] = dp
                cols.append(fd(lambda e, E=E: synth(lam, model.residues + e * E, model.upper_residual,
                                               model.lower_residual), 0.0, 1.0))
        for which in ("ur", "lr"):
            for dp in (1.0, 1.0j):
                E = np.zeros((2, 1), dtype=complex)
                E[o, 0] = dp
                if which == "ur":
                    cols.append(fd(lambda e, E=E: synth(lam, model.residues, model.upper_residual + e * E,
                                                   model.lower_residual), 0.0, 1e-6))
                else:
                    cols.append(fd(lambda e, E=E: synth(lam, model.residues, model.upper_residual,
                                                   model.lower_residual + e * E), 0.0, 1.0))
    J = np.column_stack(cols)
    F_fd = J.T @ J / (noise_var / 2)
    assert F.shape == F_fd.shape == (6 + 2 * 10, 6 + 2 * 10)
    scale = np.sqrt(np.outer(np.diag(F), np.diag(F)))
    assert np.max(np.abs(F - F_fd) / scale) < 1e-6


@pytest.mark.parametrize("form", ["physical", "paper", "none"])
def test_crlb_equals_inverse_of_full_fisher(form: str) -> None:
    """The Schur-complement bound of crlb_poles is the pole block of the inverse full Fisher matrix."""
    model = small_model(n_out=3, n_ref=2, residual_form=form, seed=1)
    nv = 0.02
    F = fisher_information(model, FREQ, nv)
    d = np.sqrt(np.diag(F))
    Finv = np.linalg.inv(F / np.outer(d, d)) / np.outer(d, d)
    b = crlb_poles(model, FREQ, nv)
    assert np.allclose(b.cov_poles, Finv[:6, :6], rtol=1e-6, atol=1e-9 * np.abs(Finv[:6, :6]).max())
    fs, zs = fz_std(model.poles, Finv[:6, :6])
    assert np.allclose(b.freq_hz_std, fs, rtol=1e-6)
    assert np.allclose(b.damping_std, zs, rtol=1e-6)


def test_crlb_scaling_laws() -> None:
    """std bound ~ sqrt(noise_var); duplicating every output halves the variance of the poles."""
    model = small_model(n_out=2)
    b1 = crlb_poles(model, FREQ, 1.0)
    b4 = crlb_poles(model, FREQ, 4.0)
    assert np.allclose(b4.freq_hz_std, 2 * b1.freq_hz_std)
    assert np.allclose(b4.damping_std, 2 * b1.damping_std)
    doubled = replace(model, residues=np.concatenate([model.residues] * 2),
                      upper_residual=np.concatenate([model.upper_residual] * 2),
                      lower_residual=np.concatenate([model.lower_residual] * 2))
    b2 = crlb_poles(doubled, FREQ, 1.0)
    assert np.allclose(b2.freq_hz_std, b1.freq_hz_std / np.sqrt(2))


def test_sdof_crlb_matches_closed_form_limit() -> None:
    """One lightly damped mode, receptance, no residuals, dense lines over a wide band: the bound on
    omega_d approaches the closed form from the continuous-frequency Fisher integral,
    var(omega) ~ sigma_n^2 * 2 |sigma|^3 / (pi |R|^2 * n_per_rad) * 2 (the factor 2: the amplitude
    and phase of R are estimated too, which for a single pole doubles the variance)."""
    sig, wd = -2.0, 2 * np.pi * 50.0
    R = -1j * 3.0
    model = ModalModel(np.array([sig + 1j * wd]), np.array([[[R]]]), quantity="receptance", residual_form="none")
    f = np.arange(30.0, 70.0, 0.01)
    nv = 1e-4
    b = crlb_poles(model, f, nv)
    density = 1.0 / (2 * np.pi * 0.01)            # lines per rad/s
    # Fisher of (sigma, omega, a, b) for R/(jw - lambda) alone, integrated over all w:
    # int |R|^2 / |jw - lambda|^4 dw = pi |R|^2 / (2 |sigma|^3); int 1/|jw-lambda|^2 = pi/|sigma|;
    # int |R|/|..|^3 terms vanish by symmetry except the coupling that doubles the variance.
    info_w = density * (np.pi * abs(R) ** 2 / (2 * abs(sig) ** 3)) / (nv / 2)
    var_w = 2.0 / info_w
    var_theta = b.cov_poles[1, 1]
    assert var_theta == pytest.approx(var_w, rel=0.05)


def test_covariance_from_normal_handles_singular_matrix() -> None:
    M = np.array([[1.0, 1.0], [1.0, 1.0]])
    c = covariance_from_normal(M, 2.0)
    assert np.all(np.isfinite(c))
    assert np.allclose(c, 2.0 * np.linalg.pinv(M))


def test_bad_noise_var_raises() -> None:
    with pytest.raises(ValueError, match="noise_var"):
        crlb_poles(small_model(), FREQ, 0.0)
    with pytest.raises(ValueError, match="noise_var"):
        fisher_information(small_model(), FREQ, -1.0)


@pytest.mark.long
def test_monte_carlo_rms_error_matches_crlb() -> None:
    """20 noisy fits: the RMS error of f and zeta per mode is within the Monte Carlo spread of the CRLB
    (pooled RMS/CRLB between 0.7 and 1.3 for 20 runs)."""
    model = small_model(n_out=3, seed=2)
    clean = synthesize(model, FREQ)
    rms = np.sqrt(np.mean(np.abs(clean.H) ** 2))
    sd = 0.02 * rms
    rng = np.random.default_rng(3)
    ef, ez = [], []
    for _ in range(20):
        noise = sd / np.sqrt(2) * (rng.normal(size=clean.H.shape) + 1j * rng.normal(size=clean.H.shape))
        res = fit_lsfd(replace(clean, H=clean.H + noise), model.poles * (1 + 1e-3))
        assert res.success
        ef.append(res.freq_hz - model.freq_hz)
        ez.append(res.damping - model.damping)
    b = crlb_poles(model, FREQ, sd ** 2)
    rf = np.sqrt(np.mean(np.square(ef), axis=0)) / b.freq_hz_std
    rz = np.sqrt(np.mean(np.square(ez), axis=0)) / b.damping_std
    pooled = np.sqrt(np.mean(np.concatenate([rf, rz]) ** 2))
    assert 0.7 < pooled < 1.3
