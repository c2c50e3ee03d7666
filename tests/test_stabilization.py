"""Stabilization flags, automatic hint-free pole selection, the stabilization plot."""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from analysis.frf import FRFSet
from analysis.mac import mac, mac_matrix
from analysis.modal import ModalModel, damping_ratio, natural_freq_hz, pole_from_fz, synthesize
from analysis.plots import plot_stabilization
from analysis.selection import poles_from_frequencies, select_clusters, select_poles
from analysis.stabilization import (
    NEW,
    STABLE_DAMP,
    STABLE_FREQ,
    STABLE_MAC,
    StabilizationResult,
    quick_residues,
    stabilization,
)

F_TRUE = np.array([40.0, 75.0, 78.0, 130.0, 180.0, 240.0, 310.0, 390.0])  # 75/78: 4 % apart
Z_TRUE = np.linspace(0.005, 0.02, F_TRUE.size)


def make_frf(freqs=F_TRUE, zetas=Z_TRUE, *, n_out=12, n_f=2000, fmax=500.0, noise=0.0, seed=0,
             out_of_band=True) -> tuple[FRFSet, np.ndarray]:
    """Accelerance FRFs (one reference exciting every mode) plus a mode below and above the band."""
    rng = np.random.default_rng(seed)
    f_all = np.concatenate([[3.0], freqs, [800.0]]) if out_of_band else np.asarray(freqs, float)
    z_all = np.concatenate([[0.02], zetas, [0.02]]) if out_of_band else np.asarray(zetas, float)
    poles = pole_from_fz(f_all, z_all)
    phi = rng.standard_normal((n_out, f_all.size))
    R = phi[:, None, :] * np.exp(0.05j * rng.standard_normal(f_all.size)) * poles.imag / 2j
    model = ModalModel(poles, R, quantity="accelerance", residual_form="none")
    frf = synthesize(model, np.linspace(fmax / n_f, fmax, n_f))
    if noise:
        n = (rng.standard_normal(frf.H.shape) + 1j * rng.standard_normal(frf.H.shape)) / np.sqrt(2)
        frf = replace(frf, H=frf.H + noise * np.abs(frf.H) * n)
    return frf, pole_from_fz(freqs, zetas)


BAND = (20.0, 480.0)


@pytest.mark.parametrize("method", ["lsce", "lscf"])
def test_true_modes_flagged_stable_noise_free(method):
    frf, truth = make_frf()
    st = stabilization(frf, 20, method=method, band=BAND)
    assert st.orders == tuple(range(1, 21))
    for n, p, s in zip(st.orders[-5:], st.poles[-5:], st.status[-5:]):
        for lam in truth:
            k = np.argmin(np.abs(p - lam))
            assert abs(p[k] - lam) / abs(lam) < 1e-4
            assert s[k] == STABLE_MAC, (method, n, natural_freq_hz(lam))
    # classes never exceed the stages; non-physical poles are -1
    allst = np.concatenate(st.status)
    assert set(np.unique(allst)) <= {-1, NEW, STABLE_FREQ, STABLE_DAMP, STABLE_MAC}
    for p, ph, s in zip(st.poles, st.physical, st.status):
        assert np.all(s[~ph] == -1)
        assert np.all(damping_ratio(p[ph]) > 0)


def test_many_frfs_projected_shapes_keep_mac():
    """More FRFs than the shape projection keeps (60 > 2 * 8 + 8): MAC flags are unchanged."""
    frf, truth = make_frf(freqs=np.array([60.0, 140.0, 300.0]), zetas=np.array([0.01, 0.01, 0.015]), n_out=60)
    st = stabilization(frf, 8, method="lscf", band=BAND)
    for p, s, m in zip(st.poles[4:], st.status[4:], st.mac[4:]):
        for lam in truth:
            k = np.argmin(np.abs(p - lam))
            assert s[k] == STABLE_MAC and m[k] > 1 - 1e-6


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_selection_finds_exactly_the_true_modes_with_one_percent_noise(seed):
    frf, truth = make_frf(noise=0.01, seed=seed)
    st = stabilization(frf, 24, method="lscf", band=BAND)
    p = select_poles(st)
    assert p.size == truth.size, np.round(natural_freq_hz(p), 2)
    np.testing.assert_allclose(natural_freq_hz(p), F_TRUE, rtol=3e-3)
    np.testing.assert_allclose(damping_ratio(p), Z_TRUE, rtol=0.3)


def test_selection_n_modes_keeps_most_persistent():
    frf, truth = make_frf(noise=0.01)
    st = stabilization(frf, 24, method="lscf", band=BAND)
    clusters = select_clusters(st)
    p3 = select_poles(st, n_modes=3)
    assert p3.size == 3
    top = sorted(natural_freq_hz(np.array([c.pole for c in clusters[:3]])))
    np.testing.assert_allclose(natural_freq_hz(p3), top)
    assert all(clusters[i].n_orders >= clusters[i + 1].n_orders for i in range(len(clusters) - 1))


def _hand_made(lines, scatter, n_orders=20):
    """A StabilizationResult built by hand: persistent pole lines plus one-off scattered poles."""
    poles, status, phys, mac = [], [], [], []
    rng = np.random.default_rng(3)
    for n in range(1, n_orders + 1):
        p = [pole_from_fz(f * (1 + 1e-4 * rng.standard_normal()), z) for f, z, start in lines if n >= start]
        if n in scatter:
            p.append(pole_from_fz(scatter[n], 0.03))
        p = np.array(p, dtype=complex)
        poles.append(p)
        st = np.full(p.size, STABLE_MAC)
        status.append(st)
        phys.append(np.ones(p.size, bool))
        mac.append(np.ones(p.size))
    return StabilizationResult(tuple(range(1, n_orders + 1)), tuple(poles), tuple(phys), tuple(status),
                               tuple(mac), "lscf", (1.0, 500.0), 0.01, 0.05, 0.02, 0.2)


def test_selection_rule_persistence_and_median():
    # two lines 4 % apart, one line appearing late (order 17 of 20 -> 4 orders, passes min_orders and
    # fraction), scattered one-off poles never selected
    lines = [(100.0, 0.01, 3), (104.0, 0.012, 5), (300.0, 0.02, 17)]
    scatter = {4: 150.0, 9: 151.0, 12: 220.0, 15: 152.5}
    st = _hand_made(lines, scatter)
    p = select_poles(st)
    np.testing.assert_allclose(natural_freq_hz(p), [100.0, 104.0, 300.0], rtol=1e-3)
    np.testing.assert_allclose(damping_ratio(p), [0.01, 0.012, 0.02], rtol=1e-9)
    # a stricter persistence drops the late line
    p2 = select_poles(st, min_orders=6)
    np.testing.assert_allclose(natural_freq_hz(p2), [100.0, 104.0], rtol=1e-3)


def test_poles_from_frequencies_takes_damping_from_diagram():
    frf, truth = make_frf()
    st = stabilization(frf, 16, method="lscf", band=BAND)
    p = poles_from_frequencies([40.1, 130.2], st)
    np.testing.assert_allclose(damping_ratio(p), Z_TRUE[[0, 3]], rtol=1e-3)
    np.testing.assert_allclose(natural_freq_hz(p), [40.1, 130.2])
    q = poles_from_frequencies([10.0])
    assert damping_ratio(q)[0] == pytest.approx(0.01)
    with pytest.raises(ValueError, match="positive"):
        poles_from_frequencies([-3.0])


def test_quick_residues_exact_and_mac():
    frf, truth = make_frf(n_out=5)
    all_poles = pole_from_fz(np.concatenate([[3.0], F_TRUE, [800.0]]), np.concatenate([[0.02], Z_TRUE, [0.02]]))
    Y = frf.H.reshape(5, -1)
    A = quick_residues(frf.omega, Y, all_poles, frf.quantity, "none")
    # the synthetic model's residues are recovered exactly (noise-free, complete pole set)
    rng = np.random.default_rng(0)
    phi = rng.standard_normal((5, all_poles.size))
    R = phi * np.exp(0.05j * rng.standard_normal(all_poles.size)) * all_poles.imag / 2j
    # in-band modes exact; the 3 Hz and 800 Hz modes are barely determined by the 0.25..500 Hz lines
    np.testing.assert_allclose(A[:, 1:-1], R[:, 1:-1], rtol=1e-6)
    M = mac_matrix(A, A * (2 - 1j))
    np.testing.assert_allclose(np.diag(M), 1.0, rtol=1e-12)
    assert np.all((M >= 0) & (M <= 1 + 1e-12))


def test_refined_diagram_lines_are_straight():
    """Noise-free modal data: LSFD-refined poles sit on the true poles at every order from 3 on."""
    frf, truth = make_frf(freqs=np.array([60.0, 140.0, 300.0]), zetas=np.array([0.01, 0.01, 0.015]), n_out=4,
                          n_f=800, out_of_band=False)
    st = stabilization(frf, 8, method="lsce", band=BAND, refine_lsfd=True, refine_iterations=20)
    assert st.method == "lsce+lsfd"
    for lam in truth:
        near = np.array([p[np.argmin(np.abs(p - lam))] for p in st.poles[2:]])
        assert np.max(np.abs(near - lam)) / abs(lam) < 1e-7


def test_plot_and_json(tmp_path):
    frf, truth = make_frf(n_out=4, noise=0.01)
    st = stabilization(frf, 16, method="lsce", band=BAND)
    out = plot_stabilization(st, frf, tmp_path / "stab.png", selected=select_poles(st))
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20000
    doc = json.loads(json.dumps(st.to_dict(), allow_nan=False))
    assert doc["method"] == "lsce" and len(doc["orders"]) == 16
    assert {"freq_hz", "damping", "class"} <= set(doc["orders"][-1]["poles"][0])


def test_bad_arguments():
    frf, _ = make_frf(n_out=2)
    with pytest.raises(ValueError, match="method"):
        stabilization(frf, 5, method="era")
    with pytest.raises(ValueError, match="max_modes"):
        stabilization(frf, 0)
    with pytest.raises(ValueError, match="tol_freq"):
        stabilization(frf, 5, tol_freq=0)
    with pytest.raises(ValueError, match="n_modes"):
        select_poles(stabilization(frf, 5, method="lscf"), n_modes=0)


def test_mac_is_scale_and_phase_blind_and_zero_for_orthogonal_or_zero_vectors() -> None:
    a = np.array([1.0, 2.0 - 1j, -0.5j])
    assert mac(a, (3 - 4j) * a) == pytest.approx(1.0, abs=1e-15)
    b = np.array([2.0 + 1j, -1.0, 0.0])  # a^H b = 0
    assert abs(np.vdot(a, b)) < 1e-15 and mac(a, b) == 0.0
    assert mac(a, np.zeros(3)) == 0.0
    # the same number the matrix form gives, and by the formula written out
    c = np.array([1.0, 1j, 1.0])
    expected = abs(np.vdot(a, c)) ** 2 / (np.vdot(a, a).real * np.vdot(c, c).real)
    assert mac(a, c) == pytest.approx(expected) == pytest.approx(mac_matrix(a[:, None], c[:, None])[0, 0])
