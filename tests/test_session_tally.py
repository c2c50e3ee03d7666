"""During ``acquisition capture`` the terminal shows, after each hit, every point's accepted hits against
the hits asked (``top:4:Z 1/2``): run at a real pseudo-terminal, one key press per hit (acquisition.session)."""
from __future__ import annotations

import os
import re
import select
import subprocess
import sys
from pathlib import Path

import pytest

from analysis.recording import Recording

ROOT = Path(__file__).resolve().parents[1]
PROMPT = "accept (a), reject (r), quit (q)?"


class _Terminal:
    """A child process on a pty: read until a text shows, then type a key."""

    def __init__(self, argv: list[str], cwd: Path) -> None:
        self.master, slave = os.openpty()
        env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1", "MPLBACKEND": "Agg"}
        self.proc = subprocess.Popen(argv, stdin=slave, stdout=slave, stderr=slave, cwd=cwd, env=env, close_fds=True)
        os.close(slave)
        self.text = ""

    def read_until(self, needle: str, start: int) -> int:
        """Position just past the next ``needle`` after ``start`` (fails the test if the program ends first)."""
        while needle not in self.text[start:]:
            ready, _, _ = select.select([self.master], [], [], 60)   # a hang guard only, never a timing check
            assert ready, f"no {needle!r} in:\n{self.text[start:]}"
            try:
                chunk = os.read(self.master, 4096)
            except OSError:      # the child closed the pty
                chunk = b""
            assert chunk, f"the program ended before {needle!r}:\n{self.text[start:]}"
            self.text += chunk.decode(errors="replace").replace("\r\n", "\n")
        return self.text.index(needle, start) + len(needle)

    def type(self, key: str) -> None:
        os.write(self.master, key.encode())

    def finish(self) -> int:
        """Read to the end of the program's output; its exit code."""
        try:
            while True:
                chunk = os.read(self.master, 4096)
                if not chunk:
                    break
                self.text += chunk.decode(errors="replace").replace("\r\n", "\n")
        except OSError:   # the child closed the pty
            pass
        return self.proc.wait()

    def kill(self) -> None:
        """End the program if it still runs (a failed test) and release the pty."""
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        os.close(self.master)


@pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pseudo-terminal")
def test_the_terminal_counts_accepted_hits_per_point_as_the_operator_keys_them(tmp_path) -> None:
    rec = tmp_path / "rec.h5"
    term = _Terminal([sys.executable, "-m", "acquisition", "capture", "--device", "sim://?seed=1", "--out", str(rec),
                      "--hits", "2", "--points", "right:6:-X,top:4:Z"], tmp_path)
    tallies = []
    pos = 0
    try:
        for key in "araa" + "a":   # accept, reject, accept (right:6:-X done), accept, accept (top:4:Z done)
            pos = term.read_until(PROMPT, pos)
            term.type(key)
            pos = term.read_until("per point ", pos)
            end = term.read_until("\n", pos)
            tallies.append(term.text[pos:end].strip())
        code = term.finish()
    finally:
        term.kill()
    assert code == 0, term.text[-2000:]
    assert tallies == ["right:6:-X 1/2, top:4:Z 0/2",
                       "right:6:-X 1/2, top:4:Z 0/2",    # the rejected hit counts for nothing
                       "right:6:-X 2/2, top:4:Z 0/2",
                       "right:6:-X 2/2, top:4:Z 1/2",
                       "right:6:-X 2/2, top:4:Z 2/2"], term.text
    # the key was read from the terminal itself (one key, no Enter): echoed after the prompt
    assert re.search(re.escape(PROMPT) + r" ?r\n", term.text), term.text
    with Recording(rec) as r:
        assert [h.accepted for h in r.hits()] == [True, False, True, True, True]
