"""Load a benchmark script (``benchmarks/<kind>/<name>.py``) as a module, for tests that reuse its cases."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]


def load_benchmark(relative_path: str) -> ModuleType:
    """The script ``benchmarks/<relative_path>`` imported under its file name (registered in
    ``sys.modules``: dataclasses look their module up)."""
    path = ROOT / "benchmarks" / relative_path
    spec = importlib.util.spec_from_file_location(path.stem, path)
    assert spec is not None and spec.loader is not None, f"cannot load {path}"
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod
