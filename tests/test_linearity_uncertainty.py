"""The noise the data show at each mode (analysis.uncertainty: window_line_correlation, mode_noise_factor; the
per-line noise of analysis.reciprocity.frf_error_variance), against Monte Carlo: seeded, small, fast."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from analysis.frf import FRFSet
from analysis.lsfd import fit_lsfd
from analysis.modal import ModalModel, pole_from_fz, synthesize
from analysis.reciprocity import frf_error_variance
from analysis.uncertainty import mode_noise_factor, window_line_correlation


def test_frf_error_variance_from_the_coherence_matches_the_scatter_of_h1():
    """The per-line noise the widening uses (analysis.reciprocity.frf_error_variance) against the scatter of
    H1 over repeated sets of 6 averages."""
    rng = np.random.default_rng(3)
    n_avg, trials, H = 6, 4000, 0.8 - 0.3j
    F = rng.normal(size=(trials, n_avg)) + 1j * rng.normal(size=(trials, n_avg))
    X = H * F + 0.5 * (rng.normal(size=(trials, n_avg)) + 1j * rng.normal(size=(trials, n_avg)))
    gff, gxx = np.sum(np.abs(F) ** 2, 1), np.sum(np.abs(X) ** 2, 1)
    gfx = np.sum(np.conj(F) * X, 1)
    h1, coh = gfx / gff, np.abs(gfx) ** 2 / (gff * gxx)
    frf = FRFSet(freq_hz=np.arange(1.0, trials + 1.0), H=h1[None, None, :], quantity="receptance", outputs=("o",),
                 references=("r",), coherence=coh[None, None, :], meta={"n_averages": [n_avg]})
    scatter = np.mean(np.abs(h1 - H) ** 2)
    assert np.mean(frf_error_variance(frf)) == pytest.approx(scatter, rel=0.1)


def test_window_line_correlation_matches_windowed_white_noise():
    rng = np.random.default_rng(4)
    n, tau_frac = 512, 0.25                       # window exp(-t / tau) with tau a quarter of the record
    w = np.exp(-np.arange(n) / (tau_frac * n))
    X = np.fft.fft(w * rng.normal(size=(3000, n)), axis=1)[:, 40:200]
    emp = [np.mean(X[:, :-m] * np.conj(X[:, m:])) / np.mean(np.abs(X) ** 2) if m else 1.0 for m in range(4)]
    fs = 1000.0
    rho = window_line_correlation(tau_frac * n / fs, fs / n, 3)
    assert np.max(np.abs(rho - np.array(emp))) < 0.03
    assert window_line_correlation(None, 1.0, 3).tolist() == [1, 0, 0, 0]


def _two_modes() -> tuple[ModalModel, np.ndarray]:
    lam = pole_from_fz(np.array([100.0, 400.0]), np.array([0.01, 0.01]))
    R = np.array([[[-2e3j, -4e3j]]])                 # one FRF (receptance-like units), both modes seen
    return ModalModel(poles=lam, residues=R, quantity="receptance"), np.arange(20.0, 480.0, 0.5)


def test_the_factor_is_one_for_white_noise_and_the_local_variance_ratio_where_lines_differ():
    model, f = _two_modes()
    flat = mode_noise_factor(model.poles, model.residues, f, 1.0)
    assert flat == pytest.approx([1.0, 1.0])
    line_var = np.where(f > 300, 25.0, 1.0)[None, None, :]
    c = mode_noise_factor(model.poles, model.residues, f, 1.0, line_var)
    assert c[0] == pytest.approx(1.0, abs=0.01) and c[1] == pytest.approx(25.0, rel=0.02)


def test_widened_standard_deviation_of_damping_matches_monte_carlo_at_a_noisy_band_top():
    """The mode at 400 Hz sits in lines 10 times noisier (in amplitude) than the rest of the band, as a soft
    hit's mode near the top of its band does: the fit's own damping standard deviation (one noise level
    for the band) understates the scatter of its estimate over repeated noise; widened by
    mode_noise_factor it matches."""
    model, f = _two_modes()
    clean = synthesize(model, f).H
    sd_line = 0.02 * np.abs(clean).mean() * np.where((f > 350) & (f < 450), 10.0, 1.0)
    rng = np.random.default_rng(11)
    zeta, own, wide = [], [], []
    for _ in range(60):
        noise = sd_line * (rng.normal(size=f.size) + 1j * rng.normal(size=f.size)) / np.sqrt(2)
        frf = FRFSet(freq_hz=f, H=clean + noise, quantity="receptance", outputs=("o",), references=("r",))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = fit_lsfd(frf, model.poles, residual_form="none")
        c = mode_noise_factor(fit.poles_raw, fit.model.residues, f, fit.noise_var, (sd_line ** 2)[None, None, :])
        zeta.append(fit.damping[1])
        own.append(fit.damping_std[1])
        wide.append(fit.damping_std[1] * np.sqrt(max(c[1], 1.0)))
    scatter = float(np.std(zeta, ddof=1))
    assert np.median(own) < 0.6 * scatter                       # the fit alone: too certain
    assert np.median(wide) == pytest.approx(scatter, rel=0.3)   # widened to the data's noise: honest


def test_linear_frame_struck_at_40_and_200_n_is_linear(tmp_path, capsys):
    """Two recordings of the linear frame through sim:// (three points, five hits each) at 40 N and 200 N: with
    the fits' own standard deviations the damping of the 997 Hz mode, near the top of the soft hits' band,
    moved "+48 %" beyond 3 of them; the widened ones call the frame linear."""
    import contextlib
    import io

    from acquisition.cli_capture import main as capture
    from analysis.cli_linearity import main

    paths = []
    for force, seed in ((40.0, 5006), (200.0, 5007)):
        cfg = tmp_path / f"f{force:.0f}.toml"
        cfg.write_text(f"[hammer]\namplitude_n = {force}\n")
        paths.append(str(tmp_path / f"f{force:.0f}.h5"))
        with contextlib.redirect_stdout(io.StringIO()):
            assert capture(["--device", f"sim://?seed={seed}&config={cfg}", "--out", paths[-1], "--points",
                            "right:6:-X,left:6:X,top:4:Z", "--hits", "5", "--auto", "-q"]) == 0
    assert main(paths) == 0
    out = capsys.readouterr().out
    assert "verdict: linear within the noise" in out
    # the mode near 997 Hz (996.5 Hz in the band both levels' data hold, 997.1 Hz in the soft hits' band)
    row = next(line for line in out.splitlines() if line.split() and line.split()[0].replace(".", "", 1).isdigit()
               and abs(float(line.split()[0]) - 997.0) < 1.0)
    assert row.split()[-1] == "no" and abs(float(row.split()[3])) > 20     # a large change, and its sd says so
