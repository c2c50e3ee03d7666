"""One structure measured at several drive levels: ``diagnose --measured A B --levels LA,LB`` (and the Python
API ``diagnose([A, B], sim, levels=[...])``). The lowest level is compared with the simulation; the levels
with one another mode by mode: modes that move beyond their uncertainty are named ``joint_nonlinearity``
with their shifts per level; a linear structure names nothing."""
from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest

from analysis.frf import FRFSet
from analysis.modal import ModalModel, pole_from_fz, synthesize

OUTS = ("b:1:Z", "b:2:Z", "b:3:Z")
REF = ("b:1:Z",)


def _level(f_hz: np.ndarray, zeta: np.ndarray, seed: int) -> FRFSet:
    """Accelerance of a three-mode structure at three outputs, 1 % noise (seeded)."""
    lam = pole_from_fz(f_hz, zeta)
    phi = np.array([[1.0, 0.8, 0.5], [0.7, -0.6, -0.9], [0.4, -0.9, 0.8]])
    R = np.einsum("om,rm->orm", phi, phi[:1]) / (2j * lam.imag)[None, None, :]
    model = ModalModel(poles=lam, residues=R, quantity="receptance", outputs=OUTS, references=REF)
    frf = synthesize(model, np.arange(2.0, 400.0, 0.25)).as_quantity("accelerance")
    rng = np.random.default_rng(seed)
    H = frf.H * (1 + 0.01 * (rng.standard_normal(frf.H.shape) + 1j * rng.standard_normal(frf.H.shape)) / np.sqrt(2))
    return FRFSet(freq_hz=frf.freq_hz, H=H, quantity="accelerance", outputs=OUTS, references=REF)


F = np.array([60.0, 150.0, 290.0])
Z = np.array([0.01, 0.012, 0.015])


def test_api_names_the_softening_with_its_shift_per_level():
    from analysis.diagnosis import diagnose

    sim = _level(F, Z, 1)
    low, mid, high = _level(F, Z, 2), _level(F * [1, 0.995, 1], Z * [1, 1.2, 1], 3), \
        _level(F * [1, 0.99, 1], Z * [1, 1.4, 1], 4)
    d = diagnose([high, low, mid], sim, levels=[1.0, 0.1, 0.3], effects=["stiffness_shift"])
    assert d.verdict == "joint_nonlinearity" and d.linear_verdict == "none"
    named = d.named[0]
    assert named["effect"] == "joint_nonlinearity" and named["parameters"]["kind"] == "micro-slip friction"
    assert named["parameters"]["freq_hz"] == pytest.approx([150.0], rel=1e-3)
    assert named["parameters"]["df_percent"] == pytest.approx([-1.0], abs=0.1)
    rows = d.level_dependence["cause"]["per_level"]
    assert [r["level"] for r in rows] == [0.3, 1.0]
    shifts = [[m["df_percent"] for m in r["modes"]] for r in rows]
    np.testing.assert_allclose(shifts, [[0, -0.5, 0], [0, -1.0, 0]], atol=0.1)
    assert d.to_json()["level_dependence"]["cause"]["present"] is True


def test_api_a_linear_structure_at_two_levels_names_nothing():
    from analysis.diagnosis import diagnose

    d = diagnose([_level(F, Z, 5), _level(F, Z, 6)], _level(F, Z, 7), levels=[40.0, 200.0],
                 effects=["stiffness_shift"])
    assert d.verdict == "none" and d.named == [] and d.linear_verdict is None
    assert d.level_dependence["cause"]["present"] is False
    assert d.level_dependence["linearity"]["verdict"] == "linear"


def _cli(args: list[str]) -> tuple[int, str, str]:
    from analysis.cli_diagnose import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(args)
    return rc, out.getvalue(), err.getvalue()


def test_cli_bad_levels_are_one_line_usage_errors(tmp_path):
    from analysis.uff import write_uff58

    paths = []
    for i in range(2):
        paths.append(str(tmp_path / f"l{i}.uff"))
        write_uff58(paths[-1], _level(F, Z, 10 + i))
    for extra, words in ((["--levels", "1"], "1 level(s) for 2 measured file(s)"),
                         ([], "give --levels"),
                         (["--levels", "1,x"], "not a number")):
        rc, _, err = _cli(["--measured", *paths, "--simulated", paths[0], *extra, "-q"])
        assert rc == 2 and words in err and len(err.strip().splitlines()) == 1, err
    rc, _, err = _cli(["--measured", paths[0], "--levels", "1", "--simulated", paths[1], "-q"])
    assert rc == 2 and "at least two" in err


def test_cli_the_linear_frame_struck_at_40_and_200_n_names_nothing(tmp_path):
    """Two recordings of the linear simulated frame (three points, five hits each) at 40 N and 200 N, a third
    at 40 N as the simulation: the levels are linear and nothing is named."""
    from acquisition.cli_capture import main as capture

    paths = {}
    for name, force, seed in (("soft", 40.0, 5006), ("hard", 200.0, 5007), ("sim", 40.0, 5008)):
        cfg = tmp_path / f"{name}.toml"
        cfg.write_text(f"[hammer]\namplitude_n = {force}\n")
        paths[name] = str(tmp_path / f"{name}.h5")
        with contextlib.redirect_stdout(io.StringIO()):
            assert capture(["--device", f"sim://?seed={seed}&config={cfg}", "--out", paths[name], "--points",
                            "right:6:-X,left:6:X,top:4:Z", "--hits", "5", "--auto", "-q"]) == 0
    out = tmp_path / "d.json"
    rc, text, err = _cli(["--measured", paths["hard"], paths["soft"], "--levels", "200,40", "--simulated",
                          paths["sim"], "--effects", "stiffness_shift,damping_change", "--json", str(out), "-q"])
    assert rc == 0, err
    doc = json.loads(out.read_text())
    assert doc["verdict"] == "none" and doc["named"] == [], doc.get("reason")
    assert doc["level_dependence"]["linearity"]["verdict"] == "linear"
    assert doc["level_dependence"]["linearity"]["levels"] == [40.0, 200.0]
    assert "linear within the noise" in text


@pytest.mark.realdata
def test_cli_the_real_bolted_beam_at_two_drive_levels_names_the_joint(shared_data, tmp_path):
    """UNESP-BERT bolted beam (SHM Lab, UNESP Ilha Solteira), random drive at 0.05 V and 0.30 V: its three
    modes in 10-300 Hz soften (-0.2 to -1.1 %) and damp more at the higher level: joint_nonlinearity, with the
    shifts per level; the lowest level is its own simulation here (nothing else differs)."""
    from analysis.uff import write_uff58
    from benchmarks.accuracy.validation import unesp_boltedbeam as ub

    paths = {}
    for lv in ("0p05", "0p30"):
        paths[lv] = str(tmp_path / f"rand_{lv}.uff")
        write_uff58(paths[lv], ub.load(shared_data, lv))
    out = tmp_path / "d.json"
    rc, text, err = _cli(["--measured", paths["0p30"], paths["0p05"], "--levels", "0.30,0.05", "--simulated",
                          paths["0p05"], "--band", "10:300", "--effects", "stiffness_shift", "--json", str(out), "-q"])
    assert rc == 0, err
    doc = json.loads(out.read_text())
    assert doc["verdict"] == "joint_nonlinearity" and doc["linear_verdict"] == "none"
    p = doc["named"][0]["parameters"]
    assert p["kind"] == "micro-slip friction" and p["levels"] == [0.05, 0.30]
    assert len(p["freq_hz"]) == 3 and all(d < 0 for d in p["df_percent"])
    m98 = p["freq_hz"].index(min(p["freq_hz"], key=lambda f: abs(f - 98.4)))
    assert -1.3 < p["df_percent"][m98] < -0.8 and p["dzeta_percent"][m98] > 15
    assert doc["level_dependence"]["cause"]["per_level"][0]["level"] == 0.30
    assert "verdict: joint_nonlinearity" in text and "level 0.3:" in text
