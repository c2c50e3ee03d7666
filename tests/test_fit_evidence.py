"""What counts as a resonance of the structure, on small synthetic sets: a hump between two
antiresonances in one FRF of several is not one (its phase barely turns), peaks of two close modes
with different shapes are two resonances (merged by shape and bandwidth, not by distance alone), a
coherence of 1 on every line with the number of averages unknown confirms nothing, and a UFF 58
file's number of averages is read as another writer puts it in an ID line."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

_TESTS = str(Path(__file__).resolve().parent)
if _TESTS not in sys.path:
    sys.path.insert(0, _TESTS)

from uff58_text import Record58, write_uff58_text  # noqa: E402

from analysis.frf import FRFSet  # noqa: E402
from analysis.modal import ModalModel, pole_from_fz, synthesize  # noqa: E402
from analysis.visibility import resonances, visible_peaks  # noqa: E402


def _pz(f_hz: float, zeta: float) -> complex:
    w = 2 * np.pi * f_hz
    return complex(-zeta * w, w * np.sqrt(1 - zeta ** 2))


def _quad(s: np.ndarray, r: complex) -> np.ndarray:
    return (s - r) * (s - np.conj(r))


def test_a_hump_between_two_antiresonances_in_one_frf_of_several_is_not_a_resonance() -> None:
    """FRF 1: modes at 85 and 118 Hz with two antiresonances (99 and 104 Hz) between them, which leave a
    15 dB hump at 101.5 Hz whose phase turns a few degrees; FRF 2: the same modes without the zeros, a
    hundred times stronger there (the CMIF shows no hump). The hump is not a visible peak; both modes are."""
    f = np.arange(60.0, 140.0, 0.125)
    s = 2j * np.pi * f
    poles = _quad(s, _pz(85.0, 0.01)) * _quad(s, _pz(118.0, 0.01))
    hump = _quad(s, _pz(99.0, 0.002)) * _quad(s, _pz(104.0, 0.002)) / poles * (2 * np.pi * 100.0) ** 2
    smooth = 1e4 * (2 * np.pi * 100.0) ** 4 / poles
    frf = FRFSet(freq_hz=f, H=np.stack([hump, smooth])[:, None, :], outputs=("a:1:Z", "a:2:Z"),
                 references=("a:3:Z",), unit="(m/s^2)/N")
    db = 20 * np.log10(np.abs(hump))
    top = int(np.argmax(np.where((f > 99.5) & (f < 103.5), db, -np.inf)))
    assert db[top] - max(db[np.argmin(np.abs(f - 99.0))], db[np.argmin(np.abs(f - 104.0))]) > 10.0   # 10 dB high
    peaks = visible_peaks(frf, (61.0, 139.0))
    assert not [v for v in peaks if abs(v.freq_hz - f[top]) < 1.0], peaks
    for mode in (85.0, 118.0):
        assert [v for v in peaks if abs(v.freq_hz - mode) < 1.0 and v.curve_index >= 0]


def test_peaks_of_two_close_modes_with_different_shapes_are_two_resonances() -> None:
    """Two modes 0.5 Hz (two lines) apart, each seen mainly by its own output: the two FRFs' peaks lie
    within the reach of one resonance, but their operating shapes differ (MAC near 0): two resonances."""
    model = ModalModel(pole_from_fz([100.0, 100.5], [0.001, 0.001]),
                       [[[-40j, -0.8j]], [[-0.8j, -40j]]], quantity="receptance")
    frf = synthesize(model, np.arange(90.0, 110.0, 0.25))
    peaks = [v for v in visible_peaks(frf, (91.0, 109.0)) if v.curve_index >= 0]
    assert sorted(round(v.freq_hz, 2) for v in peaks) == [100.0, 100.5]
    groups = resonances(peaks, frf.line_spacing_hz)
    assert len(groups) == 2, groups


def test_one_peak_seen_through_two_frfs_stays_one_resonance() -> None:
    """One mode whose peak two FRFs show a line apart (a neighbour shifts one of them): one shape, one
    resonance."""
    model = ModalModel(pole_from_fz([100.0, 140.0], [0.004, 0.004]), [[[-40j, 30j]], [[-20j, -25j]]],
                       quantity="receptance")
    frf = synthesize(model, np.arange(90.0, 150.0, 0.25))
    peaks = [v for v in visible_peaks(frf, (91.0, 149.0)) if abs(v.freq_hz - 100.0) < 1.0]
    assert len({v.curve_index for v in peaks}) >= 2
    assert len(resonances(peaks, frf.line_spacing_hz)) == 1


def test_a_coherence_of_one_everywhere_with_the_averages_unknown_confirms_nothing() -> None:
    """A one-line spike 20 dB high: with a coherence of 1 on every line and no number of averages (a file
    that does not say) it is judged as without coherence (one line wide, no flanks: not a resonance); with
    five averages stated, the same coherence confirms it."""
    f = np.arange(10.0, 300.0, 1.0)
    H = np.full(f.size, 1e-3 + 0j)
    k = int(np.argmin(np.abs(f - 100.0)))
    H[k] *= 10.0
    unknown = FRFSet(freq_hz=f, H=H[None, None, :], outputs=("a:1:Z",), references=("a:2:Z",),
                     coherence=np.ones((1, 1, f.size)))
    assert not [v for v in visible_peaks(unknown, (20.0, 290.0)) if abs(v.freq_hz - f[k]) < 0.5]
    from analysis.visibility import coherence_bounds_nothing

    assert coherence_bounds_nothing(unknown)
    five = FRFSet(freq_hz=f, H=H[None, None, :], outputs=("a:1:Z",), references=("a:2:Z",),
                  coherence=np.ones((1, 1, f.size)), meta={"n_averages": [5]})
    assert not coherence_bounds_nothing(five)
    assert [v for v in visible_peaks(five, (20.0, 290.0)) if abs(v.freq_hz - f[k]) < 0.5]


def test_uff58_averages_as_another_writer_puts_them_in_an_id_line(tmp_path) -> None:
    """Dataset 58 has no field for the number of averages: a writer that states it in an ID line in its own
    words ("Averages: 54", "54 averages") is read; a file that does not say leaves it unknown."""
    from analysis.uff import read_uff58

    f = np.arange(0.0, 50.0, 0.5)
    H = 1.0 / (1.0 - (f / 20.0) ** 2 + 0.02j * f / 20.0)
    coh = np.linspace(0.6, 0.99, f.size)
    for ids, expected in ((("FRF", "NONE", "01-JAN-24 12:00:00", "Averages: 54", "NONE"), [54]),
                          (("FRF 54 averages", "NONE", "NONE", "NONE", "NONE"), [54]),
                          (("FRF", "NONE", "NONE", "NONE", "NONE"), None)):
        path = tmp_path / f"f{len(list(tmp_path.iterdir()))}.uff"
        write_uff58_text(path, [Record58(4, (2, 3), (1, 3), 0.0, 0.5, H, ids),
                                Record58(6, (2, 3), (1, 3), 0.0, 0.5, coh, ids)])
        s = read_uff58(path)
        assert s.meta.get("n_averages") == expected, (ids, s.meta)
