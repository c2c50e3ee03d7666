"""One writer per recording, and readers that honour its lock file: a second writer (``capture``,
``import``, a library caller) never touches a recording a live writer holds, even with
``--overwrite``; lock files are never followed through links; a stale lock left by a killed writer
is taken over with a note; readers honour ``REC.h5.lock`` where libhdf5's own lock is off.

The live writer is a real child process holding a :class:`RecordingWriter` open, driven line by line
through its standard input and output (no sleeps)."""
from __future__ import annotations

import json
import logging
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from analysis.errors import FolderBusy, OutputBusy, RecordingError
from analysis.recording import Recording
from analysis.recording_writer import RecordingWriter
from analysis.spectra import WindowSettings

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
w = RecordingWriter(sys.argv[1], instrument={}, setup={}, channels=ch, windows=WindowSettings(),
                    overwrite=len(sys.argv) > 2)
def one():
    w.write_hit(Hit(counts=np.full((2, 16), w.n_hits, np.int16), sequence=w.n_hits + 1, **hit))
print(0, flush=True)
for line in sys.stdin:
    if line.startswith("change"):  # stay inside one change of the recording until the next line
        with w._lock.changing():
            one()
            print("in", flush=True)
            sys.stdin.readline()
    else:
        for k in range(int(line)):
            one()
    print(w.n_hits, flush=True)
w.close()
"""


def start_writer(path: Path, *, overwrite: bool = False, env: dict | None = None) -> subprocess.Popen:
    """A child process holding a RecordingWriter on ``path`` open (it answers 0 once it has)."""
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path), *(["overwrite"] if overwrite else [])],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "0"
    return proc


def ask(proc: subprocess.Popen, line: str) -> str:
    assert proc.stdin is not None and proc.stdout is not None
    proc.stdin.write(f"{line}\n")
    proc.stdin.flush()
    return proc.stdout.readline().strip()


def stop(proc: subprocess.Popen) -> int:
    for pipe in (proc.stdin, proc.stdout):
        if pipe is not None:
            pipe.close()
    return proc.wait(30)


def run(*argv: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *argv], capture_output=True, text=True, timeout=120, env=env)


def n_hits(path: Path) -> int:
    with Recording(path) as rec:
        return len(list(rec.hits()))


def _sep005(path: Path) -> Path:
    """A small SEP005 test (2 hits of a force and a response channel) to import."""
    rng = np.random.default_rng(0)
    fs, n = 2048.0, 1024
    t = np.arange(n) / fs
    chans = []
    for k in range(2):
        force = np.where(t < 2e-3, np.sin(np.pi * t / 2e-3), 0.0) * 100.0
        resp = np.exp(-8 * t) * np.sin(2 * np.pi * 120 * t) * 5 + 1e-3 * rng.standard_normal(n)
        for name, data, unit, q in (("force", force, "N", "force"), ("acc", resp, "m/s^2", "acceleration")):
            chans.append({"name": name, "data": data.tolist(), "fs": fs, "unit_str": unit, "quantity": q,
                          "group": f"hit-{k + 1}"})
    path.write_text(json.dumps(chans))
    return path


def test_a_second_writer_never_touches_a_live_recording_even_with_overwrite(tmp_path):
    rec = tmp_path / "a.h5"
    src = _sep005(tmp_path / "in.json")
    proc = start_writer(rec)
    try:
        assert ask(proc, "3") == "3"
        size = rec.stat().st_size
        capture = run("-m", "acquisition", "capture", "--device", "sim://?seed=1", "--out", str(rec), "--hits", "2",
                      "--auto", "--overwrite", "-q")
        imported = run("-m", "acquisition", "import", str(src), "--out", str(rec), "--overwrite")
        for done in (capture, imported):
            lines = done.stderr.strip().splitlines()
            assert done.returncode == 1, done.stderr
            assert len(lines) == 1 and f"being recorded by process {proc.pid}" in lines[0] and "--overwrite" in lines[0]
            assert "device or session failure" not in lines[0]
        with pytest.raises(OutputBusy, match=f"process {proc.pid}"):  # the library refuses alike
            RecordingWriter(rec, instrument={}, setup={}, channels=[], windows=WindowSettings(), overwrite=True)
        with pytest.raises(OutputBusy):
            RecordingWriter.resume(rec)
        assert rec.stat().st_size >= size and (tmp_path / "a.h5.lock").read_text().strip() == str(proc.pid)
        assert ask(proc, "2") == "5"  # the first writer goes on, untouched
    finally:
        assert stop(proc) == 0
    assert n_hits(rec) == 5 and not (tmp_path / "a.h5.lock").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.h5", "in.json"]  # no temporary file left


def test_overwrite_replaces_a_closed_recording_whole_through_a_file_beside_it(tmp_path):
    rec = tmp_path / "a.h5"
    proc = start_writer(rec)
    assert ask(proc, "4") == "4" and stop(proc) == 0
    with pytest.raises(RecordingError, match="exists"):
        RecordingWriter(rec, instrument={}, setup={}, channels=[], windows=WindowSettings())
    proc = start_writer(rec, overwrite=True)  # a new recording, renamed over the old one once created
    try:
        assert ask(proc, "1") == "1"
    finally:
        assert stop(proc) == 0
    assert n_hits(rec) == 1 and sorted(p.name for p in tmp_path.iterdir()) == ["a.h5"]


@pytest.mark.parametrize("dangling", [False, True])
def test_a_lock_file_that_is_a_link_is_never_written_through(tmp_path, dangling):
    notes = tmp_path / "notes.txt"
    if not dangling:
        notes.write_text("my notes\n")
    (tmp_path / "s.h5.lock").symlink_to(notes.name)
    done = run("-m", "acquisition", "capture", "--device", "sim://?seed=1", "--out", str(tmp_path / "s.h5"),
               "--hits", "1", "--auto", "-q")
    lines = done.stderr.strip().splitlines()
    assert done.returncode != 0 and len(lines) == 1 and "s.h5.lock is a symbolic link" in lines[0], done.stderr
    assert "move it away" in lines[0]
    assert notes.read_text() == "my notes\n" if not dangling else not notes.exists()
    assert not (tmp_path / "s.h5").exists()


def test_a_lock_file_that_is_a_hard_link_or_no_regular_file_is_refused(tmp_path):
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes\n")
    os.link(notes, tmp_path / "h.h5.lock")
    os.mkfifo(tmp_path / "f.h5.lock")
    for name, what in (("h.h5", "a hard link"), ("f.h5", "not a regular file")):
        with pytest.raises(RecordingError, match=what):
            RecordingWriter(tmp_path / name, instrument={}, setup={}, channels=[], windows=WindowSettings())
    assert notes.read_text() == "my notes\n"


def test_the_batch_folder_lock_is_never_written_through_a_link(tmp_path):
    from analysis.batch.out_lock import FolderLock

    notes = tmp_path / "notes.txt"
    notes.write_text("my notes\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / ".batch.lock").symlink_to(notes)
    with pytest.raises(FolderBusy, match="symbolic link"):
        FolderLock(out)
    assert notes.read_text() == "my notes\n"


def test_a_reader_honours_the_lock_file_where_libhdf5_locking_is_off(tmp_path):
    rec = tmp_path / "a.h5"
    env = {**os.environ, "HDF5_USE_FILE_LOCKING": "FALSE"}
    reader = ("import sys\nfrom analysis.recording import Recording\nwith Recording(sys.argv[1]) as r:\n"
              "    print(r.live, len(list(r.hits())), r.closed_cleanly)")
    proc = start_writer(rec, env=env)
    try:
        assert ask(proc, "3") == "3"
        done = run("-c", reader, str(rec), env=env)
        assert done.returncode == 0 and done.stdout.split() == ["True", "3", "False"], done.stderr
        assert ask(proc, "change") == "in"  # the writer is inside a change (hit 4 written, not yet released)
        during = subprocess.Popen([sys.executable, "-c", reader, str(rec)], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True, env=env)
        assert ask(proc, "leave") == "4"
        out, err = during.communicate(timeout=60)
        assert during.returncode == 0 and out.split() in (["True", "3", "False"], ["True", "4", "False"]), err
    finally:
        assert stop(proc) == 0
    done = run("-c", reader, str(rec), env=env)
    assert done.stdout.split() == ["False", "4", "True"]


def test_a_stale_lock_of_a_killed_writer_is_taken_over_with_a_note(tmp_path, caplog):
    rec = tmp_path / "a.h5"
    (tmp_path / "a.h5.lock").write_bytes(b"")  # a capture killed before its file existed
    done = run("-m", "acquisition", "capture", "--device", "sim://?seed=1", "--out", str(rec), "--hits", "1",
               "--auto", "-q")
    assert done.returncode == 0, done.stderr
    assert "a.h5.lock: removed a stale empty lock file" in done.stderr
    assert n_hits(rec) >= 1 and not (tmp_path / "a.h5.lock").exists()

    proc = start_writer(tmp_path / "b.h5")
    assert ask(proc, "2") == "2"
    proc.send_signal(signal.SIGKILL)
    stop(proc)
    lock = tmp_path / "b.h5.lock"
    assert lock.read_text().strip() == str(proc.pid)  # left behind, but nobody holds it
    with Recording(tmp_path / "b.h5") as r:  # read in place: no live writer
        assert not r.live and r.n_hits == 2
    with caplog.at_level(logging.WARNING, logger="analysis.recording_lock"):
        with RecordingWriter.resume(tmp_path / "b.h5") as w:
            assert w.n_hits == 2 and lock.read_text().strip() == str(os.getpid())
    assert f"stale lock of process {proc.pid}" in caplog.text
    assert not lock.exists()


def test_an_output_that_a_live_writer_holds_is_refused_by_every_face(tmp_path, sim_capture):
    done = tmp_path / "done.h5"  # a finished recording with FRFs, the input (the session's, copied)
    shutil.copy(sim_capture("--device", "sim://?seed=1", "--hits", "1", "--auto"), done)
    live = tmp_path / "live.h5"
    proc = start_writer(live)
    try:
        assert ask(proc, "1") == "1"
        for argv in (("-m", "acquisition", "export", str(done), "--uff", str(live), "--overwrite"),
                     ("-m", "acquisition", "replay", str(done), "--out", str(live), "--overwrite"),
                     ("-m", "analysis", "fit", str(done), "--json", str(live), "--overwrite")):
            got = run(*argv)
            lines = got.stderr.strip().splitlines()
            assert got.returncode == 1 and len(lines) == 1, got.stderr
            assert f"live.h5 is being recorded by process {proc.pid}" in lines[0]
        assert ask(proc, "1") == "2"
    finally:
        assert stop(proc) == 0
    assert n_hits(live) == 2
