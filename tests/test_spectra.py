"""analysis.spectra: windows, one-sided spectra, H1/H2/coherence against analytic results."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from analysis.spectra import (
    FRFAccumulator,
    WindowSettings,
    exponential_window,
    force_window,
    hit_spectra,
    parse_duration,
    tau_from_end_fraction,
)

FS = 1024.0
N = 4096


def two_mode_filter(fs: float = FS):
    """A digital 2-mode system (driving-point like: residues of equal sign -> antiresonance between)."""
    poles = []
    for f0, z in ((60.0, 0.02), (150.0, 0.015)):
        p = np.exp((-z * 2 * np.pi * f0 + 1j * 2 * np.pi * f0 * math.sqrt(1 - z * z)) / fs)
        poles += [p, np.conj(p)]
    a = np.real(np.poly(poles))
    # residues of equal sign: sum of the two resonators
    a1 = np.real(np.poly(poles[:2]))
    a2 = np.real(np.poly(poles[2:]))
    b = np.convolve([0, 1.0], a2) + np.convolve([0, 1.0], a1)
    return b, a


def pulse(n: int = N, start: int = 20, width: int = 6, amp: float = 100.0) -> np.ndarray:
    f = np.zeros(n)
    k = np.arange(width)
    f[start:start + width] = amp * np.sin(np.pi * (k + 0.5) / width)
    return f


def test_parse_duration_forms():
    assert parse_duration("5ms") == pytest.approx(0.005)
    assert parse_duration("0.25s") == pytest.approx(0.25)
    assert parse_duration("0.1") == pytest.approx(0.1)
    assert parse_duration("256samples", fs_hz=1024) == pytest.approx(0.25)
    with pytest.raises(ValueError, match="sample rate"):
        parse_duration("10samples")
    with pytest.raises(ValueError, match="bad duration"):
        parse_duration("ten ms")


def test_force_window_shape():
    w = force_window(100, 100.0, trigger_index=10, width_s=0.2, taper_s=0.1)
    assert np.all(w[:30] == 1.0)
    m = np.arange(10)
    assert np.allclose(w[30:40], 0.5 * (1 + np.cos(np.pi * m / 10)))
    assert np.all(w[40:] == 0.0)


def test_exponential_window_end_fraction():
    k0 = 100
    tau = tau_from_end_fraction(0.01, (N - k0) / FS)
    w = exponential_window(N, FS, k0, tau)
    assert np.all(w[: k0 + 1] == 1.0)
    # one sample before the (virtual) end sample N, the window is 0.01 * exp(1/(tau fs))
    assert w[-1] * math.exp(-1 / (tau * FS)) == pytest.approx(0.01, rel=1e-12)
    ws = WindowSettings(exp_window_end_fraction=0.01).resolved(N, FS, k0)
    assert ws.exp_window_tau_s == pytest.approx(tau) and ws.exp_window_end_fraction is None


def test_parseval_one_sided_scaling():
    rng = np.random.default_rng(1)
    x = rng.normal(size=N)
    hs = hit_spectra(x, x[None, :], FS)
    df = FS / N
    assert np.sum(hs.Gff) * df == pytest.approx(np.mean(x ** 2), rel=1e-12)
    assert np.allclose(hs.Gfx[0].imag, 0) and np.allclose(hs.Gfx[0].real, hs.Gff)


def test_h1_equals_analytic_frf_of_decaying_system():
    b, a = two_mode_filter()
    f = pulse()
    x = signal.lfilter(b, a, f)
    acc = FRFAccumulator(["n:1:Z"], "n:2:Z")
    acc.add(hit_spectra(f, x, FS))
    _, Htrue = signal.freqz(b, a, worN=acc.freq_hz, fs=FS)
    H1 = acc.h1()[0]
    ok = acc.spectra()[0] > 1e-9 * acc.spectra()[0].max()  # lines where the pulse has energy
    assert ok.sum() > 0.9 * ok.size
    assert np.max(np.abs(H1[ok] - Htrue[ok]) / np.abs(Htrue[ok])) < 1e-8
    assert np.allclose(acc.h2()[0][ok], H1[ok], rtol=1e-8)
    assert np.allclose(acc.coherence()[0][ok], 1.0, atol=1e-9)


def test_exponential_window_shifts_poles_exactly():
    """exp(-t/tau) on force and response: H1 is the FRF of the system with z-poles scaled by exp(-dt/tau)."""
    b, a = two_mode_filter()
    f = pulse(start=0)
    x = signal.lfilter(b, a, f)
    tau = 0.5
    acc = FRFAccumulator(["n:1:Z"], "n:2:Z")
    acc.add(hit_spectra(f, x, FS, trigger_index=0, windows=WindowSettings(exp_window_tau_s=tau)))
    r = math.exp(-1 / (tau * FS))
    bw = b * r ** np.arange(b.size)
    aw = a * r ** np.arange(a.size)
    _, Hw = signal.freqz(bw, aw, worN=acc.freq_hz, fs=FS)
    assert np.max(np.abs(acc.h1()[0] - Hw) / np.abs(Hw)) < 1e-9
    fs_set = acc.frfset()
    assert fs_set.exp_window_tau_s == tau


def test_h1_over_h2_is_coherence_and_noise_brackets_truth():
    """H1/H2 = gamma^2 exactly. Force noise only: H1 biased low by Gff/(Gff + Gnn), H2 unbiased.
    Noise on force and response: |H1| <= |H| <= |H2| on average."""
    b, a = two_mode_filter()
    sigma_f = 0.5
    results = {}
    for label, sigma_x in (("force", 0.0), ("both", 0.5)):
        rng = np.random.default_rng(7)
        acc = FRFAccumulator(["n:1:Z"], "n:2:Z")
        Gff_true = 0.0
        for _ in range(20):
            f = pulse(amp=100 * rng.uniform(0.8, 1.2))
            x = signal.lfilter(b, a, f)
            Gff_true = Gff_true + hit_spectra(f, f, FS).Gff
            acc.add(hit_spectra(f + rng.normal(0, sigma_f, N), x + rng.normal(0, sigma_x, N), FS))
        H1, H2, c = acc.h1()[0], acc.h2()[0], acc.coherence()[0]
        assert np.allclose(H1 / H2, c, rtol=1e-9, atol=1e-12)
        _, H = signal.freqz(b, a, worN=acc.freq_hz, fs=FS)
        band = (acc.freq_hz > 20) & (acc.freq_hz < 200)  # the 6-sample pulse has its first zero at 256 Hz
        Gnn = 20 * 2 * sigma_f ** 2 / FS  # one-sided white-noise density summed over 20 hits
        predicted = np.mean((Gff_true / (Gff_true + Gnn))[band])
        results[label] = (np.mean(np.abs(H1[band]) / np.abs(H[band])), np.mean(np.abs(H2[band]) / np.abs(H[band])),
                          predicted)
        assert np.all(np.abs(H1[band]) <= np.abs(H2[band]) * (1 + 1e-12))
    h1, h2, pred = results["force"]
    assert h1 == pytest.approx(pred, abs=0.01) and h1 < 0.98
    assert h2 == pytest.approx(1.0, abs=0.005)
    h1, h2, _ = results["both"]
    assert h1 < 0.98 and h2 > 1.003


def test_coherence_drops_at_antiresonance():
    rng = np.random.default_rng(3)
    b, a = two_mode_filter()
    acc = FRFAccumulator(["n:1:Z"], "n:2:Z")
    for _ in range(10):
        f = pulse()
        x = signal.lfilter(b, a, f)
        acc.add(hit_spectra(f, x + rng.normal(0, 0.5, N), FS))
    fq = acc.freq_hz
    _, H = signal.freqz(b, a, worN=fq, fs=FS)
    between = (fq > 70) & (fq < 140)
    k_anti = np.flatnonzero(between)[np.argmin(np.abs(H[between]))]
    k_res = np.argmin(np.abs(fq - 60.0))
    c = acc.coherence()[0]
    assert c[k_res] > 0.99
    assert c[k_anti] < c[k_res] - 0.1


def test_rollback_is_exact_and_guarded():
    rng = np.random.default_rng(0)
    hits = [hit_spectra(rng.normal(size=512), rng.normal(size=(2, 512)), FS) for _ in range(3)]
    a = FRFAccumulator(["n:1:Z", "n:2:Z"], "n:3:Z")
    b = FRFAccumulator(["n:1:Z", "n:2:Z"], "n:3:Z")
    for h in hits:
        a.add(h)
    a.rollback()
    for h in hits[:2]:
        b.add(h)
    assert a.n_averages == 2
    assert np.array_equal(a.h1(), b.h1()) and np.array_equal(a.coherence(), b.coherence())
    a.rollback()
    a.rollback()
    with pytest.raises(ValueError, match="no hit to roll back"):
        a.rollback()
    with pytest.raises(ValueError, match="no hits accumulated"):
        a.h1()


def test_frfset_labels_and_quantity():
    rng = np.random.default_rng(2)
    acc = FRFAccumulator(["left:9:Y", "top:4:X"], "right:6:-X", unit="(m/s^2)/N")
    acc.add(hit_spectra(rng.normal(size=256), rng.normal(size=(2, 256)), FS))
    s = acc.frfset("H2")
    assert s.H.shape == (2, 1, 129)
    assert s.outputs == ("left:9:Y", "top:4:X") and s.references == ("right:6:-X",)
    assert s.quantity == "accelerance" and s.meta["estimator"] == "H2" and s.meta["n_averages"] == 1
    assert s.exp_window_tau_s is None


def test_bad_input_messages():
    with pytest.raises(ValueError, match="shape"):
        hit_spectra(np.zeros(100), np.zeros((2, 99)), FS)
    with pytest.raises(ValueError, match="trigger index"):
        hit_spectra(np.zeros(100), np.zeros(100), FS, trigger_index=100)
    with pytest.raises(ValueError, match="end fraction"):
        tau_from_end_fraction(1.5, 1.0)
    with pytest.raises(ValueError, match="not both"):
        WindowSettings(exp_window_tau_s=1.0, exp_window_end_fraction=0.01)
    acc = FRFAccumulator(["n:1:Z"], "n:2:Z")
    acc.add(hit_spectra(np.ones(64), np.ones(64), FS, windows=WindowSettings(exp_window_tau_s=0.1)))
    with pytest.raises(ValueError, match="tau"):
        acc.add(hit_spectra(np.ones(64), np.ones(64), FS, windows=WindowSettings(exp_window_tau_s=0.2)))


def test_inputs_not_modified():
    f = pulse()
    x = np.vstack([f, 2 * f])
    f0, x0 = f.copy(), x.copy()
    hit_spectra(f, x, FS, 10, WindowSettings(force_width_s=0.01, force_taper_s=0.005, exp_window_tau_s=0.5))
    assert np.array_equal(f, f0) and np.array_equal(x, x0)


def test_windows_a_few_samples_apart_average_but_different_windows_do_not():
    """Hits windowed by the window's end value get the time constant of their trigger sample: 0.333560 s
    and 0.333547 s (pyFRF's five hits) are one window and average; 1 % apart, or a window against none,
    is refused as differently processed."""
    from analysis.spectra import WINDOW_TAU_RTOL, HitSpectra, same_window_tau

    f = np.linspace(0.0, 100.0, 11)
    hit = lambda tau: HitSpectra(f, np.ones(11), np.ones((1, 11)), np.ones((1, 11), complex), tau)  # noqa: E731
    acc = FRFAccumulator(["n:1:Z"], "n:2:Z")
    acc.add(hit(0.3335604524213805))
    acc.add(hit(0.33354741303854085))
    assert acc.n_averages == 2 and acc.exp_window_tau_s == 0.3335604524213805
    with pytest.raises(ValueError, match="exponential tau"):
        acc.add(hit(0.3335604524213805 * 1.01))
    assert same_window_tau(None, None) and not same_window_tau(0.33, None) and not same_window_tau(None, 0.33)
    assert same_window_tau(1.0, 1.0 + 0.9 * WINDOW_TAU_RTOL) and not same_window_tau(1.0, 1.0 + 1.1 * WINDOW_TAU_RTOL)
