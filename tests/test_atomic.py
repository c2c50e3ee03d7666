"""Atomic writes (analysis.atomic): a failed or interrupted write never leaves a half file."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from analysis.atomic import atomic_path, write_json_atomic


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    target = tmp_path / "fleet.json"
    write_json_atomic(target, {"v": 1})
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text('{"v": 2, "half')
            raise RuntimeError("the writer failed midway")
    assert json.loads(target.read_text()) == {"v": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fleet.json"]
    with pytest.raises(ValueError):                       # NaN is refused before anything is written
        write_json_atomic(target, {"v": float("nan")})
    assert json.loads(target.read_text()) == {"v": 1}


def test_a_process_killed_while_writing_leaves_the_target_whole(tmp_path):
    target = tmp_path / "r.json"
    write_json_atomic(target, {"v": 1})
    code = (f"import os, signal\nfrom analysis.atomic import atomic_path\n"
            f"with atomic_path({str(target)!r}) as tmp:\n"
            f"    tmp.write_text('{{\"v\": 2, ')\n"
            f"    os.kill(os.getpid(), signal.SIGKILL)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True)
    assert done.returncode == -9
    assert json.loads(target.read_text()) == {"v": 1}     # the reader sees the old, whole file
    leftovers = [p.name for p in tmp_path.iterdir() if p.name != "r.json"]
    assert leftovers and all(n.startswith(".r.json.") and n.endswith(".part") for n in leftovers)
    assert os.stat(target).st_mode & 0o644 == 0o644       # the umask's permissions, not a temp file's 0600
