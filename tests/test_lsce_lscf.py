"""LSCE and LSCF initial poles against the known poles of synthetic FRFs (paper eq. (11))."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from analysis.frf import FRFSet
from analysis.lsce import lsce_poles, lsce_poles_all_orders
from analysis.lscf import lscf_poles, lscf_poles_all_orders, parse_band
from analysis.modal import ModalModel, damping_ratio, natural_freq_hz, pole_from_fz, synthesize

F_TRUE = np.array([40.0, 75.0, 78.0, 130.0, 180.0, 240.0, 310.0, 390.0])
Z_TRUE = np.linspace(0.005, 0.02, F_TRUE.size)


def make_frf(freqs=F_TRUE, zetas=Z_TRUE, *, n_out=12, n_ref=1, n_f=2000, fmax=500.0, out_of_band=False,
             residuals=False, seed=0) -> tuple[FRFSet, np.ndarray]:
    """Accelerance FRFs of a modal model; the reference point excites every mode (shape 1 there)."""
    rng = np.random.default_rng(seed)
    f_all, z_all = np.asarray(freqs, float), np.asarray(zetas, float)
    if out_of_band:
        f_all = np.concatenate([[3.0], f_all, [800.0]])
        z_all = np.concatenate([[0.02], z_all, [0.02]])
    poles = pole_from_fz(f_all, z_all)
    phi = rng.standard_normal((n_out, f_all.size))
    part = 1.0 + 0.3 * rng.standard_normal((n_ref, f_all.size))
    R = phi[:, None, :] * part[None, :, :] * np.exp(0.05j * rng.standard_normal(f_all.size)) * poles.imag / 2j
    model = ModalModel(
        poles, R, quantity="accelerance", residual_form="physical" if residuals else "none",
        upper_residual=1e-7 * rng.standard_normal((n_out, n_ref)) if residuals else None,
        lower_residual=1e2 * rng.standard_normal((n_out, n_ref)) if residuals else None,
    )
    f = np.linspace(fmax / n_f, fmax, n_f)
    return synthesize(model, f), pole_from_fz(np.asarray(freqs, float), np.asarray(zetas, float))


def add_noise(frf: FRFSet, level: float, seed: int = 1) -> FRFSet:
    """Proportional complex noise: each line gets level * |H| * (n1 + j n2) / sqrt(2)."""
    rng = np.random.default_rng(seed)
    n = (rng.standard_normal(frf.H.shape) + 1j * rng.standard_normal(frf.H.shape)) / np.sqrt(2)
    return replace(frf, H=frf.H + level * np.abs(frf.H) * n)


def match_errors(found: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Relative natural-frequency and damping errors of the found pole nearest each true pole."""
    ef, ez = [], []
    for lam in truth:
        q = found[np.argmin(np.abs(found - lam))]
        ef.append(abs(natural_freq_hz(q) / natural_freq_hz(lam) - 1))
        ez.append(abs(damping_ratio(q) / damping_ratio(lam) - 1))
    return np.array(ef), np.array(ez)


@pytest.mark.parametrize("band", [None, (20.0, 450.0)])
def test_lscf_exact_on_pure_modal_data(band):
    frf, truth = make_frf()
    p = lscf_poles(frf, 20, band=band)
    ef, ez = match_errors(p, truth)
    assert ef.max() < 1e-7 and ez.max() < 1e-5
    assert np.all(p.imag > 0)


@pytest.mark.parametrize("band", [None, (20.0, 450.0)])
def test_lsce_exact_on_pure_modal_data(band):
    frf, truth = make_frf()
    p = lsce_poles(frf, 20, band=band)
    ef, ez = match_errors(p, truth)
    assert ef.max() < 1e-6 and ez.max() < 1e-4
    assert np.all(p.imag > 0)
    if band is not None:  # only poles whose damped frequency is in the band are returned
        fd = p.imag / (2 * np.pi)
        assert fd.min() >= band[0] and fd.max() <= band[1]


def test_both_close_with_residual_terms_and_out_of_band_modes():
    frf, truth = make_frf(out_of_band=True, residuals=True)
    for fn in (lscf_poles, lsce_poles):
        p = fn(frf, 30, band=(20.0, 480.0))
        ef, ez = match_errors(p, truth)
        # LSCE/LSCF have no residual terms: the out-of-band content biases them a little
        assert ef.max() < 1e-3, fn.__name__
        assert ez.max() < 5e-2, fn.__name__


def test_multi_reference_and_receptance():
    frf, truth = make_frf(n_ref=2, n_out=6)
    rec = frf.as_quantity("receptance")
    # receptance spans a wider dynamic range (1/w^2): the normal equations are less well conditioned
    for fn, tol_f, tol_z in ((lscf_poles, 5e-6, 1e-3), (lsce_poles, 5e-5, 1e-3)):
        ef, ez = match_errors(fn(rec, 20), truth)
        assert ef.max() < tol_f and ez.max() < tol_z, fn.__name__


def test_all_orders_match_single_order():
    frf, _ = make_frf(n_out=4)
    allp = lscf_poles_all_orders(frf, 12)
    assert len(allp) == 12
    np.testing.assert_allclose(np.sort_complex(allp[9]), np.sort_complex(lscf_poles(frf, 10)), rtol=1e-9)
    alle = lsce_poles_all_orders(frf, 12)
    assert len(alle) == 12 and all(p.size <= 2 * (k + 1) for k, p in enumerate(alle))


def test_lscf_non_uniform_lines_direct_sums():
    """Lines off a uniform grid take the direct (non-FFT) path and still give exact poles."""
    frf, truth = make_frf(n_out=4)
    keep = np.ones(frf.freq_hz.size, bool)
    keep[::7] = False
    sub = replace(frf, freq_hz=frf.freq_hz[keep], H=frf.H[..., keep])
    ef, ez = match_errors(lscf_poles(sub, 20), truth)
    assert ef.max() < 1e-7 and ez.max() < 1e-5
    with pytest.raises(ValueError, match="uniformly spaced"):
        lsce_poles(sub, 10)


def test_noise_one_percent_close():
    frf, truth = make_frf()
    noisy = add_noise(frf, 0.01)
    # LSCE weighs the long, lightly damped tails: its strongly damped modes are biased more
    for fn, tol_f in ((lscf_poles, 2e-3), (lsce_poles, 2e-2)):
        ef, ez = match_errors(fn(noisy, 24, band=(20.0, 480.0)), truth)
        assert ef.max() < tol_f, fn.__name__
        assert np.median(ef) < 1e-4, fn.__name__
        assert np.median(ez) < 0.1, fn.__name__


@pytest.mark.parametrize("fn", [lsce_poles, lscf_poles])
def test_bad_input(fn):
    frf, _ = make_frf(n_out=2)
    with pytest.raises(ValueError, match=">= 1"):
        fn(frf, 0)
    with pytest.raises(ValueError, match="reversed"):
        fn(frf, 4, band=(300.0, 100.0))
    with pytest.raises(ValueError, match="outside the data"):
        fn(frf, 4, band=(600.0, 900.0))
    H = frf.H.copy()
    H[0, 0, 10] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        fn(replace(frf, H=H), 4)
    with pytest.raises(ValueError, match="too few|at least"):
        fn(frf, 4, band=(100.0, 101.0))


def test_parse_band_clips_to_data():
    f = np.linspace(1.0, 100.0, 100)
    assert parse_band(None, f) == (1.0, 100.0)
    assert parse_band((0.0, 50.0), f) == (1.0, 50.0)
    with pytest.raises(ValueError, match="pair"):
        parse_band("5:10", f)


def test_inputs_not_modified():
    frf, _ = make_frf(n_out=3)
    H0 = frf.H.copy()
    lscf_poles(frf, 10)
    lsce_poles(frf, 10)
    np.testing.assert_array_equal(frf.H, H0)
