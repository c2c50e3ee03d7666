"""Mode indicator functions against analytic FRFs of known modal models."""
from __future__ import annotations

import numpy as np
import pytest

from analysis.frf import FRFSet
from analysis.mif import cmif, mif
from analysis.modal import ModalModel, pole_from_fz, synthesize


def _normal_mode_model(freqs_hz, zetas, shapes):
    """A proportionally damped model: residues R = phi_o phi_r / (2 j omega_d) (real shapes)."""
    lam = pole_from_fz(np.asarray(freqs_hz), np.asarray(zetas))
    phi = np.asarray(shapes, dtype=float)  # (n_points, n_modes)
    R = phi[:, None, :] * phi[None, :, :] / (2j * lam.imag)[None, None, :]
    return ModalModel(poles=lam, residues=R, quantity="receptance", residual_form="none")


def test_cmif_singular_values_match_numpy_and_peak_at_modes():
    phi = np.array([[1.0, 0.5, 0.2], [0.3, -1.0, 0.7], [0.8, 0.4, -0.9]])
    model = _normal_mode_model([20.0, 45.0, 80.0], [0.01, 0.01, 0.01], phi)
    f = np.linspace(5, 100, 1901)
    frf = synthesize(model, f)
    s = cmif(frf)
    assert s.shape == (f.size, 3)
    k = 123
    assert np.allclose(s[k], np.linalg.svd(frf.H[:, :, k], compute_uv=False), rtol=1e-12)
    assert np.all(np.diff(s, axis=1) <= 1e-30)  # largest first
    peaks = [i for i in range(1, f.size - 1) if s[i, 0] > s[i - 1, 0] and s[i, 0] > s[i + 1, 0]]
    assert np.allclose(sorted(f[peaks]), [20.0, 45.0, 80.0], atol=0.2)


def test_cmif_second_curve_reveals_a_close_pair():
    # two modes 1 Hz apart with orthogonal shapes: with 2 references s_2 peaks at the second mode
    phi = np.array([[1.0, 0.0], [0.0, 1.0], [0.6, 0.6]])
    model = _normal_mode_model([160.0, 161.0], [0.002, 0.002], phi)
    f = np.linspace(150, 170, 2001)
    s = cmif(synthesize(model, f))
    i160, i161, i150 = (int(np.argmin(np.abs(f - x))) for x in (160.0, 161.0, 150.0))
    # s_1 peaks at the pair; s_2 rises from the floor by more than 20 dB there: a second mode
    assert abs(f[np.argmax(s[:, 0])] - 160.0) < 1.05
    assert min(s[i160, 1], s[i161, 1]) > 10 * s[i150, 1]
    assert s[:, 1].max() > 0.3 * s[:, 0].max()


@pytest.mark.parametrize("quantity", ["receptance", "mobility", "accelerance"])
def test_mif_dips_to_zero_at_normal_modes_for_every_quantity(quantity):
    phi = np.array([[1.0, 0.4], [0.5, -1.0]])
    model = _normal_mode_model([30.0, 70.0], [0.002, 0.002], phi)
    f = np.linspace(10, 100, 9001)
    frf = synthesize(model, f).as_quantity(quantity)
    m = mif(frf, reference=0)
    for fn in (30.0, 70.0):
        i = np.argmin(np.abs(f - fn))
        assert m[i] < 0.01
    assert np.nanmax(m) > 0.9


def test_mif_bad_reference_and_nonfinite_lines():
    frf = FRFSet(freq_hz=np.array([0.0, 1.0, 2.0]), H=np.array([[[1.0, np.nan, 1j]]]), quantity="accelerance")
    with pytest.raises(ValueError, match="reference index 1"):
        mif(frf, reference=1)
    m = mif(frf)
    assert np.isnan(m[0]) and np.isnan(m[1]) and m[2] == pytest.approx(0.0, abs=1e-12)
    s = cmif(frf)
    assert np.isnan(s[1, 0]) and s[0, 0] == pytest.approx(1.0)
