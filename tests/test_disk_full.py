"""A full disk stops a command with one line and exit code 1 and loses nothing recorded.

The disk is filled for real: a child process with a file size limit (``RLIMIT_FSIZE``; the write
past it fails with ``EFBIG``, as a full disk fails with ``ENOSPC``), and where this user may mount
one, a small tmpfs (``ENOSPC``).
"""
from __future__ import annotations

import contextlib
import os
import resource
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlsplit

import numpy as np
import pytest
from disk_full_support import CAPTURE, ONE_POINT, POINTS, THREE_POINTS, one_line_exit_1, run
from station_support import WAIT_S, Api

from analysis.recording import Recording, verify_recording

#: bytes a file may grow to in the limited child: room for a few hits of the 3 x 2 test, not all
LIMIT = 2_600_000


def check_every_hit_readable(path: Path) -> tuple[int, int]:
    """(hits, accepted hits) of a recording a full disk stopped: it opens, closed cleanly, and every hit
    holds its counts (the CRC each hit stores is checked on reading)."""
    assert verify_recording(path) >= 1
    with Recording(path) as rec:
        assert rec.closed_cleanly and not rec.live
        hits = list(rec.hits())
        assert [h.index for h in hits] == list(range(len(hits)))
        assert all(np.any(h.counts != 0) for h in hits)
        return len(hits), sum(h.accepted for h in hits)


def test_capture_on_a_full_disk_keeps_every_hit_and_the_test_resumes(tmp_path):
    done = run([*CAPTURE, "--out", "rec.h5"], tmp_path, LIMIT)
    line = one_line_exit_1(done)
    assert "no room on the disk" in line and "capture --resume" in line
    n, accepted = check_every_hit_readable(tmp_path / "rec.h5")
    assert 1 <= accepted < 6 and f"the {n} hit(s) written before it" in line
    assert not (tmp_path / "rec.h5.lock").exists()
    # the point in progress has its FRFs: export and fit work on every accepted hit
    with Recording(tmp_path / "rec.h5") as rec:
        in_frfs = sorted(int(i) for name in rec.measurement_names() for i in rec.frf_group(name)["hits"])
        assert in_frfs == [h.index for h in rec.hits(accepted_only=True)]
    exported = run(["acquisition", "export", "rec.h5", "--sep005", "hits.json"], tmp_path)
    assert exported.returncode == 0, exported.stderr
    assert f"wrote {4 * n} SEP005 channels" in exported.stdout
    fitted = run(["analysis", "fit", "rec.h5", "--json", "fit.json"], tmp_path)
    assert fitted.returncode == 0, fitted.stderr[-2000:]
    # room again: the test is resumed and completed
    resumed = run(["acquisition", "capture", "--resume", "rec.h5", "--auto", "-q"], tmp_path)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    with Recording(tmp_path / "rec.h5") as rec:
        assert sum(h.accepted for h in rec.hits()) == 6 and len(rec.measurement_names()) == 3


class LimitedStation:
    """The station in a child process with the file size limit ``limit`` (bytes); what
    :class:`station_support.Api` needs of it: ``host``, ``port``, ``token``."""

    def __init__(self, args: list[str], cwd: Path, limit: int) -> None:
        def limited() -> None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

        self.proc = subprocess.Popen([sys.executable, "-m", "acquisition", "station", *args], cwd=cwd, text=True,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=limited)
        assert self.proc.stdout is not None
        parts = urlsplit(self.proc.stdout.readline().strip())
        self.host, self.port, self.token = parts.hostname, parts.port, parts.query.split("token=", 1)[1]


def test_the_station_on_a_full_disk_ends_with_one_line_and_keeps_every_hit(tmp_path):
    station = LimitedStation(["--device", "sim://?seed=1", "--out", "rec.h5", "--hits", "2", "--auto", "-q",
                              "--points", POINTS], tmp_path, LIMIT)
    try:
        st = Api(station).wait(lambda s: s.get("phase") in ("error", "finished"), "the disk to fill")
    finally:
        station.proc.send_signal(signal.SIGTERM)
        _, err = station.proc.communicate(timeout=WAIT_S)
    assert st["phase"] == "error" and "no room on the disk" in st["error"]
    assert station.proc.returncode == 1 and "Traceback" not in err
    assert [ln for ln in err.splitlines() if ln.startswith("station:")] == [f"station: {st['error']}"]
    n, accepted = check_every_hit_readable(tmp_path / "rec.h5")
    assert 1 <= accepted < 6
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.h5"]


def test_replay_and_import_onto_a_full_disk_leave_no_partial_recording(tmp_path, sim_capture, one_point):
    # the inputs: the 3-point and the one-point recordings of the session (shared: copied here)
    shutil.copy(sim_capture(*THREE_POINTS), tmp_path / "src.h5")
    (tmp_path / "old.h5").write_bytes(b"the user's earlier file")
    replayed = run(["acquisition", "replay", "src.h5", "--out", "old.h5", "--overwrite"], tmp_path, 400_000)
    assert "no room on the disk" in one_line_exit_1(replayed)
    assert (tmp_path / "old.h5").read_bytes() == b"the user's earlier file"
    # the hits of one point (an import names one reference point)
    shutil.copy(one_point, tmp_path / "one.h5")
    assert run(["acquisition", "export", "one.h5", "--sep005", "hits.json"], tmp_path).returncode == 0
    imported = run(["acquisition", "import", "hits.json", "--out", "imp.h5", "--reference", "right:6:-X"],
                   tmp_path, 400_000)
    assert "no room on the disk" in one_line_exit_1(imported)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hits.json", "old.h5", "one.h5", "src.h5"]


@pytest.fixture(scope="module")
def one_point(sim_capture) -> Path:
    """A recording of one point with two hits (shared: copied by each test)."""
    return sim_capture(*ONE_POINT)


@pytest.mark.parametrize("command", [["analysis", "fit", "src.h5", "--json", "out.json"],
                                     ["analysis", "report", "src.h5", "--out", "out"]], ids=["fit", "report"])
def test_fit_and_report_on_a_full_disk_exit_1(tmp_path, one_point, command):
    (tmp_path / "src.h5").write_bytes(one_point.read_bytes())
    done = run(command, tmp_path, 20_000)
    line = one_line_exit_1(done)
    assert "the disk is full or the file size limit is reached" in line and command[-1] in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["src.h5"]


@contextlib.contextmanager
def small_tmpfs(where: Path, size: str) -> Iterator[Path]:
    """A tmpfs of ``size`` mounted at ``where``; skips the test where mounting is not permitted."""
    where.mkdir()
    try:
        mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                                 capture_output=True, timeout=30)
    except OSError:
        pytest.skip("no mount command here")
    if mounted.returncode != 0:
        pytest.skip(f"mounting a tmpfs is not permitted here: {mounted.stderr.decode(errors='replace').strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", str(where)], capture_output=True, timeout=30)


@pytest.mark.skipif(os.name != "posix", reason="tmpfs is a Linux file system")
def test_capture_onto_a_full_tmpfs_stops_cleanly(tmp_path):
    # room for a few hits, not all: the recording and its journal (as much again while it is written)
    with small_tmpfs(tmp_path / "disk", "4m") as disk:
        done = run([*CAPTURE, "--out", str(disk / "rec.h5")], tmp_path)
        line = one_line_exit_1(done)
        assert "No space left on device" in line
        n, accepted = check_every_hit_readable(disk / "rec.h5")
        assert n >= 1 and accepted >= 1
        assert sorted(p.name for p in disk.iterdir()) == ["rec.h5"]
