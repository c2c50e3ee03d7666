"""tests/conftest.py: the asserts of the test modules rewritten in turn by the processes of ``make test``."""
from __future__ import annotations

import os
from pathlib import Path

import pytest
from _pytest.assertion.rewrite import PYC_TAIL, _read_pyc
from conftest import rewrite_in_turn


def _module(folder: Path, name: str) -> Path:
    path = folder / f"{name}.py"
    path.write_text("def test_it():\n    x = 1\n    assert x == 2\n")
    return path


@pytest.fixture(autouse=True)
def _bytecode_written(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("sys.dont_write_bytecode", False)     # as in make test, whatever the caller's environment


def test_each_file_is_rewritten_once_into_the_pyc_pytest_reads(pytestconfig: pytest.Config, tmp_path: Path) -> None:
    """Two processes of three: each writes the files from its own share on; a file with a pyc newer than its source
    is not rewritten again; the pyc is the one pytest's import accepts, with pytest's assert message."""
    files = [_module(tmp_path, f"test_m{k}") for k in range(6)]
    assert rewrite_in_turn(pytestconfig, files[2:4], 1, 3) == 2        # gw1 of 3, first (given two files): both
    assert rewrite_in_turn(pytestconfig, files, 0, 3) == 4             # gw0: the four others only
    for fn in files:
        co = _read_pyc(fn, tmp_path / "__pycache__" / (fn.name[:-3] + PYC_TAIL))
        assert co is not None and co.co_filename == str(fn)
        space: dict = {}
        exec(co, space)
        with pytest.raises(AssertionError, match="assert 1 == 2"):   # the rewritten assert tells the values
            space["test_it"]()
    later = os.stat(files[0]).st_mtime + 10
    os.utime(files[0], (later, later))                                  # an edited source: rewritten again
    assert rewrite_in_turn(pytestconfig, files, 2, 3) == 1


def test_a_file_pytest_cannot_rewrite_is_left_to_pytest(pytestconfig: pytest.Config, tmp_path: Path) -> None:
    """A syntax error: no pyc, the others still written (pytest's own import reports the error)."""
    bad = tmp_path / "test_bad.py"
    bad.write_text("def test_it(:\n")
    assert rewrite_in_turn(pytestconfig, [bad, _module(tmp_path, "test_good")], 0, 1) == 1
    assert not (tmp_path / "__pycache__" / ("test_bad" + PYC_TAIL)).exists()
