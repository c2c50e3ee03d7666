"""Shared fixtures. Real measured data lives in ../shared/data and is never committed."""
from __future__ import annotations

import os
from pathlib import Path

# The tests solve many small linear-algebra problems; threaded OpenBLAS on the shared 2-core
# machine is 10-100x slower for them under contention. Must be set before numpy is imported.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: the real measurements (IMPACTLAB_SHARED_DATA overrides, e.g. from a git worktree elsewhere)
SHARED_DATA = Path(os.environ.get("IMPACTLAB_SHARED_DATA", ROOT.parent / "shared" / "data"))


@pytest.fixture
def shared_data() -> Path:
    """Path to ../shared/data; skips the test when the folder is absent (fresh clone elsewhere)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real measured data not found at {SHARED_DATA} (only present in the workplace)")
    return SHARED_DATA


@pytest.fixture(scope="session")
def report_case(tmp_path_factory) -> dict:
    """The report tests' small simulated test, its fit and report folders (tests/report_data.py)."""
    from report_data import make_report_case

    return make_report_case(tmp_path_factory)
