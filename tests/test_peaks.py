"""Peaks, prominences and widths (analysis.peaks) agree with scipy.signal's definitions."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from analysis.peaks import find_peaks, peak_widths, prominences


def curves():
    rng = np.random.default_rng(7)
    for k in range(400):
        n = int(rng.integers(0, 50))
        # integer curves have flat tops and equal minima; smooth noisy curves have many small peaks
        yield rng.integers(0, 4, n).astype(float) if k % 2 else np.cumsum(rng.standard_normal(n))


@pytest.mark.parametrize("prominence", [None, 0.0, 0.7, 2.0])
def test_peaks_and_prominences_as_scipy(prominence):
    for x in curves():
        ours, props = find_peaks(x, prominence=prominence)
        ref, ref_props = scipy.signal.find_peaks(x, prominence=prominence)
        np.testing.assert_array_equal(ours, ref)
        if prominence is not None:
            np.testing.assert_allclose(props["prominences"], ref_props["prominences"])


@pytest.mark.parametrize("rel_height", [0.5, 1.0, 0.25])
def test_widths_as_scipy(rel_height):
    for x in curves():
        peaks, _ = find_peaks(x)
        if peaks.size:
            np.testing.assert_allclose(peak_widths(x, peaks, rel_height=rel_height),
                                       scipy.signal.peak_widths(x, peaks, rel_height=rel_height)[0])


def test_resonance_peak_width_is_its_half_power_bandwidth():
    f = np.linspace(80.0, 120.0, 4001)
    fn, zeta = 100.0, 0.01
    p2 = 1.0 / ((1 - (f / fn) ** 2) ** 2 + (2 * zeta * f / fn) ** 2)   # |H|^2 of one mode
    peaks, _ = find_peaks(p2)
    assert peaks.size == 1 and f[peaks[0]] == pytest.approx(fn * np.sqrt(1 - 2 * zeta ** 2), abs=0.01)
    width_hz = peak_widths(p2, peaks, rel_height=0.5)[0] * (f[1] - f[0])
    assert width_hz == pytest.approx(2 * zeta * fn, rel=0.02)
    assert prominences(p2, peaks)[0] == pytest.approx(p2.max() - p2[0])


def test_short_and_2d_curves():
    assert find_peaks(np.array([1.0, 2.0]))[0].size == 0
    with pytest.raises(ValueError, match="1-D"):
        find_peaks(np.zeros((2, 3)))


def test_every_peak_rule_is_named_once_and_applies_its_level():
    """One table of peak rules: a dB rule keeps peaks by their prominence in dB, a relative rule by a
    fraction of the curve's maximum; the modules read their levels from it."""
    from analysis import bands, driving_point, visibility
    from analysis.peaks import PEAK_RULES

    assert {r.name for r in PEAK_RULES.values()} == set(PEAK_RULES)
    assert visibility.VISIBLE_PROMINENCE_DB == PEAK_RULES["visible"].prominence_db
    assert bands.EDGE_PEAK_DB == PEAK_RULES["band_edge"].prominence_db
    assert driving_point.PEAK_PROMINENCE_DB == PEAK_RULES["modal_peaks"].prominence_db
    x = np.zeros(50)
    x[10], x[30] = 100.0, 4.0          # 4 % of the maximum: below the 5 % of the level rule
    pk, prom = PEAK_RULES["level_peaks"].find(x)
    assert list(pk) == [10] and list(prom) == [100.0]
    db = np.zeros(50)
    db[10], db[30] = 7.0, 5.0          # 6 dB rule: one of the two
    assert list(PEAK_RULES["modal_peaks"].find(db)[0]) == [10]
    with pytest.raises(ValueError, match="relative"):
        PEAK_RULES["level_peaks"].options()
