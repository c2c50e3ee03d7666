"""The mains grid from the data (analysis.mains_grid): 50 Hz, 60 Hz or unknown from the narrow lines
at the grids' harmonics, the fit's mains check on that grid, and ``fit --mains``."""
from __future__ import annotations

import json

import numpy as np
import pytest

from analysis import cli_fit
from analysis.frf import FRFSet
from analysis.mains_grid import detect_mains_grid, mains_for_fit, parse_mains_option
from analysis.pipeline import fit_auto
from analysis.uff import write_uff58

#: modes of the synthetic structure (Hz) and their damping; none on a harmonic of 50 or 60 Hz
MODES_HZ = (37.3, 133.7, 277.1, 512.9)
ZETA = 0.01


def structure(seed: int = 0, df: float = 0.125, top: float = 640.0, coherence_spread: float = 0.01) -> FRFSet:
    """3 accelerances of 4 modes, 1 % noise, coherence 0.97 with a small scatter (many averages)."""
    rng = np.random.default_rng(seed)
    f = np.arange(1, int(top / df) + 1) * df
    w = 2 * np.pi * f
    H = np.zeros((3, 1, f.size), complex)
    for k, fr in enumerate(MODES_HZ):
        lam = -ZETA * 2 * np.pi * fr + 2j * np.pi * fr * np.sqrt(1 - ZETA ** 2)
        for o in range(3):
            r = (1 + o) * (-1) ** (k * o) * (1 + 0.3 * k) * 1j
            H[o, 0] += r / (1j * w - lam) + np.conj(r) / (1j * w - np.conj(lam))
    H *= -(w ** 2)
    H *= 1 + 0.01 * (rng.normal(size=H.shape) + 1j * rng.normal(size=H.shape))
    C = np.clip(0.97 + coherence_spread * rng.normal(size=H.shape), 0, 1)
    return FRFSet(f, H, "accelerance", ("n:1:Z", "n:2:Z", "n:3:Z"), ("n:1:Z",), "(m/s^2)/N", C,
                  meta={"estimator": "H1", "n_averages": 30})


def with_lines(frf: FRFSet, spikes_hz=(), dips_hz=()) -> FRFSet:
    """``frf`` with electrical lines: a spike of |H| 20 dB on the line nearest each of ``spikes_hz``
    (in every FRF) and a coherence dip to 0.3 on the line nearest each of ``dips_hz`` (|H| as it is)."""
    H, C = frf.H.copy(), frf.coherence.copy()
    for x in spikes_hz:
        i = int(np.argmin(np.abs(frf.freq_hz - x)))
        H[..., i] *= 10.0
        C[..., i] = 0.5
    for x in dips_hz:
        i = int(np.argmin(np.abs(frf.freq_hz - x)))
        C[..., i] = 0.3
    return FRFSet(frf.freq_hz, H, frf.quantity, frf.outputs, frf.references, frf.unit, C, meta=dict(frf.meta))


def test_lines_at_60_hz_harmonics_give_60():
    grid = detect_mains_grid(with_lines(structure(), spikes_hz=(300.0, 420.0), dips_hz=(60.0, 180.0, 240.0)))
    assert grid.hz == 60.0 and grid.guard_hz == (60.0,)
    assert grid.lines_hz[60.0] == (60.0, 180.0, 240.0, 420.0)   # 300 Hz is also 6 x 50: it says nothing
    assert grid.lines_hz[50.0] == ()


def test_lines_at_50_hz_harmonics_give_50():
    grid = detect_mains_grid(with_lines(structure(1), spikes_hz=(150.0, 300.0), dips_hz=(50.0, 250.0, 350.0)))
    assert grid.hz == 50.0 and grid.lines_hz[50.0] == (50.0, 150.0, 250.0, 350.0) and grid.lines_hz[60.0] == ()


def test_grid_frequency_off_nominal_is_still_seen():
    """A grid running 0.1 % fast (60.06 Hz): its k-th harmonic is k x 0.06 Hz off, within the tolerance."""
    grid = detect_mains_grid(with_lines(structure(2), spikes_hz=(420.42,), dips_hz=(180.18, 480.48)))
    assert grid.hz == 60.0


def test_no_lines_is_unknown_and_the_check_keeps_both_grids():
    frf = structure(3)
    grid = detect_mains_grid(frf)
    assert grid.hz is None and "no narrow lines" in grid.reason and grid.guard_hz == (50.0, 60.0)
    assert mains_for_fit("auto", frf)[0] == (50.0, 60.0)


def test_lines_of_both_grids_are_unknown():
    grid = detect_mains_grid(with_lines(structure(4), dips_hz=(100.0, 150.0, 180.0, 240.0)))
    assert grid.hz is None and "neither grid stands out" in grid.reason


def test_a_single_line_is_not_enough():
    assert detect_mains_grid(with_lines(structure(5), spikes_hz=(420.0,))).hz is None


def test_scattered_coherence_of_few_averages_shows_no_grid():
    """Few averages scatter the coherence by +-0.15: no dip is read into that."""
    for seed in range(4):
        assert detect_mains_grid(structure(seed, coherence_spread=0.15)).hz is None


def test_an_anti_resonance_on_a_harmonic_is_not_a_line():
    """A coherence dip where |H| dips too is an anti-resonance, not pickup."""
    frf = structure(6)
    H, C = frf.H.copy(), frf.coherence.copy()
    for x in (180.0, 240.0, 420.0):
        i = int(np.argmin(np.abs(frf.freq_hz - x)))
        H[..., i - 1:i + 2] *= 0.05
        C[..., i - 1:i + 2] = 0.2
    frf2 = FRFSet(frf.freq_hz, H, frf.quantity, frf.outputs, frf.references, frf.unit, C)
    assert detect_mains_grid(frf2).hz is None


def test_coarse_lines_cannot_tell():
    grid = detect_mains_grid(with_lines(structure(7, df=2.5), spikes_hz=(180.0, 420.0)))
    assert grid.hz is None and "too coarse" in grid.reason


def test_detection_leaves_the_input_alone():
    frf = with_lines(structure(8), spikes_hz=(420.0,), dips_hz=(180.0,))
    H, C = frf.H.copy(), frf.coherence.copy()
    detect_mains_grid(frf)
    assert np.array_equal(frf.H, H) and np.array_equal(frf.coherence, C)


def test_mains_option():
    assert parse_mains_option("auto") == "auto" and parse_mains_option("none") == ()
    assert parse_mains_option("60") == (60.0,) and parse_mains_option("50,60") == (50.0, 60.0)
    for bad in ("-5", "sixty", "", "0"):
        with pytest.raises(ValueError, match="--mains"):
            parse_mains_option(bad)


def test_fit_names_the_300_hz_line_by_the_60_hz_grid():
    """A 60 Hz grid's line at 300 Hz is 5 x 60 Hz, never 6 x 50 Hz; the grid is named in the notes."""
    frf = with_lines(structure(9, df=0.25), spikes_hz=(300.0, 420.0), dips_hz=(180.0, 240.0))
    fit = fit_auto(frf)
    text = " ".join(fit.warnings)
    assert "mains grid 60 Hz from the data" in text
    assert "x 50 Hz" not in text and "5 x 60 Hz" in text
    assert not any(abs(f - 300.0) < 1.0 for f in fit.lsfd.freq_hz)


def test_fit_mains_option_on_the_command_line(tmp_path, capsys):
    frf = with_lines(structure(10, df=0.25), spikes_hz=(300.0, 420.0), dips_hz=(180.0, 240.0))
    uff = tmp_path / "hum.uff"
    write_uff58(uff, frf)
    out = tmp_path / "fit.json"
    assert cli_fit.main([str(uff), "--json", str(out), "--mains", "50", "-q"]) == 0
    doc = json.loads(out.read_text())
    assert not any("mains grid" in w for w in doc["warnings"])   # given, not detected
    assert any("6 x 50 Hz" in w for w in doc["warnings"])       # the grid as the user says
    assert cli_fit.main([str(uff), "--json", str(out), "--mains", "fifty"]) == 2
    assert "--mains 'fifty'" in capsys.readouterr().err


@pytest.mark.realdata
def test_unesp_lab_is_on_a_60_hz_grid(shared_data):
    """UNESP (Brazil, 60 Hz): both drive levels show the 60 Hz family; the fit calls 300 Hz 5 x 60 Hz."""
    pytest.importorskip("scipy")
    from benchmarks.accuracy.validation.unesp_boltedbeam import NAME, load

    if not (shared_data / NAME).is_dir():
        pytest.skip(f"{NAME} not in {shared_data}")
    for level in ("0p05", "0p30"):
        grid = detect_mains_grid(load(shared_data, level))
        assert grid.hz == 60.0 and {180.0, 420.0} <= set(grid.lines_hz[60.0]) and grid.lines_hz[50.0] == ()
    fit = fit_auto(load(shared_data, "0p05"))
    text = " ".join(fit.warnings)
    assert "mains grid 60 Hz" in text and "5 x 60 Hz" in text and "x 50 Hz" not in text


@pytest.mark.realdata
def test_european_labs_are_never_read_as_60_hz(shared_data):
    """Data measured on 50 Hz grids (Ljubljana, Liege) are never taken for 60 Hz."""
    from analysis.uff import read_uff58
    from benchmarks.accuracy.validation import uliege_plane

    frfs = []
    if (shared_data / "pyuff_3frf").is_dir():
        frfs.append(read_uff58(shared_data / "pyuff_3frf" / "measurement.uff"))
    if (shared_data / uliege_plane.NAME).is_dir():
        frfs.append(uliege_plane.load(shared_data))
    if not frfs:
        pytest.skip("neither pyuff_3frf nor the ULiege plane is in the shared data")
    assert all(detect_mains_grid(f).hz != 60.0 for f in frfs)
