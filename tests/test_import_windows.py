"""Raw time data imported without window options get capture's windows (force window after the
trigger, exponential to 5 % at the block end), so the force spectrum, and the fit's band from it,
is the hammer pulse's rather than the noise and drift of a long block."""
from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal

from acquisition.cli_import import import_windows
from acquisition.cli_import import main as import_main
from acquisition.window_options import DEFAULT_EXP_WINDOW, DEFAULT_FORCE_WINDOW
from analysis.bands import default_band
from analysis.recording import Recording, load_frfset

FS = 1024.0
N = 8192   # 8 s: a long block, as lab analysers record for lightly damped structures


def long_block_hit(tmp_path):
    """One hit (4 ms half-sine, 100 N) on three resonators (40, 120, 300 Hz) in an 8 s block whose
    force channel also carries noise and a slow drift of 3 N (an AC-coupled channel settling)."""
    rng = np.random.default_rng(0)
    t = np.arange(N) / FS
    f = np.zeros(N)
    w = int(0.004 * FS)
    f[100:100 + w] = 100.0 * np.sin(np.pi * (np.arange(w) + 0.5) / w)
    x = np.zeros(N)
    for fr, amp in ((40.0, 1.0), (120.0, 0.5), (300.0, 0.3)):
        b, a = signal.iirpeak(fr, 50.0, fs=FS)
        x += amp * signal.lfilter(b, a, f)
    f += 0.2 * rng.normal(size=N) + 3.0 * np.sin(2 * np.pi * 0.5 * t)
    x += 1e-3 * rng.normal(size=N)
    np.save(tmp_path / "hit.npy", np.vstack([t, f, x]))
    desc = {"time_row": 0, "channels": [{"name": "hammer", "unit": "N", "point": "n:1:Z"},
                                        {"name": "acc", "unit": "m/s^2", "point": "n:2:Z"}]}
    (tmp_path / "desc.json").write_text(json.dumps(desc))
    return [str(tmp_path / "hit.npy"), "--describe", str(tmp_path / "desc.json")]


def test_raw_import_gets_captures_windows_and_the_pulses_band(tmp_path, capsys):
    args = long_block_hit(tmp_path)
    rec = tmp_path / "rec.h5"
    assert import_main([*args, "--out", str(rec)]) == 0, capsys.readouterr().err
    with Recording(rec) as r:
        assert r.windows.force_width_s == pytest.approx(0.020) and r.windows.force_taper_s == pytest.approx(0.005)
        assert r.windows.exp_window_end_fraction == pytest.approx(0.05)
    frf = load_frfset(rec)
    assert frf.exp_window_tau_s is not None
    lo, hi = default_band(frf)
    assert 250.0 < hi <= FS / 2.56   # the 4 ms pulse excites up to ~310 Hz: the three modes are in the band
    # the same hit without windows: the drift dominates the force spectrum and the band ends at a few Hz
    bare = tmp_path / "bare.h5"
    assert import_main([*args, "--out", str(bare), "--force-window", "none", "--exp-window", "none"]) == 0
    assert default_band(load_frfset(bare))[1] < 10.0


def test_windows_given_or_already_applied_are_kept():
    assert import_windows(None, None, windowed=False) == (DEFAULT_FORCE_WINDOW, DEFAULT_EXP_WINDOW)
    assert import_windows("10ms,2ms", None, windowed=False) == ("10ms,2ms", DEFAULT_EXP_WINDOW)
    assert import_windows(None, "none", windowed=False) == (DEFAULT_FORCE_WINDOW, "none")
    assert import_windows(None, None, windowed=True) == ("none", "none")   # the analyser's windows are on them
    assert import_windows("5ms", None, windowed=True) == ("5ms", "none")


@pytest.mark.realdata
def test_uliege_first_lab_hit_imported_as_raw_gets_the_band_of_its_pulse(shared_data, tmp_path, capsys):
    """ULiege first lab, one 16 s block at 512 Hz imported as the README shows: the band is the
    analyser's 0..200 Hz that the hammer excites, not 0.31..1.25 Hz of the unwindowed force's drift."""
    mat = shared_data / "uliege_meca0062_plane_hammer" / "first_lab" / "DPsv00001.mat"
    if not mat.is_file():
        pytest.skip(f"{mat} not in the shared data")
    rec = tmp_path / "plane.h5"
    assert import_main([str(mat), "--out", str(rec)]) == 0, capsys.readouterr().err
    frf = load_frfset(rec)
    lo, hi = default_band(frf)
    assert lo < 1.0 and hi == pytest.approx(200.0)
    assert frf.exp_window_tau_s is not None
