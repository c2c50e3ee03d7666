"""The whole automatic fit: default band, stabilization, selection, nonlinear LSFD (paper Fig. 1)."""
from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
import pytest

from analysis.frf import FRFSet
from analysis.modal import ModalModel, damping_ratio, natural_freq_hz, pole_from_fz, synthesize
from analysis.pipeline import FitError, check_band_edges, default_band, default_max_modes, fit_auto

F_TRUE = np.array([40.0, 75.0, 78.0, 130.0, 180.0, 240.0, 310.0, 390.0])
Z_TRUE = np.linspace(0.005, 0.02, F_TRUE.size)


def make_frf(freqs=F_TRUE, zetas=Z_TRUE, *, n_out=10, n_f=2000, fmax=500.0, f0=None, noise=0.0, seed=0,
             coherence=None) -> tuple[FRFSet, np.ndarray]:
    """Accelerance FRFs exactly of the LSFD model: modes plus physical residual terms."""
    rng = np.random.default_rng(seed)
    poles = pole_from_fz(freqs, zetas)
    phi = rng.standard_normal((n_out, poles.size))
    R = phi[:, None, :] * np.exp(0.05j * rng.standard_normal(poles.size)) * poles.imag / 2j
    model = ModalModel(poles, R, quantity="accelerance", residual_form="physical",
                       upper_residual=1e-6 * rng.standard_normal((n_out, 1)),
                       lower_residual=5.0 * rng.standard_normal((n_out, 1)))
    f = np.linspace(fmax / n_f if f0 is None else f0, fmax, n_f)
    frf = synthesize(model, f)
    if noise:
        n = (rng.standard_normal(frf.H.shape) + 1j * rng.standard_normal(frf.H.shape)) / np.sqrt(2)
        frf = replace(frf, H=frf.H + noise * np.abs(frf.H) * n)
    if coherence is not None:
        frf = replace(frf, coherence=np.broadcast_to(coherence, frf.H.shape))
    return frf, poles


@pytest.mark.parametrize("method", ["gn", "lm"])
@pytest.mark.parametrize("initial", ["lscf", "lsce"])
def test_fit_auto_exact_on_noise_free_data(method, initial):
    frf, truth = make_frf()
    fit_st = fit_auto(frf, method=method, initial=initial)
    res, st = fit_st
    assert res.success, res.message
    assert res.poles.size == truth.size
    p = res.poles[np.argsort(natural_freq_hz(res.poles))]
    assert np.max(np.abs(p - truth) / np.abs(truth)) < 1e-6
    np.testing.assert_allclose(damping_ratio(p), Z_TRUE, rtol=1e-5)
    lo, hi = fit_st.band
    assert lo == pytest.approx(frf.freq_hz[4])  # first line at or above 5 df
    assert hi == frf.freq_hz[-1]
    assert fit_st.warnings == ()


def test_fit_auto_one_percent_noise_finds_all_modes():
    frf, truth = make_frf(noise=0.01, seed=4)
    fit_st = fit_auto(frf)
    res, st = fit_st
    p = res.poles[np.argsort(natural_freq_hz(res.poles))]
    assert p.size == truth.size
    np.testing.assert_allclose(natural_freq_hz(p), F_TRUE, rtol=1e-4)
    np.testing.assert_allclose(damping_ratio(p), Z_TRUE, rtol=0.02)
    # LSFD improves the damping of the selected (stabilization) poles
    sel = np.sort_complex(fit_st.selected_poles)
    sel = sel[np.argsort(natural_freq_hz(sel))]
    err_sel = np.median(np.abs(damping_ratio(sel) / Z_TRUE - 1))
    err_fit = np.median(np.abs(damping_ratio(p) / Z_TRUE - 1))
    assert err_fit < err_sel


def test_default_band_skips_low_lines_and_low_coherence():
    frf, _ = make_frf(n_out=2, f0=0.0, n_f=2001)
    df = frf.freq_hz[1] - frf.freq_hz[0]
    assert default_band(frf) == (pytest.approx(5 * df), frf.freq_hz[-1])
    coh = np.ones(frf.freq_hz.size)
    coh[:40] = 0.3  # leading low-coherence lines (IEPE roll-off)
    frf2 = replace(frf, coherence=np.broadcast_to(coh, frf.H.shape))
    assert default_band(frf2)[0] == pytest.approx(frf.freq_hz[40])


def test_default_max_modes_counts_peaks():
    frf, _ = make_frf(n_out=3)
    n = default_max_modes(frf, (1.25, 500.0))
    assert 2 * 8 + 8 - 4 <= n <= 2 * 8 + 8  # 7 or 8 peaks (75/78 may merge), 2 * peaks + 8


def test_band_edges_move_or_warn():
    lam = pole_from_fz([100.0, 200.0], [0.01, 0.01])  # half-power bandwidths 2 and 4 Hz
    band, warn = check_band_edges(lam, (99.0, 205.0), (10.0, 400.0), (True, True))
    assert band == (pytest.approx(100.0 - 3 * 2.0), pytest.approx(200.0 + 3 * 4.0))
    assert warn == []
    band, warn = check_band_edges(lam, (99.0, 205.0), (98.0, 400.0), (True, False))
    assert band == (99.0, 205.0)
    assert len(warn) == 2 and "lower band edge" in warn[0] and "upper band edge" in warn[1]


def test_user_band_edge_warning_and_automatic_move(caplog):
    frf, truth = make_frf(n_out=4)
    with caplog.at_level(logging.WARNING, logger="analysis.pipeline"):
        fit_st = fit_auto(frf, band=(20.0, 400.0))
        res, st = fit_st
    assert any("390" in w and "upper band edge" in w for w in fit_st.warnings)
    assert "upper band edge" in caplog.text
    # near the end of the data the automatic edge cannot move out either: warned too
    fit_st2 = fit_auto(frf.band(1.0, 400.0))
    res2, st2 = fit_st2
    assert any("upper band edge" in w for w in fit_st2.warnings)
    assert fit_st2.band[1] <= 400.0


def test_user_frequencies_and_poles():
    frf, truth = make_frf(n_out=4)
    fit_st = fit_auto(frf, initial=F_TRUE * (1 + 2e-3))
    res, st = fit_st
    assert res.poles.size == F_TRUE.size and st is not None
    np.testing.assert_allclose(np.sort(natural_freq_hz(res.poles)), F_TRUE, rtol=1e-8)
    fit_st2 = fit_auto(frf, initial=truth * (1 + 1e-3), method="gn")
    res2, st2 = fit_st2
    assert st2 is None
    np.testing.assert_allclose(np.sort(natural_freq_hz(res2.poles)), F_TRUE, rtol=1e-8)


def test_n_modes_limits_the_selection():
    frf, truth = make_frf(n_out=4)
    fit_st = fit_auto(frf, n_modes=3)
    res, st = fit_st
    assert res.poles.size == 3


def test_no_modes_is_a_clear_error():
    rng = np.random.default_rng(0)
    f = np.linspace(1, 500, 1000)
    noise = FRFSet(f, rng.standard_normal((2, 1, f.size)) + 1j * rng.standard_normal((2, 1, f.size)))
    with pytest.raises(FitError, match="no stable physical poles"):
        fit_auto(noise, max_modes=6)
    with pytest.raises(ValueError, match="initial"):
        fit_auto(noise, initial="era")
    with pytest.raises(TypeError, match="FRFSet"):
        fit_auto(np.zeros(10))


@pytest.mark.realdata
def test_real_uff_three_frfs(shared_data):
    """Real measured data: ladisk/pyuff ``data/measurement.uff`` (MIT), 3 accelerance FRFs, df 1 Hz.

    No truth is known: the automatic fit must converge, find one pole per visible resonance
    (the summed magnitude has 6 clear peaks below 1 kHz) and reproduce the measured FRFs
    (median relative error below -20 dB on every FRF).
    """
    from scipy.signal import find_peaks

    from analysis.inputs import load_input
    from analysis.modal import synthesize

    frf = load_input(shared_data / "pyuff_3frf" / "measurement.uff")
    fit_st = fit_auto(frf)
    res, st = fit_st
    assert res.success, res.message
    lo, hi = res.band
    sel = (frf.freq_hz >= lo) & (frf.freq_hz <= hi)
    s = 20 * np.log10(np.sqrt(np.sum(np.abs(frf.H[..., sel].reshape(-1, sel.sum())) ** 2, axis=0)))
    peaks, _ = find_peaks(s, prominence=20.0)
    assert res.poles.size == peaks.size == 6
    np.testing.assert_allclose(np.sort(res.freq_hz), frf.freq_hz[sel][peaks], atol=1.0)  # within a line
    G = synthesize(res.model, frf.freq_hz[sel]).H
    rel = np.abs(frf.H[..., sel] - G) / np.abs(frf.H[..., sel])
    assert np.all(20 * np.log10(np.median(rel, axis=-1)) < -20)


def _mains_frf(n_out=3, seed=1):
    """Modes at 1 % damping plus a narrow electrical line at 300 Hz (5 x 60 Hz) on every FRF."""
    frf, poles = make_frf(np.array([120.0, 210.0, 380.0]), np.array([0.01, 0.01, 0.01]), n_out=n_out, seed=seed,
                          noise=0.002)
    f = frf.freq_hz
    df = f[1] - f[0]
    line = np.exp(-0.5 * ((f - 300.0) / (0.4 * df)) ** 2)  # one line wide
    H = frf.H + 0.5 * np.max(np.abs(frf.H)) * line * np.exp(1j * np.arange(n_out))[:, None, None]
    return replace(frf, H=H), poles


def test_misfit_step_does_not_fit_a_mains_line_as_a_mode():
    frf, truth = _mains_frf()
    fit_st = fit_auto(frf)
    res, st = fit_st
    assert not np.any(np.abs(res.freq_hz - 300.0) < 2.0), res.freq_hz
    np.testing.assert_allclose(np.sort(res.freq_hz), natural_freq_hz(truth), rtol=1e-3)
    assert any("mains line" in w and "300 Hz" in w for w in fit_st.warnings), fit_st.warnings
    # the guard off: the line is not named a mains line; the local trial of the misfit step (a fit
    # over the lines around it, on the residual of the other poles) does not keep a one-line
    # spike as a mode either (before the local trials, a full refit kept it as a very sharp pole)
    fit_off = fit_auto(frf, mains_hz=None)
    assert not any("mains line" in w for w in fit_off.warnings), fit_off.warnings
    assert not np.any(np.abs(fit_off.freq_hz - 300.0) < 1.0), fit_off.freq_hz
    # or leave the line out of the fit altogether: the modes fit better
    fit_st_x = fit_auto(frf, exclude_hz=[300.0])
    res_x, st_x = fit_st_x
    assert res_x.poles.size == 3 and any("left out of the fit" in w for w in fit_st_x.warnings)
    np.testing.assert_allclose(np.sort(res_x.freq_hz), natural_freq_hz(truth), rtol=1e-4)


def test_misfit_step_runs_with_given_frequencies_and_keeps_them():
    frf, truth = make_frf(n_out=4)
    given = np.delete(F_TRUE, 2)  # the close neighbour 78 Hz of 75 Hz is not given
    fit_st = fit_auto(frf, initial=given)
    res, st = fit_st
    assert res.poles.size == F_TRUE.size
    np.testing.assert_allclose(np.sort(res.freq_hz), F_TRUE, rtol=1e-6)
    assert any("added a pole at 78" in w for w in fit_st.warnings)
    res_old, _ = fit_auto(frf, initial=given, add_missing=False)  # the old behaviour: the user's model as given
    assert res_old.poles.size == given.size
    res_c, _ = fit_auto(frf, initial=np.delete(truth, 2) * (1 + 1e-4))  # complex poles too
    np.testing.assert_allclose(np.sort(res_c.freq_hz), F_TRUE, rtol=1e-6)


def test_fit_auto_finds_two_modes_two_lines_apart():
    """One FRF (every residue MAC is 1), 230 / 230.5 Hz at 0.08 %: 2 lines apart, half-power
    bandwidths ~0.37 Hz (1.5 lines). The stabilization sees one pole; the misfit step adds the
    other because it clearly lowers the local cost and both keep distinct residues (before:
    rejected as closer than 3 lines)."""
    df = 0.25
    f2 = 230.0 + 2 * df
    frf, truth = make_frf(np.array([120.0, 230.0, f2, 380.0]), np.array([0.002, 0.0008, 0.0008, 0.002]),
                          n_out=1, n_f=2000, fmax=500.0, noise=0.002, seed=3)
    assert frf.freq_hz[1] - frf.freq_hz[0] == pytest.approx(df)
    fit_st = fit_auto(frf)
    res, st = fit_st
    fr = np.sort(res.freq_hz)
    assert res.poles.size == 4, (fr, fit_st.warnings)
    np.testing.assert_allclose(fr, natural_freq_hz(truth), atol=0.02)
    assert any("close pair" in w for w in fit_st.warnings)


def test_success_means_converged_and_physically_sensible() -> None:
    """A fit that stops with implausible poles is not a success, in the result and
    in the JSON document; a single average is flagged."""
    from analysis.fit_result import FitResult, assess_fit
    from analysis.report import result_to_dict

    frf, _ = make_frf(noise=0.01)
    frf = replace(frf, meta={**frf.meta, "n_averages": 1})
    fit = fit_auto(frf)
    assert fit.success and fit.status == "converged" and fit.problems == ()
    assert any("one average per point" in w for w in fit.warnings)
    doc = result_to_dict(fit, frf)
    assert doc["success"] is True and doc["converged"] is True and doc["problems"] == []
    # the same LSFD result judged on a band that leaves its poles outside, with a 73 % damping pole
    lsfd = replace(fit.lsfd, damping=np.r_[fit.lsfd.damping[:-1], 0.73])
    problems = assess_fit(lsfd, (0.0, 200.0))
    assert any("outside the fitted band" in p for p in problems)
    assert any("damping ratio of 73 %" in p for p in problems)
    bad = FitResult(lsfd=lsfd, stabilization=fit.stabilization, band=(0.0, 200.0), selected_poles=fit.selected_poles,
                    problems=tuple(problems))
    assert bad.converged and not bad.success and bad.status == "implausible"
    doc = result_to_dict(bad, frf)
    assert doc["success"] is False and doc["converged"] is True and doc["fit_status"] == "implausible"
    assert "not physically sensible" in doc["message"]
    # an undetermined frequency (standard deviation of the order of the frequency) is a problem too
    lsfd2 = replace(fit.lsfd, freq_hz_std=np.r_[fit.lsfd.freq_hz_std[:-1], 1.7e3])
    assert any("not determined by the data" in p for p in assess_fit(lsfd2, fit.band))


def test_default_band_comes_from_the_analyser_the_hammer_and_the_coherence() -> None:
    """The automatic band ends where the data stop supporting a fit."""
    from analysis.bands import upper_limits

    frf, _ = make_frf(n_f=2000, fmax=500.0)
    assert default_band(frf)[1] == pytest.approx(500.0)  # nothing known: the top line
    # a 1000 Hz sample rate: the analyser's flat band ends at 1000 / 2.56 = 390.6 Hz
    with_fs = replace(frf, sample_rate_hz=1000.0)
    assert upper_limits(with_fs)["analyser"] == pytest.approx(390.625)
    assert default_band(with_fs)[1] <= 390.625 and default_band(with_fs)[1] > 390.0
    # a soft hammer whose force spectrum is 20 dB down at 250 Hz (two points, the lower counts)
    soft = replace(with_fs, meta={"excitation_limit_hz": [300.0, 250.0]})
    assert default_band(soft)[1] == pytest.approx(250.0, abs=frf.line_spacing_hz)
    # coherence that falls for good above 200 Hz
    f = frf.freq_hz
    coh = np.where(f < 200.0, 0.98, 0.2)
    noisy = replace(frf, coherence=np.broadcast_to(coh, frf.H.shape))
    assert upper_limits(noisy)["coherence"] == pytest.approx(200.0, abs=10.0)
    # one average: coherence 1 everywhere says nothing and does not cut the band
    assert "coherence" not in upper_limits(replace(frf, coherence=np.ones(frf.H.shape)))


def test_stabilization_order_respects_the_band_it_is_given() -> None:
    """A narrow band of a noisy FRF no longer asks for more modes than its lines hold."""
    frf, _ = make_frf(n_out=1, noise=0.2, n_f=2000, fmax=500.0)  # noise peaks: the old rule asked for 50 modes
    band = (4.0, 70.0)  # 265 lines
    n = default_max_modes(frf, band)
    assert n <= 265 // 11
    from analysis.stabilization import stabilization

    stab = stabilization(frf, n, method="lsce", band=band)  # raised "too few lines" before
    assert max(stab.orders) == n


def test_fit_figure_spans_the_band_numbers_the_modes_and_says_what_it_leaves_out() -> None:
    """The x axis spans the fitted band (10 % margin), the modes are numbered in
    order of frequency, a single column keeps its y labels, and a partial set says so."""
    from analysis.plots import fit_figure

    frf, _ = make_frf(n_out=3, noise=0.01, n_f=2000, fmax=500.0)
    fit = fit_auto(frf, band=(30.0, 200.0))
    fig = fit_figure(frf, fit.lsfd, pairs=[(0, 0)], band=fit.band)
    axm = fig.axes[0]
    lo, hi = fit.band
    assert axm.get_xlim() == pytest.approx((lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo)))
    numbers = [t.get_text() for t in axm.texts]
    in_view = [f for f in np.sort(fit.freq_hz) if lo - 0.1 * (hi - lo) <= f <= hi + 0.1 * (hi - lo)]
    assert len(numbers) == len(in_view) and numbers == sorted(numbers, key=int)
    assert axm.get_ylabel().startswith("|H| [dB") and fig.axes[1].get_ylabel() == "phase [deg]"
    assert fig._suptitle is not None and fig._suptitle.get_text().startswith("1 of 3 FRFs shown")
    full = fit_figure(frf, fit.lsfd, pairs=[(0, 0), (1, 0), (2, 0)], band=fit.band)
    assert full._suptitle is None


def test_many_mains_lines_give_one_warning_with_a_count() -> None:
    """A misfit peak on every mains harmonic is reported once, with a count, not
    once per line (227 lines on the LADISK beam before)."""
    frf, truth = make_frf(np.array([120.0, 210.0, 380.0]), np.array([0.01, 0.01, 0.01]), n_out=3, seed=1,
                          noise=0.002)
    f = frf.freq_hz
    df = f[1] - f[0]
    lines = sum(np.exp(-0.5 * ((f - k * 50.0) / (0.4 * df)) ** 2) for k in range(2, 10))
    frf = replace(frf, H=frf.H + 0.03 * np.max(np.abs(frf.H)) * lines * np.exp(1j * np.arange(3))[:, None, None])
    fit = fit_auto(frf)
    mains = [w for w in fit.warnings if "mains line" in w]
    assert len(mains) == 1, fit.warnings
    assert "more misfit peak(s) on mains lines" in mains[0]
    assert not any(np.any(np.abs(fit.freq_hz - k * 50.0) < 1.0) for k in range(2, 10)), fit.freq_hz


def _chain_with_undriven_stretch(seed: int = 3) -> tuple[FRFSet, np.ndarray]:
    """Accelerances of a 3-mass chain (masses 1, 1.5, 0.8 kg; springs to ground and between; one
    discrete damper, so the damping is not proportional), by direct inversion of
    ``K - w^2 M + i w C``, on 0.0625 Hz lines up to 200 Hz, without coherence. The drive has no
    energy below 12 Hz: there the FRF is noise 30 times its level (as a shaker's random drive leaves
    it), elsewhere 1 %. Returns the set and the chain's natural frequencies (Hz)."""
    rng = np.random.default_rng(seed)
    M = np.diag([1.0, 1.5, 0.8])
    k = np.array([6.0e4, 2.0e5, 3.0e5])   # to ground at mass 1, 1-2, 2-3
    K = np.array([[k[0] + k[1], -k[1], 0.0], [-k[1], k[1] + k[2], -k[2]], [0.0, -k[2], k[2]]])
    C = 1e-4 * K + np.diag([0.0, 0.0, 8.0])
    f = np.arange(1, 3201) * 0.0625
    w = 2 * np.pi * f
    H = np.stack([-wk ** 2 * np.linalg.inv(K - wk ** 2 * M + 1j * wk * C)[:, 0] for wk in w], axis=-1)
    level = np.where(f < 12.0, 30.0, 0.01)
    n = (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)) / np.sqrt(2)
    H = H + level * np.median(np.abs(H), axis=-1, keepdims=True) * n
    frf = FRFSet(freq_hz=f, H=H[:, None, :], quantity="accelerance", outputs=("m:1:X", "m:2:X", "m:3:X"),
                 references=("m:1:X",), unit="m/s^2/N")
    A = np.block([[np.zeros((3, 3)), np.eye(3)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    lam = np.linalg.eigvals(A)
    return frf, np.sort(np.abs(lam[lam.imag > 0])) / (2 * np.pi)


def test_without_coherence_noise_bumps_do_not_start_the_fit() -> None:
    """Visible peaks start the fit only where the coherence confirms them: FRFs without coherence
    show noise bumps (10 dB, two lines wide) by the dozen where the drive has no energy; the fit starts
    from the stabilization's selection alone there and still fits the chain's three modes."""
    from analysis.selection import select_poles
    from analysis.visibility import unaccounted_peaks, visible_peaks

    frf, f_true = _chain_with_undriven_stretch()
    fit = fit_auto(frf)
    assert fit.stabilization is not None
    # the premise: the data show visible peaks far from every mode, which a seeded start would take
    bumps, _ = unaccounted_peaks(visible_peaks(frf, (float(frf.freq_hz[0]), fit.band[1])), f_true, frf.line_spacing_hz)
    assert len(bumps) >= 5
    assert fit.selected_poles.size == select_poles(fit.stabilization).size
    f = fit.lsfd.freq_hz
    assert f.size == 3
    np.testing.assert_allclose(np.sort(f), f_true, rtol=2e-3)


def _chain_with_fading_coherence(coh_floor: float, drop_bandwidths: float) -> tuple[FRFSet, np.ndarray]:
    """H1 accelerances of a grounded 4-mass spring chain (Rayleigh damping; force at the first mass,
    all four masses measured) whose coherence fades from 0.97 to ``coh_floor`` around
    ``drop_bandwidths`` half-power bandwidths of the top mode off that mode (a shaker running out of
    force), with the random error of 54 averages (``sqrt((1 - g^2) / (2 n g^2))`` of |H| per line).
    Returns the FRFs and the chain's poles (rad/s, from its state matrix)."""
    m = np.array([1.0, 0.8, 1.2, 0.9])
    k = np.array([4.0e5, 3.0e5, 5.0e5, 2.5e5])
    K = np.diag(k + np.r_[k[1:], 0.0]) - np.diag(k[1:], 1) - np.diag(k[1:], -1)
    M = np.diag(m)
    C = 2.0 * M + 1.5e-5 * K
    f = np.linspace(0.05, 250.0, 5000)
    w = 2 * np.pi * f
    H = np.stack([-x ** 2 * np.linalg.solve(K - x ** 2 * M + 1j * x * C, np.eye(4)[:, 0]) for x in w], axis=-1)
    A = np.block([[np.zeros((4, 4)), np.eye(4)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    lam = np.linalg.eigvals(A)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(lam.imag)]
    top, bw = natural_freq_hz(lam[-1]), -lam[-1].real / np.pi
    coh = coh_floor + (0.97 - coh_floor) / (1.0 + np.exp((f - top - drop_bandwidths * bw) / bw))
    rng = np.random.default_rng(3)
    err = np.sqrt((1 - coh) / (2 * 54 * coh)) * np.abs(H)
    H = H + err * (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)) / np.sqrt(2)
    return FRFSet(freq_hz=f, H=H[:, None, :], outputs=tuple(f"c:{i + 1}:X" for i in range(4)), references=("c:1:X",),
                  unit="(m/s^2)/N", coherence=np.broadcast_to(coh, (4, 1, f.size)).copy(), meta={"averages": 54}), lam


@pytest.mark.parametrize("drop_bandwidths, kept", [(-1.0, True), (-2.0, False)])
def test_coherence_edge_takes_a_resonance_whole_or_not_at_all(drop_bandwidths, kept) -> None:
    """A coherence that fades on the rising flank of the top mode ends the automatic band there
    (the sec. 3.1 case of an edge through a resonance); the band takes the mode whole when the
    coherence over its top is still usable (0.33 here) and leaves it out, edge before its flank,
    when it is not (0.2); the fitted modes match the chain's poles either way (within 0.01 %: a
    strong mode just above the band, taken by the residual terms, shifts the others by a few of
    their standard deviations)."""
    from analysis.bands import upper_limits

    frf, lam = _chain_with_fading_coherence(0.1, drop_bandwidths)
    f_true, bw = natural_freq_hz(lam), -lam.real / np.pi
    cut = upper_limits(frf)["coherence"]
    assert f_true[-1] - 3 * bw[-1] < cut < f_true[-1]  # the coherence alone ends the band on the flank
    hi = default_band(frf)[1]
    fit = fit_auto(frf)
    assert fit.success, fit.message
    rows = fit.table()
    n_expected = 4 if kept else 3
    if kept:
        assert hi >= f_true[-1] + 2.5 * bw[-1]
    else:
        assert hi <= f_true[-1] - 2.5 * bw[-1]
    assert fit.band[1] == pytest.approx(hi)
    assert len(rows) == n_expected
    for row, f0 in zip(rows, f_true[:n_expected]):
        assert abs(row["freq_hz"] / f0 - 1) < 1e-4
    if kept:  # the mode at the edge, taken whole, is not biased beyond its scatter
        assert abs(rows[-1]["freq_hz"] - f_true[-1]) < 4 * rows[-1]["freq_hz_std"]
