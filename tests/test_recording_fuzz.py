"""Fuzzing the HDF5 recording reader with damaged copies of a real small recording.

libhdf5 itself can crash (segmentation fault) on some damaged files, which no Python code can
catch; :func:`verify_recording` reads the file in a child process first and turns that into
:class:`RecordingError`. A file that passed verification must then read in-process with only
``RecordingError`` coming out.

A real recording (two hits, an FRF group, events) is written once; hypothesis then overwrites
bytes, inserts/deletes runs and truncates the file. Opening it and reading everything
(``Recording``: hits, events, FRF groups, FRF sets; ``load_frfset``) either works or raises
:class:`RecordingError` with a message; a hit that comes back has counts matching its CRC-32.
Cases per test: ``IMPACTLAB_FUZZ_EXAMPLES`` (default 100; 300 cases in all).
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from acquisition.errors import RecordingError
from analysis.frf import FRFSet
from analysis.hit import Hit
from analysis.recording import Recording, counts_crc32, load_frfset, verify_recording
from analysis.recording_writer import FRFPoint, RecordingWriter
from analysis.spectra import AveragedSpectra, WindowSettings

N = int(os.environ.get("IMPACTLAB_FUZZ_EXAMPLES", "100"))  # each case forks a verifying child
FUZZ = settings(max_examples=N, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow])


def _real_recording() -> bytes:
    rng = np.random.default_rng(0)
    channels = [{"name": "force", "point": "right:6:-X", "direction": "-X", "quantity": "force", "sensitivity": 2.25,
                 "sensitivity_unit": "mV/N", "unit": "N", "range_v": 1.0, "coupling": "AC", "iepe": True},
                {"name": "acc1", "point": "left:9:Y", "direction": "Y", "quantity": "acceleration",
                 "sensitivity": 100.0, "sensitivity_unit": "mV/g", "unit": "m/s^2", "range_v": 5.0, "coupling": "AC",
                 "iepe": True}]
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "rec.h5"
        with RecordingWriter(p, instrument={"vendor": "IMPACTLB", "serial": "X"}, setup={"block_size": 64},
                             channels=channels, windows=WindowSettings(), plan={"mode": "roving_hammer"}) as w:
            for k in range(2):
                w.write_hit(Hit(counts=rng.integers(-3000, 3000, (2, 64)).astype(np.int16), eu_per_count=[0.01, 0.02],
                                volts_per_count=[3e-5, 1.5e-4], trigger_index=8, sample_rate_hz=6400.0, sequence=k + 1,
                                timestamp=1.0 + k, measurement=0, point="right:6:-X", reference="right:6:-X",
                                outputs=["left:9:Y"], force_channel=0, response_channels=[1], overload=[False, False],
                                accepted=bool(k == 0), reasons=[] if k == 0 else ["double hit"], check={"peak": 1.0}))
            w.log("INFO", "fuzz base")
            f = np.arange(5) * 100.0
            ones = np.ones((1, 5))
            w.write_frf(FRFPoint(0, "right:6:-X", (0,)),
                        FRFSet(freq_hz=f, H=ones * (1 + 1j), quantity="accelerance", outputs=["left:9:Y"],
                               references=["right:6:-X"], unit="(m/s^2)/N", coherence=ones),
                        AveragedSpectra(Gff=np.ones(5), Gxx=ones, Gfx=ones * (1 + 0j), H2=ones * (1 + 1j), n_averages=1,
                                        windows=WindowSettings()))
        return p.read_bytes()


BASE = _real_recording()


def _read_everything(raw: bytes) -> None:
    """Verify in a child (libhdf5 may crash on some damage), then read in-process what passed."""
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "rec.h5"
        p.write_bytes(raw)
        try:
            verify_recording(p, timeout_s=60)
        except RecordingError as exc:
            assert str(exc)
            return
        try:
            with Recording(p) as rec:
                for name in rec.hit_names():
                    try:
                        h = rec.hit(int(name))
                    except RecordingError as exc:
                        assert str(exc)
                        continue
                    assert counts_crc32(h.counts) == h_crc(rec, name)
                rec.events()
                for name in rec.measurement_names():
                    rec.frf_group(name)
                rec.frfsets()
            load_frfset(p)
        except RecordingError as exc:
            assert str(exc)


def h_crc(rec: Recording, name: str) -> int:
    return int(rec._f["hits"][name].attrs["crc32"])


def test_base_reads_back():
    _read_everything(BASE)
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "rec.h5"
        p.write_bytes(BASE)
        with Recording(p) as rec:
            assert rec.n_hits == 2 and [h.accepted for h in rec.hits()] == [True, False]


@FUZZ
@given(data=st.data())
def test_overwritten_bytes(data):
    raw = bytearray(BASE)
    for _ in range(data.draw(st.integers(1, 8))):
        k = data.draw(st.integers(0, len(raw) - 1))
        n = data.draw(st.integers(1, 8))
        raw[k:k + n] = data.draw(st.binary(min_size=n, max_size=n))
    _read_everything(bytes(raw))


@FUZZ
@given(cut=st.integers(0, len(BASE)), junk=st.binary(max_size=64))
def test_truncated_or_extended(cut, junk):
    _read_everything(BASE[:cut] + junk)


@FUZZ
@given(data=st.data())
def test_inserted_and_deleted_runs(data):
    raw = bytearray(BASE)
    k = data.draw(st.integers(0, len(raw) - 1))
    if data.draw(st.booleans()):
        raw[k:k] = data.draw(st.binary(min_size=1, max_size=32))
    else:
        del raw[k:k + data.draw(st.integers(1, 256))]
    _read_everything(bytes(raw))
