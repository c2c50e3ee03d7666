"""The band of FRFs without force spectra (a UFF export, an analyser's FRFs): its top from the FRFs'
own noise floor, and suspension modes named as such (analysis.bands.noise_limit_hz, analysis.suspension)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from analysis.bands import coherence_informative, default_band, noise_limit_hz, upper_limits
from analysis.frf import FRFSet
from analysis.modal import ModalModel, pole_from_fz, synthesize
from analysis.pipeline import fit_auto
from analysis.spectra import excitation_limit_hz
from analysis.suspension import suspension_modes

F = np.arange(0.0, 2001.0, 1.0)   # Hz, 1 Hz lines


def two_point_model(freqs, amps, quantity: str, zeta: float = 0.01) -> ModalModel:
    """Two outputs, one reference; residues ``amps`` (scaled by the pole's frequency)."""
    p = pole_from_fz(np.asarray(freqs, float), np.full(len(freqs), zeta))
    R = (np.asarray(amps, float)[None, None, :] * p.imag / 2j) * np.ones((2, 1, 1))
    R[1] *= -0.7
    return ModalModel(p, R, quantity=quantity, residual_form="none")


def half_sine_spectrum(width_s: float) -> np.ndarray:
    """The spectrum (N s) at ``F`` of a 1 N half-sine hammer pulse ``width_s`` long (first zero at 1.5 / width)."""
    fs = 200_000.0
    t = np.arange(0.0, 0.02, 1.0 / fs)
    pulse = np.where(t <= width_s, np.sin(np.pi * t / width_s), 0.0)
    return np.exp(-2j * np.pi * np.outer(F, t)) @ pulse / fs


def single_hit_set(seed: int = 1) -> tuple[FRFSet, float, np.ndarray]:
    """H1 of one hit: modes to 1650 Hz, response noise (white, 60 dB under the FRFs' level) over a
    half-sine force whose spectrum is 20 dB down at about 1.6 kHz; one average, coherence 1, no force
    spectrum. Returns the set, the force's 20 dB edge (Hz) and the true natural frequencies."""
    freqs = np.array([150.0, 420.0, 700.0, 1000.0, 1300.0, 1650.0])
    frf = synthesize(two_point_model(freqs, np.ones(freqs.size), "accelerance"), F)
    force = half_sine_spectrum(0.8e-3)
    rng = np.random.default_rng(seed)
    noise = (rng.standard_normal(frf.H.shape) + 1j * rng.standard_normal(frf.H.shape)) / np.sqrt(2)
    sigma = 1e-3 * np.sqrt(np.mean(np.abs(frf.H) ** 2))
    H = frf.H + sigma * noise * np.abs(force[0]) / force
    hit = replace(frf, H=H, coherence=np.ones(frf.H.shape), meta={"n_averages": [1]})
    edge = excitation_limit_hz(F, np.abs(force) ** 2)
    assert edge is not None
    return hit, edge, freqs


def test_single_hit_band_ends_where_the_noise_floor_shows_the_force_ending():
    hit, edge, freqs = single_hit_set()
    assert not coherence_informative(hit)
    limits = upper_limits(hit)
    assert "excitation" not in limits and "coherence" not in limits
    assert limits["noise"] == pytest.approx(edge, rel=0.1)
    lo, hi = default_band(hit)
    assert hi == pytest.approx(edge, rel=0.1)
    res = fit_auto(hit)
    assert res.band[1] <= 1.1 * edge
    assert np.all(res.freq_hz <= res.band[1])
    # every mode inside the excited band is fitted, and no pole is fitted to the noise above it
    for x in freqs[freqs < 0.9 * edge]:
        assert np.min(np.abs(res.freq_hz - x)) < 0.005 * x
    assert not np.any(res.freq_hz > edge)


def test_band_ends_where_the_modes_drown_in_a_flat_noise_floor():
    """Receptance falling with frequency into a flat noise floor; the two top modes lie 30 dB under it."""
    freqs = [100.0, 250.0, 400.0, 600.0, 1100.0, 1400.0]
    clean = synthesize(two_point_model(freqs, [1, 1, 1, 1, 1e-5, 1e-5], "receptance"), F)
    sigma = 3e-3 * float(np.abs(clean.H[0, 0, 600]))   # the 600 Hz peak stands 50 dB above the noise
    rng = np.random.default_rng(4)
    noisy = replace(clean, H=clean.H + sigma * (rng.standard_normal(clean.H.shape)
                                                + 1j * rng.standard_normal(clean.H.shape)) / np.sqrt(2))
    level = np.median(np.abs(clean.H), axis=(0, 1))
    drowned = float(F[np.flatnonzero(level >= 10 ** (10 / 20) * sigma)[-1]])   # the clean level 10 dB over the noise
    hi = noise_limit_hz(noisy)
    assert hi is not None
    assert hi == pytest.approx(drowned, rel=0.1)
    assert hi > 600.0 * 1.06   # the last standing mode with its margin
    res = fit_auto(noisy)
    assert res.band[1] <= hi + 1.0
    for x in freqs[:4]:
        assert np.min(np.abs(res.freq_hz - x)) < 0.005 * x
    # no pole for the drowned modes, none fitted to the noise above the band
    assert not np.any(res.freq_hz > 1000.0)


def test_noise_free_frfs_are_not_cut():
    clean = synthesize(two_point_model([150.0, 700.0, 1650.0], [1, 1, 1], "accelerance"), F)
    assert noise_limit_hz(clean) is None
    assert noise_limit_hz(replace(clean, meta={"n_averages": [1]})) is None
    assert default_band(clean)[1] == F[-1]


def test_noise_relative_to_the_frf_with_a_steady_force_is_not_cut():
    """One average, noise 1 % of the FRF (noise on a force that does not fall): the floor follows the
    resonances and antiresonances by 40 dB, its ratio to the FRF is steady; nothing ends the band."""
    freqs = np.array([40.0, 75.0, 78.0, 130.0, 180.0, 240.0, 310.0, 390.0])
    clean = synthesize(two_point_model(freqs, np.ones(freqs.size), "accelerance"), F)
    rng = np.random.default_rng(0)
    noisy = replace(clean, H=clean.H * (1 + 0.01 * (rng.standard_normal(clean.H.shape)
                                                    + 1j * rng.standard_normal(clean.H.shape)) / np.sqrt(2)),
                    meta={"n_averages": [1]})
    assert noise_limit_hz(noisy) is None
    assert default_band(noisy)[1] == F[-1]


def test_an_informative_coherence_takes_precedence_over_the_noise_floor():
    hit, _, _ = single_hit_set()
    averaged = replace(hit, coherence=np.full(hit.H.shape, 0.95), meta={"n_averages": [5]})
    assert coherence_informative(averaged)
    assert "noise" not in upper_limits(averaged)
    # the averages say one: a coherence of 1 says nothing, whatever the file holds
    assert not coherence_informative(replace(averaged, meta={"n_averages": [1]}))


def test_suspension_modes_sit_below_a_gap_to_the_first_elastic_mode():
    sus, elastic = suspension_modes([695.7, 17.99, 36.98, 1898.0, 36.99])
    assert sus.tolist() == pytest.approx([17.99, 36.98]) and elastic == pytest.approx(695.7)
    assert suspension_modes([12.9, 30.0, 45.0, 120.0])[1] is None         # no gap: all elastic
    assert suspension_modes([])[1] is None
    seven = [1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 400.0]                     # a rigid body has six
    assert suspension_modes(seven)[1] is None


def free_free_set() -> FRFSet:
    """A free-free structure on soft supports: rigid-body resonances at 40 and 75 Hz (3 %), elastic
    modes from 600 Hz (1 %); 0.3 % noise."""
    freqs = [40.0, 75.0, 600.0, 1100.0, 1700.0]
    model = two_point_model(freqs, [3, 3, 1, 1, 1], "accelerance")
    model = replace(model, poles=pole_from_fz(np.array(freqs), np.array([0.03, 0.03, 0.01, 0.01, 0.01])))
    clean = synthesize(model, F)
    rng = np.random.default_rng(2)
    return replace(clean, H=clean.H * (1 + 0.003 * (rng.standard_normal(clean.H.shape)
                                                    + 1j * rng.standard_normal(clean.H.shape))))


def test_unfitted_suspension_peaks_are_named_not_a_failure():
    frf = free_free_set()
    # the user's elastic modes only: the rigid-body peaks stay without a pole, as on the LADISK beam
    res = fit_auto(frf, band=(20.0, 2000.0), initial=[600.0, 1100.0, 1700.0], add_missing=False)
    assert sorted(res.suspension_hz) == pytest.approx([40.0, 75.0], rel=0.02)
    assert res.problems == () and res.success
    note = next(w for w in res.warnings if w.startswith("suspension mode(s) at"))
    assert "not fitted" in note and "first elastic mode (600" in note


def test_fitted_suspension_poles_are_kept_and_named():
    res = fit_auto(free_free_set(), band=(20.0, 2000.0))
    assert sorted(res.suspension_hz) == pytest.approx([40.0, 75.0], rel=0.02)
    assert np.sum(res.freq_hz < 100.0) == 2 and res.success   # kept in the model
    assert any("stand for them" in w for w in res.warnings)
    # the band above the rigid-body modes: nothing to name
    assert fit_auto(free_free_set(), band=(300.0, 2000.0)).suspension_hz == ()
