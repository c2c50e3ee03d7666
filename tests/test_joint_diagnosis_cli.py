"""End to end: a frame with a friction joint captured through sim:// (hits of widely scattered force),
then ``python -m analysis diagnose`` against the nominal frame names joint_nonlinearity at that joint."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

NOMINAL = """[joints]
stiffness = [1e9, 1e9, 1e9, 1e8, 2e4, 1e8]

[supports]
stiffness = [1e9, 1e9, 1e9, 1.6e7, 5e4, 1.6e7]
"""

MEASURED = NOMINAL + """
[hammer]
amplitude_scatter = 1.0
double_hit_probability = 0.0
neighbour_probability = 0.0

[nonlinear]
law = "iwan"
joint = "right:10"
axis = "ry"
slip_moment_nm = 2.0
"""


@pytest.mark.long
def test_diagnose_names_the_friction_joint(tmp_path):
    (tmp_path / "nominal.toml").write_text(NOMINAL)
    (tmp_path / "measured.toml").write_text(MEASURED)
    rec = tmp_path / "rec.h5"
    cap = subprocess.run([sys.executable, "-m", "acquisition", "capture", "--device",
                          f"sim://?seed=11&config={tmp_path / 'measured.toml'}", "--out", str(rec), "--hits", "8",
                          "--points", "right:6:-X,left:6:X,top:4:Z", "--auto"],
                         capture_output=True, text=True, timeout=1200)
    assert cap.returncode == 0, cap.stderr
    assert "quality: linearity: nonlinear" in cap.stdout
    out = tmp_path / "diag.json"
    res = subprocess.run([sys.executable, "-m", "analysis", "diagnose", "--measured", str(rec), "--simulated",
                          str(tmp_path / "nominal.toml"), "--json", str(out)], capture_output=True, text=True,
                         timeout=1800)
    assert res.returncode == 0, res.stderr
    doc = json.loads(out.read_text())
    assert doc["verdict"] == "joint_nonlinearity"
    cause = doc["level_dependence"]["cause"]
    assert cause["present"] and "right:10" in cause["joint"]["nodes"] and cause["joint"]["axis"] == "ry"
    assert doc["level_dependence"]["linearity"]["verdict"] == "nonlinear"
