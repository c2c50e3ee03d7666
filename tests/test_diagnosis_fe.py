"""``diagnose --simulated model.toml`` with the user's own FE model (an ``[fe]`` table): a spring-mass chain
given as Matrix Market files. The "measured" FRFs come from a direct frequency-response solve of the
changed chain with hysteretic damping and a dashpot plus noise (tests/fe_chain.py), not from the modal
synthesis the diagnosis fits (no inverse crime)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from fe_chain import chain_matrices, direct_frfs, write_chain

from analysis.cli_diagnose import main, simulation_kind
from analysis.uff import write_uff58

N = 6
#: the FE causes and the damping: the FRF-level catalogue beyond them is tested elsewhere
EFFECTS = "added_mass,ground_spring,stiffness_shift,mass_scale,mass_loading,damping_change"
ROOT = Path(__file__).resolve().parents[1]


def _measured(tmp_path: Path, K: sp.spmatrix, M: sp.spmatrix, seed: int) -> Path:
    f = np.arange(1, 1361) * 0.25
    frf = direct_frfs(K, M, [1, 3, 5], N - 1, f, seed=seed, noise=0.02)
    path = tmp_path / "measured.uff"
    write_uff58(path, frf)
    return path


def _diagnose(tmp_path: Path, measured: Path, toml: Path, capsys: pytest.CaptureFixture) -> tuple[int, dict, str]:
    out = tmp_path / "diag.json"
    code = main(["--measured", str(measured), "--simulated", str(toml), "--json", str(out), "--band", "5:340",
                 "--effects", EFFECTS])
    cap = capsys.readouterr()
    return code, json.loads(out.read_text()) if out.exists() else {}, cap.out + cap.err


def test_an_fe_toml_is_its_own_kind_of_simulation(tmp_path: Path) -> None:
    toml = write_chain(tmp_path / "m", N)
    frame = tmp_path / "frame.toml"
    frame.write_text("[material]\n")
    assert simulation_kind(str(toml)) == "fe_model"
    assert simulation_kind(str(frame)) == "frame_config"
    assert simulation_kind(str(tmp_path / "a.uff")) == "frf_file"


def test_an_added_mass_is_named_with_its_node_and_size(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    K, M = chain_matrices(N)
    M = M + sp.diags(0.3 * np.eye(N)[3])                # 0.3 kg at DOF 3: node n:4, not measured
    code, doc, text = _diagnose(tmp_path, _measured(tmp_path, K, M, 1), write_chain(tmp_path / "m", N), capsys)
    assert code == 0, text
    assert doc["verdict"] == "added_mass", text
    named = doc["named"][0]["parameters"]
    assert named["point"] == "n:4"
    assert named["mass_kg"] == pytest.approx(0.3, rel=0.03)


def test_a_spring_to_ground_is_named_with_its_node_and_stiffness(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture) -> None:
    K, M = chain_matrices(N)
    K = K + sp.diags(2.0e5 * np.eye(N)[2])              # 2e5 N/m to ground at DOF 2: node n:3
    code, doc, text = _diagnose(tmp_path, _measured(tmp_path, K, M, 2), write_chain(tmp_path / "m", N), capsys)
    assert code == 0, text
    assert doc["verdict"] == "ground_spring", text
    named = doc["named"][0]["parameters"]
    assert named["point"] == "n:3"
    assert named["stiffness_n_m"] == pytest.approx(2.0e5, rel=0.03)


def test_the_unchanged_chain_names_nothing(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    K, M = chain_matrices(N)
    code, doc, text = _diagnose(tmp_path, _measured(tmp_path, K, M, 3), write_chain(tmp_path / "m", N), capsys)
    assert code == 0, text
    assert doc["verdict"] == "none" and doc["named"] == [], text


def test_a_group_stiffness_change_is_named_with_its_group(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """The springs between DOFs 3, 4 and 5 (group "tip") 0.7 times as stiff."""
    k = 1.0e6
    K, M = chain_matrices(N)
    K = K.tolil()
    for i in (3, 4):
        d = -0.3 * k                                    # spring i-(i+1) loses 30 %
        K[i, i] += d
        K[i + 1, i + 1] += d
        K[i, i + 1] -= d
        K[i + 1, i] -= d
    toml = write_chain(tmp_path / "m", N, groups={0: "base", 1: "base", 2: "base", 3: "tip", 4: "tip", 5: "tip"})
    out = tmp_path / "diag.json"
    code = main(["--measured", str(_measured(tmp_path, K.tocsr(), M, 4)), "--simulated", str(toml), "--json",
                 str(out), "--band", "5:340", "--effects", EFFECTS + ",group_stiffness,group_mass"])
    cap = capsys.readouterr()
    doc = json.loads(out.read_text())
    assert code == 0 and doc["verdict"] == "group_stiffness", cap.out + cap.err
    named = doc["named"][0]["parameters"]
    assert named["group"] == "tip" and named["factor"] == pytest.approx(0.7, rel=0.03)


def test_bad_fe_input_is_one_line_and_exit_1(tmp_path: Path) -> None:
    """Through the real command: a non-symmetric stiffness matrix, then a measured point the map lacks."""
    K, M = chain_matrices(N)
    measured = _measured(tmp_path, K, M, 5)
    bad = K.tolil()
    bad[0, 2] = 5.0
    toml = write_chain(tmp_path / "m", N, K=bad.tocsr(), symmetric=False)
    cmd = [sys.executable, "-m", "analysis", "diagnose", "--measured", str(measured), "--simulated", str(toml),
           "--json", str(tmp_path / "d.json")]
    run = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert run.returncode == 1, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and str(tmp_path / "m" / "K.mtx") in lines[0] and "row 1, column 3" in lines[0]
    toml = write_chain(tmp_path / "m2", N)
    (tmp_path / "m2" / "dofs.csv").write_text("dof,point\n" + "".join(f"{i},n:{i + 1}:Z\n" for i in range(4)))
    cmd[cmd.index(str(tmp_path / "m" / "model.toml"))] = str(toml)
    run = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=120)
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 1 and len(lines) == 1, run.stderr
    assert str(tmp_path / "m2" / "dofs.csv") in lines[0] and "n:6:Z" in lines[0]
