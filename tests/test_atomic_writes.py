"""Every file written whole goes through one atomic helper (analysis.atomic): on a full disk the
previous file is left as it was and nothing half-written stays behind; temporaries left by killed
processes (a writer's, a reader's live copy, a report's folder) sit beside their file, named with
the process id, and are removed by the next process that comes by."""
from __future__ import annotations

import ast
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from disk_full_support import ONE_POINT, one_line_exit_1, run

import analysis.atomic as atomic
from analysis.recording import Recording

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def one_point(sim_capture) -> Path:
    return sim_capture(*ONE_POINT)


@pytest.fixture
def folder(tmp_path, one_point) -> Path:
    (tmp_path / "src.h5").write_bytes(one_point.read_bytes())
    return tmp_path


def test_export_uff_onto_a_full_disk_keeps_the_previous_file(folder):
    first = run(["acquisition", "export", "src.h5", "--uff", "good.uff"], folder)
    assert first.returncode == 0, first.stderr
    before = (folder / "good.uff").read_bytes()
    done = run(["acquisition", "export", "src.h5", "--uff", "good.uff", "--time", "--overwrite"], folder,
               len(before) // 2)
    assert "good.uff" in one_line_exit_1(done)
    assert (folder / "good.uff").read_bytes() == before
    assert sorted(p.name for p in folder.iterdir()) == ["good.uff", "src.h5"]


def test_export_sep005_onto_a_full_disk_leaves_nothing(folder):
    done = run(["acquisition", "export", "src.h5", "--sep005", "hits.json"], folder, 100_000)
    assert "hits.json" in one_line_exit_1(done)
    assert sorted(p.name for p in folder.iterdir()) == ["src.h5"]


def test_fit_outputs_onto_a_full_disk_keep_the_previous_files(folder):
    first = run(["analysis", "fit", "src.h5", "--json", "fit.json", "--uff", "fit.uff"], folder)
    assert first.returncode == 0, first.stderr[-2000:]
    fit_json, fit_uff = (folder / "fit.json").read_bytes(), (folder / "fit.uff").read_bytes()
    done = run(["analysis", "fit", "src.h5", "--json", "fit.json", "--uff", "fit.uff", "--overwrite"], folder,
               len(fit_json) // 2)
    one_line_exit_1(done)
    assert (folder / "fit.json").read_bytes() == fit_json and (folder / "fit.uff").read_bytes() == fit_uff
    # room for the JSON, not for the UFF file: the new JSON, the old UFF file, nothing else
    done = run(["analysis", "fit", "src.h5", "--json", "fit.json", "--uff", "fit.uff", "--overwrite"], folder,
               max(len(fit_json) + 4096, len(fit_uff) // 2))
    assert "fit.uff" in one_line_exit_1(done)
    assert json.loads((folder / "fit.json").read_text())["input"] == "src.h5"
    assert (folder / "fit.uff").read_bytes() == fit_uff
    assert sorted(p.name for p in folder.iterdir()) == ["fit.json", "fit.uff", "src.h5"]


def test_import_onto_a_full_disk_keeps_the_previous_recording(folder):
    assert run(["acquisition", "export", "src.h5", "--sep005", "hits.json"], folder).returncode == 0
    before = (folder / "src.h5").read_bytes()
    done = run(["acquisition", "import", "hits.json", "--out", "src.h5", "--overwrite", "--reference", "right:6:-X"],
               folder, 300_000)
    assert "nothing was written, the file there is unchanged" in one_line_exit_1(done)
    assert (folder / "src.h5").read_bytes() == before
    assert sorted(p.name for p in folder.iterdir()) == ["hits.json", "src.h5"]


# -- every writer of a whole file goes through analysis.atomic ----------------------------------
#: calls that write or create a file, by name
_WRITERS = {"write_text", "write_bytes", "savefig", "write_sets", "copyfile", "copy2", "copyfileobj", "dump",
            "to_csv", "to_parquet", "write_table", "save", "savez", "tofile"}
#: the writers that do not write a whole file in place, and why
_NOT_WHOLE_FILES = {
    ("analysis/atomic.py", "atomic_path"): "the helper itself (fsync of its temporary)",
    ("analysis/atomic.py", "fsync_file"): "the helper that syncs a file, opened for it (writes nothing)",
    ("analysis/batch/out_lock.py", "__init__"): "a lock file (a process id), not data",
    ("analysis/recording_lock.py", "__init__"): "the recording's lock file (a process id)",
    ("analysis/recording_lock.py", "live_copy"): "a reader's temporary copy, removed after reading",
    ("analysis/recording_lock.py", "live_copy_file"): "the same temporary copy, created",
    ("analysis/recording_writer.py", "_open_locked"): "the recording, appended to hit by hit (room reserved first)",
    ("analysis/recording_changes.py", "_replay"): "a new file (never replacing one): recover gives it atomic_path's "
                                                  "temporary, a reader its temporary copy",
    ("analysis/recording_repair.py", "_rewrite"): "the temporary atomic_path gave repair_recording, written in a child",
    ("analysis/report_html/build.py", "_write_files"): "files of a new temporary folder moved into place whole",
}


def _mode(call: ast.Call) -> str | None:
    for arg in call.args[1:2]:
        if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
            return arg.value
    for kw in call.keywords:
        if kw.arg == "mode" and isinstance(kw.value, ast.Constant):
            return str(kw.value.value)
    return None


def _writes(call: ast.Call) -> bool:
    f = call.func
    name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
    if name in _WRITERS:
        return True
    if name == "open" and isinstance(f, ast.Attribute) and getattr(f.value, "id", "") == "os":
        return "O_CREAT" in ast.dump(call)
    if name in ("open", "fdopen", "File"):
        mode = _mode(call)
        return (mode is not None and any(c in mode for c in "wax+")) or (name == "File" and mode is None
                                                                         and len(call.args) > 1)
    return False


def _raw_writers(path: Path) -> set[tuple[str, str]]:
    """(file, function) of each call writing a file outside a ``with atomic_path(...)`` or
    ``with whole_recording(...)`` block."""
    found: set[tuple[str, str]] = set()
    rel = path.relative_to(ROOT).as_posix()

    def visit(node: ast.AST, func: str, guarded: bool) -> None:
        for child in ast.iter_child_nodes(node):
            f, g = func, guarded
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                f = child.name
            if isinstance(child, ast.With):
                for item in child.items:
                    e = item.context_expr
                    if isinstance(e, ast.Call) and getattr(e.func, "attr", getattr(e.func, "id", "")) in (
                            "atomic_path", "whole_recording"):
                        g = True
            if isinstance(child, ast.Call) and not g and _writes(child):
                found.add((rel, f))
            visit(child, f, g)

    visit(ast.parse(path.read_text(encoding="utf-8")), "<module>", False)
    return found


def test_every_whole_file_is_written_through_the_atomic_helper():
    sources = [p for pkg in ("analysis", "acquisition", "simulator") for p in sorted((ROOT / pkg).rglob("*.py"))]
    raw = set().union(*(_raw_writers(p) for p in sources))
    assert not raw - set(_NOT_WHOLE_FILES), "write these through analysis.atomic (atomic_path, write_*_atomic)"


# -- temporaries of killed processes -------------------------------------------------------------
def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait(30)
    return child.pid


def test_temporaries_of_killed_processes_are_removed_by_the_next_write(tmp_path):
    dead, target = _dead_pid(), tmp_path / "fit.json"
    stale_file = tmp_path / f".fit.json.{dead}-0123456789ab.part"
    stale_file.write_text("half")
    stale_lock = tmp_path / f".fit.json.{dead}-0123456789ab.part.lock"
    stale_lock.write_text(str(dead))
    alive = atomic.temporary_beside(target)  # this process still runs: its temporary stays
    alive.write_text("being written")
    other = tmp_path / f".other.json.{dead}-0123456789ab.part"
    other.write_text("another file's")
    atomic.write_json_atomic(target, {"v": 1})
    assert not stale_file.exists() and not stale_lock.exists()
    assert alive.exists() and other.exists() and json.loads(target.read_text()) == {"v": 1}
    report = tmp_path / f".report.{dead}-00ff00ff00ff.part"  # a report's folder, killed while built
    (report / "sub").mkdir(parents=True)
    (report / "sub" / "index.html").write_text("<html>")
    assert atomic.remove_stale_temporaries(tmp_path / "report") == 1 and not report.exists()


READER = """
import sys, time
from analysis.recording import Recording
rec = Recording(sys.argv[1])
print("live" if rec.live else "closed", flush=True)
time.sleep(120)
"""


def test_a_killed_reader_leaves_its_live_copy_beside_the_recording_and_the_next_reader_removes_it(tmp_path):
    from test_reliability_live import _start_writer, _stop, _write

    path = tmp_path / "rec.h5"
    writer = _start_writer(path)
    try:
        assert _write(writer, 3) == 3
        reader = subprocess.Popen([sys.executable, "-c", READER, str(path)], stdout=subprocess.PIPE, text=True)
        try:
            assert reader.stdout is not None and reader.stdout.readline().strip() == "live"
            copies = sorted(tmp_path.glob(".rec.h5.*.part"))
            assert [c.name.split(".")[3].split("-")[0] for c in copies] == [str(reader.pid)]
        finally:
            reader.send_signal(signal.SIGKILL)
            reader.wait(30)
            if reader.stdout is not None:
                reader.stdout.close()
        assert copies[0].exists()  # left by the killed reader, beside the recording, where it is seen
        with Recording(path) as rec:  # the next reader removes it (and its own copy when done)
            assert rec.live and rec.n_hits == 3
            assert not copies[0].exists()
        assert not list(tmp_path.glob(".rec.h5.*.part"))
    finally:
        assert _stop(writer) == 0
    assert sorted(os.listdir(tmp_path)) == ["rec.h5"]
