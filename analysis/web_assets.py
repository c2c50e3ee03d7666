"""Browser assets shipped by installed packages (served offline: nothing from a CDN)."""
from __future__ import annotations

import pathlib

__all__ = ["plotly_js_path"]


def plotly_js_path() -> pathlib.Path:
    """Path of ``plotly.min.js`` inside the installed ``plotly`` package (``pip install plotly``).

    Raises ModuleNotFoundError naming the package to install when plotly is missing."""
    try:
        import plotly
    except ModuleNotFoundError:
        raise ModuleNotFoundError("the plots need the 'plotly' package: pip install plotly "
                                  "(or the project's extra: pip install -e '.[station]')") from None
    return pathlib.Path(plotly.__file__).resolve().parent / "package_data" / "plotly.min.js"
