"""Time-data effects detected from synthetic hits with known truth."""
from __future__ import annotations

import numpy as np
import pytest

from analysis.diagnosis.timedata import (
    detect_amplitude_nonlinearity,
    detect_double_hit,
    detect_input_noise,
    detect_overload,
    diagnose_hits,
)

FS = 2048.0
N = 4096
PRE = 200


def _pulse(amp: float, width_s: float = 1e-3, at: int = PRE) -> np.ndarray:
    x = np.zeros(N)
    k = int(round(width_s * FS))
    x[at:at + k] = amp * np.sin(np.pi * np.arange(k) / k)
    return x


def _response(force: np.ndarray, freqs=(40.0, 95.0), zeta=0.01) -> np.ndarray:
    t = np.arange(N) / FS
    h = np.zeros(N)
    for f in freqs:
        wn = 2 * np.pi * f
        wd = wn * np.sqrt(1 - zeta ** 2)
        h += np.exp(-zeta * wn * t) * np.sin(wd * t) / wd
    return np.convolve(force, h)[:N] / FS


def _hits(amps, freqs_of=lambda a: (40.0, 95.0), double=(), seed=0, noise=0.0):
    rng = np.random.default_rng(seed)
    F, X = [], []
    for i, a in enumerate(amps):
        f = _pulse(a)
        if i in double:
            f = f + _pulse(0.3 * a, at=PRE + int(0.004 * FS))
        X.append(_response(f, freqs_of(a)))
        F.append(f + noise * rng.standard_normal(N))
    return np.array(F), np.array(X)[:, None, :]


def test_double_hits_counted_and_measured():
    F, _ = _hits([50.0] * 10, double=(2, 5, 7))
    c = detect_double_hit(F, FS)
    assert c["present"] and c["parameters"]["hits"] == [2, 5, 7]
    assert c["parameters"]["fraction"] == pytest.approx(0.3)
    assert c["parameters"]["delay_s"] == pytest.approx(0.004, abs=1.5 / FS)
    assert c["parameters"]["ratio"] == pytest.approx(0.3, abs=0.02)
    assert not detect_double_hit(_hits([50.0] * 4)[0], FS)["present"]


def test_overload_from_full_scale():
    F, X = _hits([10.0, 10.0, 200.0, 10.0, 200.0])
    data = np.concatenate([F[:, None, :], X], axis=1)
    fs = [100.0, np.abs(X).max() * 10]
    c = detect_overload(np.clip(data, -np.array(fs)[None, :, None], np.array(fs)[None, :, None]), fs)
    assert c["present"] and c["parameters"]["hits"] == [2, 4] and c["parameters"]["channels"] == [0]


def test_input_noise_level_recovered():
    F, _ = _hits([20.0] * 8, noise=0.05, seed=3)
    c = detect_input_noise(F, FS, band=(5, 900))
    assert c["parameters"]["noise_rms_n"] == pytest.approx(0.05, rel=0.1)
    assert c["parameters"]["worst_bias_db"] < 0


def test_amplitude_nonlinearity_softening_found_and_linear_case_clean():
    amps = [10.0, 100.0] * 5
    soft = lambda a: (40.0 * (0.99 if a > 50 else 1.0), 95.0 * (0.99 if a > 50 else 1.0))   # noqa: E731
    F, X = _hits(amps, soft)
    c = detect_amplitude_nonlinearity(F, X, FS, band=(10, 200))
    assert c["present"]
    assert c["parameters"]["mean_df_percent"] == pytest.approx(-1.0, abs=0.15)
    F, X = _hits(amps)
    assert not detect_amplitude_nonlinearity(F, X, FS, band=(10, 200))["present"]
    F, X = _hits([50.0] * 6)
    one = detect_amplitude_nonlinearity(F, X, FS, band=(10, 200))
    assert not one["present"] and "two levels" in one["evidence"]


def test_diagnose_hits_puts_present_effects_first():
    F, X = _hits([50.0] * 6, double=(1,))
    causes = diagnose_hits(F, X, FS, (10, 200))
    assert causes[0]["effect"] == "double_hit" and causes[0]["present"]
    assert {c["effect"] for c in causes} >= {"double_hit", "input_noise", "amplitude_nonlinearity"}
