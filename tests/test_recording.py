"""analysis.recording: schema v1 round trip, crash safety (SIGKILL), and every kind of bad file."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from acquisition.errors import RecordingError
from analysis.frf import FRFSet
from analysis.hit import Hit
from analysis.recording import (
    SCHEMA_VERSION,
    Recording,
    counts_crc32,
    load_frfset,
    scale_counts,
)
from analysis.recording_writer import FRFPoint, RecordingWriter
from analysis.spectra import AveragedSpectra, WindowSettings


def _kill_writer_script() -> str:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from benchmarks.reliability.kill_writer import WRITER as script

    return script

CHANNELS = [
    {"name": "force", "point": "right:6:-X", "direction": "-X", "quantity": "force", "sensitivity": 2.25,
     "sensitivity_unit": "mV/N", "unit": "N", "range_v": 5.0, "coupling": "AC", "iepe": True},
    {"name": "acc1", "point": "left:9:Y", "direction": "Y", "quantity": "acceleration", "sensitivity": 100.0,
     "sensitivity_unit": "mV/g", "unit": "m/s^2", "range_v": 5.0, "coupling": "AC", "iepe": True},
]
WIN = WindowSettings(force_width_s=0.01, force_taper_s=0.002, exp_window_tau_s=0.4)


def write_example(path: Path, n_hits: int = 3, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    counts = []
    with RecordingWriter(path, instrument={"vendor": "sim", "model": "SL-4", "serial": "0001"},
                         setup={"sample_rate_hz": 1000.0, "block_size": 256}, channels=CHANNELS, windows=WIN,
                         plan={"mode": "roving_hammer", "points": ["right:6:-X"]}) as w:
        for i in range(n_hits):
            c = rng.integers(-32768, 32767, size=(2, 256), endpoint=True).astype(np.int16)
            counts.append(c)
            w.write_hit(Hit(counts=c, eu_per_count=[0.01, 0.002], volts_per_count=[2.2e-5, 1.5e-4], trigger_index=16,
                            sample_rate_hz=1000.0, sequence=100 + i, timestamp=1.5 + i, measurement=0,
                            point="right:6:-X", reference="right:6:-X", outputs=["left:9:Y"], force_channel=0,
                            response_channels=[1], overload=[False, i == 1], accepted=i != 1,
                            reasons=["overload on channel 2"] if i == 1 else [], check={"force_peak_n": 100.0 + i}))
            w.log("INFO", f"hit {i}")
        f = np.linspace(0, 500, 129)
        H = (np.arange(129) + 1j)[None, :] * np.array([[1.0]])
        w.write_frf(FRFPoint(0, "right:6:-X", (0, 2)),
                    FRFSet(freq_hz=f, H=H, quantity="accelerance", outputs=["left:9:Y"], references=["right:6:-X"],
                           unit="(m/s^2)/N", coherence=np.full((1, 129), 0.9), exp_window_tau_s=0.4),
                    AveragedSpectra(Gff=np.ones(129), Gxx=np.ones((1, 129)), Gfx=H, H2=2 * H, n_averages=2,
                                    windows=WIN))
    return counts


def test_round_trip(tmp_path):
    p = tmp_path / "rec.h5"
    counts = write_example(p)
    with h5py.File(p, "r") as f:
        assert f.attrs["schema"] == "impactlab-recording" and f.attrs["schema_version"] == SCHEMA_VERSION
    with Recording(p) as rec:
        assert rec.instrument["model"] == "SL-4"
        assert rec.setup["block_size"] == 256
        assert rec.channels[1]["point"] == "left:9:Y" and rec.channels[0]["sensitivity"] == 2.25
        assert rec.channels[0]["iepe"] is True
        assert rec.windows == WIN
        assert rec.plan["mode"] == "roving_hammer"
        hits = list(rec.hits())
        assert len(hits) == 3 and [h.accepted for h in hits] == [True, False, True]
        assert hits[1].reasons == ["overload on channel 2"] and hits[1].overload.tolist() == [False, True]
        for h, c in zip(hits, counts):
            assert h.counts.dtype == np.int16 and np.array_equal(h.counts, c)
            assert np.array_equal(h.data, scale_counts(c, np.array([0.01, 0.002])))
            assert h.trigger_index == 16 and h.crc_ok
        assert hits[2].sequence == 102 and hits[2].timestamp == 3.5 and hits[0].check["force_peak_n"] == 100.0
        assert [h.index for h in rec.hits(accepted_only=True)] == [0, 2]
        assert [e[2] for e in rec.events()] == ["hit 0", "hit 1", "hit 2"]
        assert rec.closed_cleanly
    s = load_frfset(p, "H2")
    assert s.H.shape == (1, 1, 129) and s.exp_window_tau_s == 0.4
    assert np.array_equal(s.H[0, 0], 2 * (np.arange(129) + 1j))
    assert s.outputs == ("left:9:Y",) and s.references == ("right:6:-X",) and s.meta["estimator"] == "H2"


def test_writer_refuses_to_overwrite(tmp_path):
    p = tmp_path / "rec.h5"
    write_example(p, 1)
    with pytest.raises(RecordingError, match="exists"):
        write_example(p, 1)


def test_not_hdf5(tmp_path):
    p = tmp_path / "x.h5"
    p.write_text("hello, not HDF5")
    with pytest.raises(RecordingError, match="not an HDF5 file"):
        Recording(p)
    with pytest.raises(RecordingError, match="not found"):
        Recording(tmp_path / "missing.h5")


def test_other_schema_version(tmp_path):
    p = tmp_path / "rec.h5"
    write_example(p, 1)
    with h5py.File(p, "a") as f:
        f.attrs["schema_version"] = 2
    with pytest.raises(RecordingError, match="schema version 2"):
        Recording(p)


def test_foreign_hdf5(tmp_path):
    p = tmp_path / "other.h5"
    with h5py.File(p, "w") as f:
        f["data"] = np.zeros(3)
    with pytest.raises(RecordingError, match="not an impactlab recording"):
        Recording(p)


def test_truncated_file(tmp_path):
    p = tmp_path / "rec.h5"
    write_example(p, 3)
    data = p.read_bytes()
    q = tmp_path / "cut.h5"
    q.write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingError, match="damaged|truncated"):
        with Recording(q) as rec:
            list(rec.hits())


def test_damaged_counts_fail_crc(tmp_path):
    p = tmp_path / "rec.h5"
    write_example(p, 2)
    with h5py.File(p, "a") as f:
        c = f["hits/000001/counts"]
        c[0, 0] = c[0, 0] ^ 1
    with Recording(p) as rec:
        assert rec.hit(0).crc_ok
        with pytest.raises(RecordingError, match="CRC-32"):
            rec.hit(1)
        assert [h.index for h in rec.hits(skip_damaged=True)] == [0]


def test_missing_group_is_damage(tmp_path):
    p = tmp_path / "rec.h5"
    write_example(p, 1)
    with h5py.File(p, "a") as f:
        del f["setup"]
    with pytest.raises(RecordingError, match="'/setup' is missing"):
        Recording(p)


def test_crc32_known_value():
    # zlib CRC-32 of the little-endian int16 bytes 01 00 02 00
    import zlib

    assert counts_crc32(np.array([[1, 2]], np.int16)) == zlib.crc32(b"\x01\x00\x02\x00")


#: the writer process the SIGKILL tests kill: the one ``benchmarks/reliability/kill_writer.py`` kills many times
WRITER = _kill_writer_script()


@pytest.mark.parametrize("seed,n_before_kill", [(1, 4), (2, 9)])
def test_sigkill_mid_session_loses_no_hit(tmp_path, seed, n_before_kill):
    """A writer killed with SIGKILL (while busy writing) leaves a file that opens with every reported hit."""
    p = tmp_path / "killed.h5"
    script = tmp_path / "writer.py"
    script.write_text(WRITER)
    proc = subprocess.Popen([sys.executable, str(script), str(p), str(seed)], stdout=subprocess.PIPE, text=True)
    reported = {}
    try:
        for line in proc.stdout:
            idx, total = map(int, line.split())
            reported[idx] = total
            if len(reported) >= n_before_kill:
                break
        time.sleep(0.002 * seed)  # the writer is now in the middle of the next hit
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL
    with Recording(p) as rec:
        assert not rec.closed_cleanly
        hits = {h.index: h for h in rec.hits(skip_damaged=True)}
        for idx, total in reported.items():
            assert idx in hits and int(hits[idx].counts.sum()) == total
        assert len(rec.events()) >= len(reported)


def test_frfs_carry_sample_rate_and_the_preferred_estimator(tmp_path) -> None:
    """The FRF set carries the sample rate it was measured at, and a recording replayed with H2 is
    read as H2 by every consumer unless told otherwise."""
    from analysis.recording import load_frfset
    from analysis.recording_writer import RecordingWriter
    from analysis.spectra import WindowSettings

    f = np.linspace(0.0, 200.0, 129)
    H = np.ones((1, 129), complex)
    path = tmp_path / "r.h5"
    with RecordingWriter(path, instrument={}, setup={}, channels=[], windows=WindowSettings(), plan={}) as w:
        w.write_frf(FRFPoint(0, "right:6:-X", (0, 1, 2)),
                    FRFSet(freq_hz=f, H=H, quantity="accelerance", outputs=["left:9:Y"], references=["right:6:-X"],
                           unit="(m/s^2)/N", coherence=np.full((1, 129), 0.9), sample_rate_hz=512.0),
                    AveragedSpectra(Gff=np.ones(129), Gxx=np.ones((1, 129)), Gfx=np.ones((1, 129), complex), H2=2 * H,
                                    n_averages=3, windows=WindowSettings()))
    frf = load_frfset(path)
    assert frf.sample_rate_hz == 512.0 and frf.analyser_band_hz == pytest.approx(200.0)
    assert frf.line_spacing_hz == pytest.approx(200.0 / 128)
    assert frf.meta["estimator"] == "H1" and np.allclose(frf.H, 1.0)
    with RecordingWriter.resume(path) as w:
        w.set_attr("preferred_estimator", "H2")
    frf2 = load_frfset(path)
    assert frf2.meta["estimator"] == "H2" and np.allclose(frf2.H, 2.0)
    assert np.allclose(load_frfset(path, estimator="H1").H, 1.0)


def test_merging_points_with_different_exponential_windows_is_refused_not_silently_dropped() -> None:
    from analysis.frf import FRFSet
    from analysis.recording import RecordingError, merge_frfsets

    f = np.linspace(1.0, 100.0, 50)
    a = FRFSet(freq_hz=f, H=np.ones((1, 1, 50)), outputs=("left:9:Y",), references=("right:6:-X",),
               exp_window_tau_s=0.5)
    b = FRFSet(freq_hz=f, H=np.ones((1, 1, 50)), outputs=("left:9:Y",), references=("top:4:Z",),
               exp_window_tau_s=0.25)
    with pytest.raises(RecordingError, match="different exponential windows.*replay"):
        merge_frfsets([a, b])
    same = merge_frfsets([a, FRFSet(freq_hz=f, H=np.ones((1, 1, 50)), outputs=("left:9:Y",),
                                    references=("top:4:Z",), exp_window_tau_s=0.5)])
    assert same.exp_window_tau_s == 0.5 and same.H.shape == (1, 2, 50)


def test_recordings_with_the_old_exponential_window_keys_are_read(tmp_path) -> None:
    """Files written before the window's names were settled (``exp_tau_s``, ``exp_decay``) read as
    ``exp_window_tau_s`` and ``exp_window_end_fraction``, in /windows and in each FRF's windows_json."""
    p = tmp_path / "old.h5"
    write_example(p)
    old = {"force_width_s": 0.01, "force_taper_s": 0.002, "exp_tau_s": 0.4, "exp_decay": None, "exp_on_force": True}
    with h5py.File(p, "r+") as f:
        f["windows"].attrs["json"] = json.dumps({**old, "exp_tau_s": None, "exp_decay": 0.05})
        f["frf/m000"].attrs["windows_json"] = json.dumps(old)
    with Recording(p) as rec:
        assert rec.windows == WindowSettings(force_width_s=0.01, force_taper_s=0.002, exp_window_end_fraction=0.05)
        assert rec.frf_group("m000")["windows"] == WIN
