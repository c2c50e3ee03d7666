"""Running commands on a full disk: a child process with a file size limit (``RLIMIT_FSIZE``: a
write past it fails with ``EFBIG`` as a full disk fails with ``ENOSPC``; Python ignores the
``SIGXFSZ`` signal that comes with it)."""
from __future__ import annotations

import resource
import subprocess
import sys
from pathlib import Path

POINTS = "right:6:-X,top:4:Z,left:9:Y"
#: a simulated 3-point roving-hammer test, 2 accepted hits per point (add --out)
CAPTURE = ["acquisition", "capture", "--device", "sim://?seed=1", "--hits", "2", "--auto", "-q", "--points", POINTS]


def run(args: list[str], cwd: Path, limit: int | None = None) -> subprocess.CompletedProcess:
    """``python -m ARGS`` in ``cwd``; ``limit``: the child's file size limit in bytes."""
    def limited() -> None:
        assert limit is not None
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return subprocess.run([sys.executable, "-m", *args], cwd=cwd, capture_output=True, text=True, timeout=300,
                          preexec_fn=limited if limit is not None else None)


def one_line_exit_1(done: subprocess.CompletedProcess) -> str:
    """The stderr line of a command a full disk stopped: exit 1 and one line besides the progress
    lines and the fit's notes and warnings (what the fit found, not the failure), no traceback."""
    assert done.returncode == 1, (done.returncode, done.stderr[-2000:])
    lines = [ln for ln in done.stderr.strip().splitlines() if not ln.startswith(("... ", "note: ", "warning: ", "WARNING analysis."))]
    assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr[-2000:]
    return lines[0]


#: capture arguments of a recording of one point with two hits (for the ``sim_capture`` fixture)
ONE_POINT = (*CAPTURE[2:-3], "--points", "right:6:-X")
#: capture arguments of CAPTURE's recording (for the ``sim_capture`` fixture)
THREE_POINTS = (*CAPTURE[2:-3], "--points", POINTS)
