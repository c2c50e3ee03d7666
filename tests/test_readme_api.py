"""The README's Python API example runs as written (a short API from exported names),
and the notebook faces (reprs, .plot) of its results work."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def test_the_readme_python_api_example_runs_and_finds_the_frames_modes() -> None:
    text = (ROOT / "README.md").read_text()
    block = re.search(r"## Python API.*?```python\n(.*?)```", text, flags=re.S)
    assert block, "README has no Python API example"
    scope: dict = {}
    exec(compile(block.group(1), "README.md", "exec"), scope)  # noqa: S102 - our own documentation
    fit, frf = scope["fit"], scope["frf"]
    assert fit.success and fit.status == "converged"
    for f_true in (12.9, 35.1, 50.4, 81.7, 128.2):
        assert np.min(np.abs(fit.freq_hz - f_true)) / f_true < 0.01, (f_true, fit.freq_hz)
    # the three overlapping modes near 1 kHz, each with a pole of its own (995.2 Hz was held at 999.5 Hz, beside
    # the 1000.2 Hz pole, by the whole-band fit)
    for f_true in (995.2, 1000.2, 1007.5):
        assert np.min(np.abs(fit.freq_hz - f_true)) / f_true < 0.0015, (f_true, fit.freq_hz)
    assert "mode" in str(fit).splitlines()[0] and "converged" in str(fit)
    assert "<table>" in fit._repr_html_() and "FitResult(" in repr(fit)
    assert repr(frf).startswith("FRFSet(3 outputs x 3 references") and "sample rate 6400 Hz" in repr(frf)
    assert "<table>" in frf._repr_html_()
    assert len(frf.plot().axes) == 2 and len(scope["fig"].axes) == 3 * 4  # 4 FRFs x (magnitude, phase, error)
