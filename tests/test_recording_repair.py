"""``acquisition repair``: a recording that ends before the end of file its HDF5 superblock records
(what a writer dying mid-write on a full disk, or a crash of libhdf5, left with older versions)
does not open; the repair writes every intact hit to a new recording that export and fit read,
drops a cut-off hit (its CRC-32 fails) and the FRF results computed from it, and never changes
its input."""
from __future__ import annotations

import dataclasses
import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import pytest

from analysis.errors import RecordingError
from analysis.recording import Recording
from analysis.recording_repair import repair_recording, stored_eof
from analysis.recording_schema import counts_crc32
from analysis.recording_writer import RecordingWriter

POINTS = "right:6:-X,top:4:Z"


def _run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def _digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def recording(sim_capture) -> Path:
    """A real capture on the simulated frame: 2 points, 2 accepted hits each (4 hits, 2 FRF groups); the
    session's (``sim_capture``: read it or copy it)."""
    return sim_capture("--device", "sim://?seed=1", "--hits", "2", "--auto", "--points", POINTS)


def _cut_mid_hit(src: Path, folder: Path) -> Path:
    """``folder/cut.h5``: ``src`` with a fifth hit whose write stopped half way: the writer flushed it
    (the superblock records the end of file after it), the disk kept only the first half of its counts."""
    live = folder / "live.h5"
    shutil.copyfile(src, live)
    with Recording(live) as rec:
        last = rec.hit(3)
    w = RecordingWriter.resume(live)
    try:
        w.write_hit(dataclasses.replace(last, sequence=99))
        shutil.copyfile(live, folder / "cut.h5")  # the file as the writer left it on disk
    finally:
        w.close()
    cut = folder / "cut.h5"
    with h5py.File(cut, "r") as f:
        ds = f["hits/000004/counts"]
        start, size = ds.id.get_offset(), ds.id.get_storage_size()
    eof = stored_eof(cut)
    assert eof is not None and eof >= start + size  # the hit lies before the recorded end
    os.truncate(cut, start + size // 2)
    return cut


def test_a_file_cut_mid_hit_is_repaired_to_every_intact_hit_and_export_and_fit_read_it(recording, tmp_path):
    cut = _cut_mid_hit(recording, tmp_path)
    before = _digest(cut)
    with pytest.raises(RecordingError, match=r"truncated.*python -m acquisition repair"):
        Recording(cut)

    done = _run(["acquisition", "repair", str(cut), "--out", "fixed.h5"], tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "4 hits kept, 1 cut-off hits dropped: wrote fixed.h5"
    assert _digest(cut) == before  # the input is never changed
    assert not [n for n in os.listdir(tmp_path) if n.endswith(".part")]

    with Recording(recording) as orig, Recording(tmp_path / "fixed.h5") as fixed:
        kept = list(fixed.hits())
        assert [h.index for h in kept] == [0, 1, 2, 3]
        assert [counts_crc32(h.counts) for h in kept] == [counts_crc32(h.counts) for h in orig.hits()]
        assert fixed.measurement_names() == orig.measurement_names() == ["m000", "m001"]
        assert any(m.startswith("repaired: 4 hits kept, 1 cut-off") for _, _, m in fixed.events())

    done = _run(["acquisition", "export", "fixed.h5", "--uff", "fixed.uff"], tmp_path)
    assert done.returncode == 0 and "UFF 58 datasets" in done.stdout, done.stderr[-2000:]
    done = _run(["analysis", "fit", "fixed.h5", "--json", "fit.json"], tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "fit.json").stat().st_size > 0
    done = _run(["acquisition", "export", "cut.h5", "--uff", "cut.uff"], tmp_path)  # the input still refused
    assert done.returncode != 0 and "repair" in done.stderr


def test_a_damaged_hit_is_dropped_with_the_frf_results_computed_from_it(recording, tmp_path):
    bad = tmp_path / "bad.h5"
    shutil.copyfile(recording, bad)
    with h5py.File(bad, "r") as f:
        at = f["hits/000003/counts"].id.get_offset()
    with open(bad, "r+b") as fh:  # a cut-off hit reads back as zeros
        fh.seek(at + 100)
        fh.write(b"\0\x7f" * 500)
    before = _digest(bad)
    result = repair_recording(bad, tmp_path / "fixed.h5")
    assert (result.kept, result.dropped, result.dropped_frf) == ((0, 1, 2), (3,), ("m001",))
    assert result.summary().startswith("3 hits kept, 1 cut-off hits dropped; FRF results m001 dropped")
    assert _digest(bad) == before
    with Recording(tmp_path / "fixed.h5") as fixed:
        assert [h.index for h in fixed.hits()] == [0, 1, 2]
        assert fixed.measurement_names() == ["m000"]
    done = _run(["acquisition", "capture", "--resume", "fixed.h5", "--auto", "-q"], tmp_path)  # the test goes on
    assert done.returncode == 0, done.stderr[-2000:]
    with Recording(tmp_path / "fixed.h5") as fixed:
        assert [h.point for h in fixed.hits()] == ["right:6:-X", "right:6:-X", "top:4:Z", "top:4:Z"]
        assert fixed.measurement_names() == ["m000", "m001"]
    with pytest.raises(RecordingError, match="exists"):
        repair_recording(bad, tmp_path / "fixed.h5")
    from analysis.errors import UsageError

    with pytest.raises(UsageError, match="is the input"):
        repair_recording(bad, bad, overwrite=True)


def test_a_file_whose_index_is_lost_is_refused_with_one_line_and_exit_1(recording, tmp_path):
    lost = tmp_path / "lost.h5"
    shutil.copyfile(recording, lost)
    os.truncate(lost, lost.stat().st_size // 2)  # the closed file's root group header was at its end
    done = _run(["acquisition", "repair", "lost.h5", "--out", "fixed.h5"], tmp_path)
    assert done.returncode == 1
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("repair: ") and "cannot be repaired" in lines[0], done.stderr
    assert sorted(os.listdir(tmp_path)) == ["lost.h5"]  # nothing written, no temporaries left


@pytest.mark.parametrize("libver", ["earliest", "latest"])  # superblock versions 0 and 3
@pytest.mark.parametrize("userblock", [0, 512])
def test_stored_eof_reads_the_end_of_file_libhdf5_checks(tmp_path, libver, userblock):
    import numpy as np

    p = tmp_path / "x.h5"
    with h5py.File(p, "w", libver=libver, userblock_size=userblock) as f:
        f["x"] = np.arange(3000)
    size = p.stat().st_size
    assert stored_eof(p) == size
    os.truncate(p, size - 1000)
    with pytest.raises(OSError, match=f"stored_eof = {size}"):
        h5py.File(p, "r")
    (tmp_path / "not.h5").write_bytes(b"plain text, no superblock" * 40)
    assert stored_eof(tmp_path / "not.h5") is None
