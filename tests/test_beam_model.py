"""The beam FE model of the ModeLAB case study (benchmarks/studies/beam_model.py): the Euler-Bernoulli
beam gives the free-free beam's exact frequencies, shear and rotary inertia lower the higher modes the
more, and the folder it writes is a user's FE model the diagnosis reads."""
from __future__ import annotations

import numpy as np
import pytest
from benchmark_modules import load_benchmark

from analysis.fe_model import FEVariants, load_fe_model, sparse_modes

BETA_L = np.array([4.730040745, 7.853204624, 10.99560784, 14.13716549])     # free-free roots of cos cosh = 1


def _hz(theory: str, n_el: int = 130) -> np.ndarray:
    bm = load_benchmark("studies/beam_model.py")
    K, M = bm.beam_matrices(1.3, 0.0356, 0.03, n_el, theory)
    f = sparse_modes(K, M, 1500.0)[0]
    return f[f > 1.0][:4]


def test_euler_bernoulli_beam_gives_the_exact_free_free_frequencies():
    E, rho, h, L = 210e9, 7850.0, 0.0356, 1.3
    exact = BETA_L ** 2 / (2 * np.pi * L ** 2) * np.sqrt(E * h ** 2 / 12 / rho)
    np.testing.assert_allclose(_hz("euler"), exact, rtol=2e-6)


def test_shear_and_rotary_inertia_lower_the_higher_modes_the_more():
    ratio = {t: _hz(t, 520) / _hz("euler", 520) for t in ("rotary", "shear", "timoshenko")}
    for r in ratio.values():
        assert np.all(np.diff(r) < 0) and np.all(r < 1)            # each lowers mode n+1 more than mode n
    # Timoshenko's correction is about the sum of the two (first order in (lambda r / L)^2)
    np.testing.assert_allclose(1 - ratio["timoshenko"], (1 - ratio["rotary"]) + (1 - ratio["shear"]), rtol=0.05)
    assert ratio["timoshenko"][3] == pytest.approx(0.977, abs=0.002)


def test_the_written_folder_is_an_fe_model_with_the_hammer_points(tmp_path):
    bm = load_benchmark("studies/beam_model.py")
    toml = bm.write_beam(tmp_path / "beam", height_m=0.0356, n_el=104)
    fe = load_fe_model(toml)
    assert fe.n_dof == 210 and fe.total_mass_kg() == pytest.approx(7850 * 1.3 * 0.0356 * 0.03, rel=1e-9)
    sim = FEVariants(fe, ["beam:4:Z"], [f"beam:{k}:Z" for k in range(1, 10)], max_freq_hz=1500.0)
    f = sim.model(None, {}).freq_hz
    np.testing.assert_allclose(f[:4], _hz("euler", 104), rtol=1e-9)
    with pytest.raises(ValueError, match="no node at 0.1"):
        bm.write_beam(tmp_path / "bad", n_el=100)


@pytest.mark.realdata
def test_modelab_beam_wants_shear_and_rotary_inertia_not_the_sensor_mass(shared_data):
    """The case study of docs/diagnosis-realdata.md: the measured frequency ratios (2.740, 5.325, 8.698) lie
    below Euler-Bernoulli's; held out one mode at a time, the Timoshenko beam predicts each within 0.1 %
    (a gain of more than 20 dB), the accelerometer's mass predicts worse than the plain beam."""
    study = load_benchmark("studies/beam_realdata.py")
    f, _, _ = study.measured_modes(shared_data)
    np.testing.assert_allclose(f[1:] / f[0], [2.740, 5.325, 8.698], atol=1e-3)
    h = 0.0356
    plain, _ = study.loo(lambda p: study.beam_hz("euler", h)[0], f, None)
    timo, h_fit = study.loo(lambda p: study.beam_hz("timoshenko", p)[0], f, (0.3 * h, 6 * h))
    mass, _ = study.loo(lambda p: study.beam_hz("euler", h, p)[0], f, (0.0, 2.0))
    rms = {k: float(np.sqrt(np.mean(v ** 2))) for k, v in (("plain", plain), ("timo", timo), ("mass", mass))}
    assert rms["plain"] > 1.0 and np.max(np.abs(timo)) < 0.1
    assert 20 * np.log10(rms["plain"] / rms["timo"]) > 20 and rms["mass"] > rms["plain"]
    assert 0.035 < h_fit < 0.045
