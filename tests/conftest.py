"""Shared fixtures. Real measured data lives in ../shared/data and is never committed."""
from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"


@pytest.fixture
def shared_data() -> Path:
    """Path to ../shared/data; skips the test when the folder is absent (fresh clone elsewhere)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real measured data not found at {SHARED_DATA} (only present in the workplace)")
    return SHARED_DATA
