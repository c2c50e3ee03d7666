"""Static web assets shipped by optional packages (no CDN: pages must open from ``file://``).

:func:`plotly_js_path` finds plotly.js inside the PyPI package ``plotly`` (the ``report`` extra).
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

from .errors import MissingAssetError

__all__ = ["MissingAssetError", "plotly_js_path"]


def plotly_js_path() -> Path:
    """Path of ``plotly.min.js`` shipped in the ``plotly`` package (``package_data/plotly.min.js``).

    Raises :class:`MissingAssetError` naming the extra to install when plotly is absent.
    """
    spec = importlib.util.find_spec("plotly")
    hint = "install the report extra: pip install 'impactlab[report]' (or pip install plotly)"
    if spec is None or not spec.submodule_search_locations:
        raise MissingAssetError(f"plotly.js is needed for HTML reports but the plotly package is not installed: {hint}")
    for root in spec.submodule_search_locations:
        path = Path(root) / "package_data" / "plotly.min.js"
        if path.is_file():
            return path
    raise MissingAssetError(f"the installed plotly package has no package_data/plotly.min.js: reinstall it ({hint})")
