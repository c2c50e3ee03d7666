"""A recording being written is read live (every flushed hit), and a file another program holds
open for writing is reported as locked with that process id, never as damaged."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from analysis.errors import RecordingError
from analysis.recording import Recording, verify_recording

WRITER = """
import sys
import numpy as np
from analysis.hit import Hit
from analysis.recording_writer import RecordingWriter
from analysis.spectra import WindowSettings
hit = dict(eu_per_count=[0.01, 0.02], volts_per_count=[3e-5, 1.5e-4], trigger_index=8, sample_rate_hz=6400.0,
           timestamp=1.0, measurement=0, point="a:1:X", reference="a:1:X", outputs=["b:2:Y"],
           force_channel=0, response_channels=[1], overload=[False, False], accepted=True)
ch = [dict(name=n, point=p, direction="X", quantity=q, sensitivity=1.0, sensitivity_unit="mV/EU", unit=u,
           range_v=10.0, coupling="ICP", iepe=True)
      for n, p, q, u in (("force", "a:1:X", "force", "N"), ("acc", "b:2:Y", "acceleration", "m/s^2"))]
w = RecordingWriter(sys.argv[1], instrument={}, setup={}, channels=ch, windows=WindowSettings())
print(0, flush=True)
for line in sys.stdin:
    for k in range(int(line)):
        w.write_hit(Hit(counts=np.full((2, 16), w.n_hits, np.int16), sequence=w.n_hits + 1, **hit))
    print(w.n_hits, flush=True)
w.close()
"""


def _start_writer(path: Path) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "0"
    return proc


def _write(proc: subprocess.Popen, n: int) -> int:
    assert proc.stdin is not None and proc.stdout is not None
    proc.stdin.write(f"{n}\n")
    proc.stdin.flush()
    return int(proc.stdout.readline())


def _stop(proc: subprocess.Popen) -> int:
    for pipe in (proc.stdin, proc.stdout):
        if pipe is not None:
            pipe.close()
    return proc.wait(30)


def test_a_recording_being_written_is_read_live_with_every_flushed_hit(tmp_path):
    path = tmp_path / "rec.h5"
    proc = _start_writer(path)
    try:
        assert (tmp_path / "rec.h5.lock").read_text().strip() == str(proc.pid)
        for total in (3, 8):
            assert _write(proc, total - (3 if total == 8 else 0)) == total
            with Recording(path) as rec:
                assert rec.live and not rec.closed_cleanly
                hits = list(rec.hits())
                assert [h.sequence for h in hits] == list(range(1, total + 1))
                assert all(int(h.counts[0, 0]) == h.index for h in hits)
            assert verify_recording(path) == total  # the checking child reads it live too
    finally:
        assert _stop(proc) == 0
    assert not (tmp_path / "rec.h5.lock").exists()
    with Recording(path) as rec:  # closed: read in place
        assert not rec.live and rec.closed_cleanly and rec.n_hits == 8
    assert not list(tmp_path.glob("*live*"))


def test_a_file_locked_by_another_program_is_reported_as_locked_with_its_pid(tmp_path):
    from analysis.recording_writer import RecordingWriter
    from analysis.spectra import WindowSettings

    path = tmp_path / "rec.h5"
    RecordingWriter(path, instrument={}, setup={}, channels=[], windows=WindowSettings()).close()
    holder = subprocess.Popen([sys.executable, "-c", "import h5py, sys, time\nf = h5py.File(sys.argv[1], 'a')\n"
                               "print('open', flush=True)\ntime.sleep(60)", str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "open"
        with pytest.raises(RecordingError) as err:
            Recording(path)
        msg = str(err.value)
        assert f"being written by process {holder.pid}" in msg and "not damaged" in msg and "\n" not in msg
        with pytest.raises(RecordingError, match=f"being written by process {holder.pid}"):
            RecordingWriter.resume(path)
    finally:
        holder.kill()
        _stop(holder)


def test_export_reads_a_live_recording(tmp_path):
    from acquisition.cli_export import export_sep005

    path = tmp_path / "rec.h5"
    proc = _start_writer(path)
    try:
        _write(proc, 4)
        assert export_sep005(path, tmp_path / "out.json") == 8  # 4 hits x 2 channels
    finally:
        assert _stop(proc) == 0
