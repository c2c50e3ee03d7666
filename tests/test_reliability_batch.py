"""Batch and command-line robustness: one line and the documented exit code for Ctrl-C, a full
disk, an unreadable file; one batch per output folder; glob matches that are not files named; no
Dask dashboard unless asked."""
from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest

from analysis.command_line import cli_entry


def _command(exc: BaseException):
    def main(argv=None) -> int:
        raise exc

    main.__module__ = "analysis.cli_batch"
    return cli_entry(main)


@pytest.mark.parametrize("exc, code, text", [
    (KeyboardInterrupt(), 130, "analysis batch: interrupted (Ctrl-C)"),
    (OSError(errno.ENOSPC, "No space left on device", "out/fits/unit-003.json"), 1,
     "analysis batch: No space left on device: out/fits/unit-003.json"),
    (PermissionError(errno.EACCES, "Permission denied", "secret.uff"), 1, "Permission denied: secret.uff"),
    (MemoryError(), 1, "out of memory"),
    (RecursionError("maximum recursion depth exceeded"), 2, "nested too deeply"),
])
def test_uncaught_interrupt_and_system_errors_are_one_line_with_the_documented_code(capsys, exc, code, text):
    assert _command(exc)([]) == code
    err = capsys.readouterr().err
    assert text in err and err.count("\n") == 1 and "Traceback" not in err


def test_fit_on_an_unreadable_file_is_one_line(tmp_path, monkeypatch, capsys):
    from analysis.inputs import InputError, detect_format

    p = tmp_path / "x.uff"
    p.write_text("-1\n")

    def denied(self, *a, **k):
        raise PermissionError(errno.EACCES, "Permission denied", str(self))

    monkeypatch.setattr(Path, "open", denied)
    with pytest.raises(InputError, match="cannot read .*x.uff: Permission denied"):
        detect_format(p)


def test_glob_matches_that_are_not_files_are_named(tmp_path):
    from analysis.cli_batch import expand_inputs

    (tmp_path / "a.h5").write_bytes(b"x")
    (tmp_path / "loop.h5").symlink_to(tmp_path / "loop.h5")
    (tmp_path / "gone.h5").symlink_to(tmp_path / "missing")
    (tmp_path / "dir.h5").mkdir()
    skipped: list[str] = []
    assert expand_inputs([str(tmp_path / "*.h5")], skipped) == [tmp_path / "a.h5"]
    text = " ".join(skipped)
    assert len(skipped) == 3 and "loop.h5 (a symbolic link that loops)" in text
    assert "gone.h5 (a dangling symbolic link)" in text and "dir.h5 (a folder)" in text


def test_a_second_batch_on_the_same_out_folder_refuses_naming_the_first(tmp_path, capsys):
    from analysis.cli_batch import main

    out = tmp_path / "out"
    out.mkdir()
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time\nfrom analysis.batch.out_lock import FolderLock\n"
                               "lock = FolderLock(sys.argv[1])\nprint('held', flush=True)\ntime.sleep(60)", str(out)],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        (tmp_path / "u.uff").write_text("-1\n")
        assert main([str(tmp_path / "u.uff"), "--out", str(out), "--workers", "1"]) == 1
        err = capsys.readouterr().err
        assert f"in use by another batch (process {holder.pid})" in err and err.count("\n") == 1
    finally:
        holder.kill()
        holder.wait()
        assert holder.stdout is not None
        holder.stdout.close()
    from analysis.batch.out_lock import FolderLock

    FolderLock(out).release()  # the holder is gone: the folder is free again


def test_no_dask_dashboard_unless_asked():
    from analysis.batch.run import open_client

    client = open_client(workers=1)
    try:
        ports = [s.getsockname()[1] for s in client.cluster.scheduler.http_server._sockets.values()]
        hosts = [s.getsockname()[0] for s in client.cluster.scheduler.http_server._sockets.values()]
        assert 8787 not in ports and set(hosts) <= {"127.0.0.1"}
    finally:
        cluster = client.cluster
        client.close()
        cluster.close()
    assert os.environ.get("DASK_DISTRIBUTED__DASHBOARD") is None
