"""The station's plot data and control lease against known answers (no server, no browser)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from acquisition.hitcheck import HitCheck, HitVerdict
from acquisition.setup import default_setup
from acquisition.station.payloads import _envelope, band_edges, hit_payload, range_advice
from acquisition.station.state import Lease


def test_band_edges_of_a_known_spectrum():
    f = np.linspace(0, 2000, 2001)
    db = -f / 50.0  # falls 1 dB per 50 Hz: -10 dB at 500 Hz, -20 dB at 1000 Hz
    edges = band_edges(f, db)
    # the level is taken without the DC line (an offset spikes there): 0.02 dB below 0 here
    assert edges["minus10_hz"] == pytest.approx(501.0) and edges["minus20_hz"] == pytest.approx(1001.0)
    assert band_edges(f[:400], db[:400]) == {"minus10_hz": None, "minus20_hz": None}  # never falls that far


def test_envelope_keeps_the_peaks_and_the_size_bound():
    t = np.arange(100_000, dtype=float)
    y = np.zeros_like(t)
    y[12_345], y[77_777] = 5.0, -3.0
    tt, yy = _envelope(t, y, 1000)
    assert yy.size <= 1000 and yy.max() == 5.0 and yy.min() == -3.0
    assert tt[np.argmax(yy)] == 12_345 and np.all(np.diff(tt) >= 0)


def test_force_band_of_a_half_sine_pulse_matches_its_analytic_spectrum():
    fs, n, width = 51200.0, 16384, 2e-3
    data = np.zeros((2, n))
    k = np.arange(round(width * fs) + 1)
    data[0, 128:128 + k.size] = 100 * np.sin(np.pi * k / (k.size - 1))
    data[1] = np.random.default_rng(0).normal(size=n)
    p = hit_payload(data, fs, 128, 128, 0, [1], ["force", "acc"], ["N", "m/s^2"], 0.02)
    # |F(f)| of a half sine of duration T is proportional to |cos(pi f T)| / |1 - (2 f T)^2|
    f = np.linspace(1e-3, 1.5 / width, 200_001)
    mag_db = 20 * np.log10(np.abs(np.cos(np.pi * f * width) / (1 - (2 * f * width) ** 2)))
    for level in (10, 20):
        truth = f[np.nonzero(mag_db < -level)[0][0]]
        assert p["spectrum"][f"minus{level}_hz"] == pytest.approx(truth, rel=0.01)
    assert max(p["force"]["y"]) == pytest.approx(100.0, rel=1e-3)
    assert p["pretrigger_ms"] == pytest.approx(-128 / fs * 1e3) and p["force_window_ms"] == pytest.approx(20.0)


def test_an_overload_suggests_the_next_range_that_holds_the_peak():
    setup = default_setup()  # force channel: 2.25 mV/N on a 1 V range
    check = HitCheck(500.0, 1.0, 0, 10, 0.0, False, (True, False, False, False), HitVerdict(False, ["overload"]))
    data = np.zeros((4, 16))
    data[0, 3] = 600.0  # N: 1.35 V at the input
    advice = range_advice(check, setup, (0.5, 1.0, 2.0, 5.0, 10.0), data)
    assert len(advice) == 1 and "set its range to 2 V" in advice[0]
    data[0, 3] = 10_000.0  # 22.5 V: no range holds it
    assert "largest range" in range_advice(check, setup, (0.5, 1.0, 2.0, 5.0, 10.0), data)[0]


def test_the_lease_lapses_only_when_its_tab_stops_renewing():
    now = [0.0]
    lease = Lease(ttl_s=15.0, clock=lambda: now[0])
    assert lease.acquire("a") and not lease.acquire("b")
    now[0] = 14.0
    assert lease.acquire("a") and lease.holds("a")  # renewed
    now[0] = 28.0
    assert not lease.acquire("b") and lease.holds("a")
    now[0] = 29.5
    assert not lease.holds("a") and lease.acquire("b") and lease.holds("b")
    assert lease.acquire("a", take=True) and not lease.holds("b")


class _Point:
    """A point's running average as the station holds it (one reference, the sensors as outputs)."""

    def __init__(self, frf, reference):
        one = frf.select(references=[reference])
        self._frf = replace(one, meta={**one.meta, "n_averages": 4})
        self.point = self.reference = reference
        self.outputs = tuple(frf.outputs)
        self.n_averages = 4

    def frfset(self, estimator="H1"):
        return self._frf


def test_quality_lines_name_the_driving_point_and_the_reciprocal_pairs_measured_so_far():
    from quality_support import SENSORS, roving_test

    from acquisition.station.payloads import quality_payload
    from simulator.stand import TestStand

    clean = roving_test(TestStand(seed=2))
    pts = [_Point(clean, p) for p in SENSORS]
    first = quality_payload(pts[0], pts[:1])  # the first point: its driving point, no pair yet
    assert first == [f"driving point {SENSORS[0]}: phase within +-90 deg, an antiresonance between every two "
                     "resonances"]
    lines = quality_payload(pts[2], pts)  # the third: the pairs among the three points
    assert lines[0] == "reciprocity: reciprocal (3 pair(s))" and lines[1].startswith(f"driving point {SENSORS[2]}: ")
    off = roving_test(TestStand(seed=5), gain={"top:2:Z": 1.1})
    pts = [_Point(off, p) for p in SENSORS]
    bad = quality_payload(pts[1], pts)
    assert bad[0].startswith("reciprocity: not reciprocal") and "top:2:Z" in bad[0]
    # a point struck where no sensor is has neither check
    away = _Point(clean, SENSORS[0])
    away.point = away.reference = "top:4:X"
    away._frf = replace(away._frf, references=("top:4:X",))
    assert quality_payload(away, pts) == []
