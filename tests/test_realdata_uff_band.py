"""The LADISK free-free beam's single hit, imported and exported to UFF 58 with the project's own commands,
fitted from the UFF (no force spectrum, one average): the band ends where the force does, no pole above it,
and the beam's suspension modes are named as such.

Source (see ../shared/data/README.md): ladisk/open_source_research_in_structural_dynamics, data/acceleration.lvm
(LADISK, University of Ljubljana, MIT). The analyst's key: benchmarks/accuracy/validation/ladisk_beam.py.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from analysis.recording import load_frfset
from benchmarks.accuracy.validation import ladisk_beam as key

pytestmark = pytest.mark.realdata

ROOT = Path(__file__).resolve().parents[1]


def _run(*args: str) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, *args], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]


def test_ladisk_uff_export_is_fitted_within_the_force_band(shared_data, tmp_path):
    rec, uff, out = tmp_path / "beam.h5", tmp_path / "beam.uff", tmp_path / "fit.json"
    _run("-m", "acquisition", "import", str(shared_data / "ladisk_beam_impact" / "acceleration.lvm"),
         "--out", str(rec), "-q")
    _run("-m", "acquisition", "export", str(rec), "--uff", str(uff), "-q")
    _run("-m", "analysis", "fit", str(uff), "--json", str(out), "-q")
    fit = json.loads(out.read_text())
    force_end = float(np.atleast_1d(load_frfset(rec).meta["excitation_limit_hz"])[0])   # the recording's force, 20 dB down
    assert force_end < key.KEY_SINGLE_FORCE_END_HZ
    lo, hi = fit["band"]
    # the UFF carries no force spectrum: its noise floor puts the top within 5 % of the force's end
    # (6.67 kHz for 6.42 kHz), not at the 25 kHz of the data
    assert hi <= 1.05 * force_end
    freqs = np.array([p["freq_hz"] for p in fit["poles"]])
    assert not np.any(freqs > force_end)
    for x in key.KEY_SINGLE_BENDING_HZ:
        assert np.min(np.abs(freqs - x)) < 0.001 * x
    assert sorted(fit["suspension_modes_hz"]) == pytest.approx(key.KEY_SINGLE_SUSPENSION_HZ, rel=0.03)
    assert not any("suspension" in p or "17.9" in p or "36.9" in p for p in fit["problems"])
    assert fit["success"]
