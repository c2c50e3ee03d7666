"""acquisition.hitcheck: force peak, pulse width, double hits and overloads against known pulses."""
from __future__ import annotations

import math

import numpy as np
import pytest

from acquisition.hitcheck import HitCheckSettings, check_hit, pulse_extent

FS = 51200.0


def half_sine(n: int, start_s: float, width_s: float, amp: float, fs: float = FS) -> np.ndarray:
    t = np.arange(n) / fs - start_s
    return np.where((t >= 0) & (t <= width_s), amp * np.sin(np.pi * np.clip(t, 0, width_s) / width_s), 0.0)


def test_peak_and_width_of_half_sine():
    T = 1.2e-3
    f = half_sine(4096, 0.005, T, 250.0)
    c = check_hit(f, FS)
    assert c.force_peak_n == pytest.approx(250.0, rel=1e-3)
    # sin(pi t/T) >= 0.1 for a time T (1 - 2 asin(0.1)/pi)
    expected_ms = 1e3 * T * (1 - 2 * math.asin(0.1) / math.pi)
    assert c.pulse_width_ms == pytest.approx(expected_ms, abs=1e3 / FS + 1e-9)
    assert not c.double_hit and c.verdict.accept is None and c.verdict.reasons == []


def test_double_hit_detected_with_ratio_and_reason():
    f = half_sine(4096, 0.005, 1e-3, 200.0) + half_sine(4096, 0.009, 1e-3, 60.0)
    c = check_hit(f, FS)
    assert c.double_hit
    assert c.second_peak_ratio == pytest.approx(0.3, abs=0.01)
    assert c.verdict.accept is False and "double hit" in c.verdict.reasons[0]


def test_small_rebound_below_threshold_is_not_a_double_hit():
    rng = np.random.default_rng(0)
    f = half_sine(4096, 0.005, 1e-3, 200.0) + half_sine(4096, 0.009, 1e-3, 10.0) + rng.normal(0, 0.5, 4096)
    c = check_hit(f, FS)
    assert c.second_peak_ratio == pytest.approx(0.05, abs=0.01)
    assert not c.double_hit  # default threshold: 10 % of the first peak
    assert check_hit(f, FS, settings=HitCheckSettings(double_hit_fraction=0.03)).double_hit


def test_negative_pulse_and_undershoot():
    f = -half_sine(2048, 0.005, 1e-3, 100.0)
    f[600:700] += 30.0  # opposite-sign undershoot is not a second hit
    c = check_hit(f, FS)
    assert c.force_peak_n == pytest.approx(-100.0, rel=1e-3)
    assert not c.double_hit


def test_overload_rejected_naming_channel():
    f = half_sine(2048, 0.005, 1e-3, 100.0)
    c = check_hit(f, FS, overload=[False, False, True], channel_names=["force", "acc1", "acc2 top:4:X"])
    assert c.verdict.accept is False
    assert len(c.verdict.reasons) == 1 and "channel 3 (acc2 top:4:X)" in c.verdict.reasons[0]
    assert c.overload == (False, False, True)


def test_pulse_extent_indices():
    f = np.array([0, 0, 1, 5, 10, 5, 0.5, 0, 0.0])
    k, s, e = pulse_extent(f, 0.1)
    assert (k, s, e) == (4, 2, 6)


def test_bad_input():
    with pytest.raises(ValueError, match="1-D"):
        check_hit(np.zeros((2, 10)), FS)
    with pytest.raises(ValueError, match="sample rate"):
        check_hit(np.zeros(10), 0.0)
    with pytest.raises(ValueError, match="double-hit fraction"):
        HitCheckSettings(double_hit_fraction=1.5)
