"""``analysis batch --diagnose SIM``: the fleet's flagged units diagnosed on Dask's own workers.

A small fleet made by ``simulator fleet`` (4 FE frames with +-1 % scatter, one with a physical defect,
2 hits each) is fitted and flagged on a LocalCluster of 2 worker processes, the flagged unit is
diagnosed against the nominal frame config on the same workers, a restart reuses the stored
diagnosis, and a SIM that is not the fleet's structure is refused before the work it would spoil.
Dask runs in child processes only (see tests/test_batch_dask.py)."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")
pytest.importorskip("pyarrow")

from analysis.batch.diagnose import (  # noqa: E402
    describe_diagnosis,
    diagnosis_summary,
    modes_problem,
    peaks_problem,
    structure_problem,
)
from analysis.batch.unit_modes import UnitModes  # noqa: E402
from analysis.cli_batch import main as batch  # noqa: E402
from simulator.cli_fleet import main as fleet  # noqa: E402

ENV = {**{k: v for k, v in os.environ.items() if k != "MALLOC_TRIM_THRESHOLD_"}, "DASK_LOGGING__DISTRIBUTED": "error"}

#: the catalogue's cause that expresses each defect kind of ``simulator fleet``
CAUSE_OF = {"soft_joint": "joint_stiffness", "loose_support": "support_stiffness", "cracked_member": "element_stiffness"}


def _batch_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "analysis", "batch", *args], capture_output=True, text=True,
                          timeout=400, env=ENV)


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("fleet")
    # +-1 % scatter: the defect (a soft joint) is named alone, in about a fifth of the work of the default +-2 %,
    # where the unit's own modulus is named beside it (the fleet hold-out runs the default scatter)
    assert fleet(["--units", "4", "--defects", "1", "--out", str(out), "--seed", "11", "--hits", "2", "--jobs", "1",
                  "--scatter", "1", "-q"]) == 0
    (out / "nominal.toml").write_text("# the frame as designed: simulator/frame.toml's defaults\n")
    return out


@pytest.fixture(scope="module")
def diagnosed(fleet_dir, tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    out = tmp_path_factory.mktemp("batch") / "out"
    done = _batch_cli(str(fleet_dir / "unit-*.h5"), "--out", str(out), "--workers", "2",
                      "--diagnose", str(fleet_dir / "nominal.toml"))
    return out, done


def _defective(fleet_dir: Path) -> dict[str, dict]:
    return {u["name"]: u["defect"] for u in json.loads((fleet_dir / "truth.json").read_text())["units"] if u["defect"]}


def test_the_flagged_unit_is_diagnosed_and_the_good_units_are_not(fleet_dir, diagnosed):
    out, done = diagnosed
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    bad = _defective(fleet_dir)
    assert len(bad) == 1
    name, defect = next(iter(bad.items()))
    doc = json.loads((out / "fleet.json").read_text())
    units = {u["name"]: u for u in doc["units"]}
    assert {n for n, u in units.items() if u["flagged"]} == {name}
    diag = units[name]["diagnosis"]
    assert set(diag) == {"verdict", "named", "trace"}
    assert diag["named"] and all(set(c) == {"effect", "parameters"} and c["parameters"] for c in diag["named"])
    assert CAUSE_OF[defect["kind"]] in [c["effect"] for c in diag["named"]]
    assert diag["trace"] and all("effect" in t or "rule" in t for t in diag["trace"])
    assert all("diagnosis" not in u for n, u in units.items() if n != name)        # good units: none
    assert sorted(p.name for p in (out / "diagnoses").glob("*.json")) == [f"{name}.json"]
    stored = json.loads((out / "diagnoses" / f"{name}.json").read_text())
    assert stored["status"] == "ok" and stored["diagnosis"] == diag
    assert str(os.getpid()) not in stored["worker"]                                  # diagnosed on a worker
    # the terminal says it in one line a person reads, the same line fleet.png shows
    line = describe_diagnosis(name, stored)
    assert line.startswith(f"{name} flagged: ") and line in done.stdout.splitlines()
    assert "1 flagged unit(s) diagnosed (1 new, 0 reused, 0 failed" in done.stdout
    assert doc["run"]["diagnosed"] == 1 and doc["run"]["diagnosis_seconds"] > 0
    assert (out / "fleet.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_restart_reuses_the_stored_diagnosis(fleet_dir, diagnosed):
    out, first = diagnosed
    assert first.returncode == 0, first.stderr
    stamp = {p.name: p.stat().st_mtime_ns for p in (out / "diagnoses").glob("*.json")}
    before = {u["name"]: u.get("diagnosis") for u in json.loads((out / "fleet.json").read_text())["units"]}
    again = _batch_cli(str(fleet_dir / "unit-*.h5"), "--out", str(out), "--workers", "1", "-q",
                       "--diagnose", str(fleet_dir / "nominal.toml"))
    assert again.returncode == 0, again.stderr
    assert "(0 fitted, 4 reused)" in again.stdout and "(0 new, 1 reused, 0 failed" in again.stdout, again.stdout
    assert {p.name: p.stat().st_mtime_ns for p in (out / "diagnoses").glob("*.json")} == stamp
    after = {u["name"]: u.get("diagnosis") for u in json.loads((out / "fleet.json").read_text())["units"]}
    assert after == before


def _refused(capsys, *args: str) -> str:
    assert batch(list(args)) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def test_a_sim_with_other_points_or_range_is_refused_before_any_fit(fleet_dir, tmp_path, capsys):
    from analysis.inputs import load_input
    from analysis.uff import write_uff58

    inputs = str(fleet_dir / "unit-*.h5")
    out = tmp_path / "out"
    fewer = tmp_path / "fewer_nodes.toml"        # the right column in 3 elements: no node right:4 or right:6
    fewer.write_text("[components.right]\nn_elements = 3\n")
    assert "fewer_nodes.toml" in _refused(capsys, inputs, "--out", str(out), "--diagnose", str(fewer))
    golden = load_input(str(fleet_dir / "unit-002.h5"))
    write_uff58(tmp_path / "two_points.uff", golden.select(outputs=golden.outputs[:2]))
    err = _refused(capsys, inputs, "--out", str(out), "--diagnose", str(tmp_path / "two_points.uff"))
    assert "not the fleet's structure" in err and "points" in err
    write_uff58(tmp_path / "to_1k.uff", golden.band(0.0, 1000.0))
    err = _refused(capsys, inputs, "--out", str(out), "--diagnose", str(tmp_path / "to_1k.uff"))
    assert "not the fleet's structure" in err and "frequency range" in err
    assert _refused(capsys, inputs, "--out", str(out), "--diagnose", str(tmp_path / "none.toml")).endswith(
        "give the fleet's frame config (.toml) or a good unit's recording")
    assert not (out / "fits").exists() and not (out / "diagnoses").exists()          # nothing was done


def test_a_frame_whose_modes_do_not_pair_is_refused_before_any_diagnosis(fleet_dir, diagnosed, tmp_path):
    out, first = diagnosed
    assert first.returncode == 0, first.stderr
    mine = tmp_path / "out"
    mine.mkdir()
    shutil.copytree(out / "fits", mine / "fits")                  # the fits are done: only the SIM is new
    other = tmp_path / "other_frame.toml"                          # taller columns, a thin beam: another frame
    other.write_text("[components.left]\nend_m = [0.0, 0.0, 2.0]\n[components.right]\nend_m = [1.7, 0.0, 2.0]\n"
                     "[sections.beam]\nwidth_m = 0.02\ndepth_m = 0.02\n")
    done = _batch_cli(str(fleet_dir / "unit-*.h5"), "--out", str(mine), "--workers", "1", "-q",
                      "--diagnose", str(other))
    assert done.returncode == 2, done.stdout + done.stderr
    err = done.stderr.strip()
    assert len(err.splitlines()) == 1 and "other_frame.toml is not the fleet's structure: only" in err, err
    assert not (mine / "diagnoses").exists() and not (mine / "fleet.json").exists()


@pytest.mark.parametrize("name, text", [
    ("thick_columns.toml", "[sections.column]\ndepth_m = 0.02\n"),                 # the same nodes, stiffer columns
    ("narrow.toml", "[components.top]\nend_m = [1.2, 0.0, 0.668]\n[components.right]\nstart_m = [1.2, 0.0, 0.0]\n"
                    "end_m = [1.2, 0.0, 0.668]\n"),                                # the same nodes, a shorter span
])
def test_a_sim_with_the_fleets_points_but_other_modes_is_refused_before_the_cluster_or_any_fit(fleet_dir, tmp_path,
                                                                                                capsys, name, text):
    sim = tmp_path / name
    sim.write_text(text)
    out = tmp_path / "out"
    threads = set(threading.enumerate())
    # in this process, as a refusal before any work (a cluster started here would leave its threads: checked)
    err = _refused(capsys, str(fleet_dir / "unit-*.h5"), "--out", str(out), "--workers", "1", "--diagnose", str(sim))
    assert f"{name} is not the fleet's structure: only" in err and "resonances" in err, err
    assert "Dask worker" not in err and not out.exists()           # no cluster started, no fit, nothing written
    assert set(threading.enumerate()) <= threads


def test_the_fleets_own_frame_and_a_units_recording_pass_the_check_before_any_work(fleet_dir):
    from analysis.cli_batch import check_sim_points

    units = sorted(fleet_dir.glob("unit-*.h5"))
    defective = [u for u in units if u.stem in _defective(fleet_dir)]
    for first in (units, defective + units):           # the check compares with the first unit, good or defective
        assert check_sim_points(str(fleet_dir / "nominal.toml"), first, None, None).variants is not None
        assert check_sim_points(str(units[-1]), first, None, None).variants is None      # a recording


def test_the_resonance_check_pairs_a_shifted_unit_and_refuses_another_pattern():
    unit = np.array([13.3, 35.2, 128.1, 160.9, 283.6, 446.1, 525.0, 624.2, 775.0])
    assert peaks_problem(unit, unit * 1.02) is None                         # a material's common shift
    moved = unit.copy()
    moved[[1, 4]] *= (0.95, 1.04)                                           # a defect moves a few modes
    assert peaks_problem(moved, unit) is None
    other = np.array([14.8, 18.8, 27.3, 46.9, 79.7, 88.3, 103.9, 125.8, 157.8, 295.3, 342.2, 443.8, 568.0, 732.0])
    why = peaks_problem(unit, other) or ""
    assert why.startswith("only ") and "within 3 %" in why, why


def test_describe_diagnosis_says_the_named_cause_in_words():
    def doc(*named: dict, verdict: str = "x") -> dict:
        return {"status": "ok", "diagnosis": {"verdict": verdict, "named": list(named), "trace": []}}

    loose = {"effect": "support_stiffness",
             "parameters": {"support": "left:0", "factor_translational": 0.18, "factor_rotational": 0.18}}
    assert describe_diagnosis("unit-012", doc(loose)) == "unit-012 flagged: loose support at left:0, x0.18"
    crack = {"effect": "element_stiffness", "parameters": {"element": "top:3", "factor": 0.41}}
    joints = {"effect": "joint_stiffness", "parameters": {"factor_translational": 0.3, "factor_rotational": 0.05}}
    assert describe_diagnosis("u", doc(crack, joints)) == ("u flagged: cracked element at top:3, x0.41 + soft joints "
                                                           "(all), x0.30 translational, x0.05 rotational")
    mass = {"effect": "added_mass", "parameters": {"point": "left:5", "mass_kg": 2.94}}
    assert describe_diagnosis("u", doc(mass)) == "u flagged: added mass at left:5, 2.9 kg"
    shift = {"effect": "stiffness_shift", "parameters": {"factor": 1.004, "stiffness_factor": 1.0081}}
    assert describe_diagnosis("u", doc(shift)) == "u flagged: stiffer material, x1.008"   # the stiffness's factor
    assert describe_diagnosis("u", doc(verdict="unexplained")) == "u flagged: no cause named (verdict unexplained)"
    assert describe_diagnosis("u", {"status": "error", "error": "FitError: no modes"}) == \
        "u flagged: diagnosis failed (FitError: no modes)"


def test_the_summary_keeps_a_trace_when_the_diagnosis_has_one_else_the_candidates():
    causes = [{"effect": "joint_stiffness", "parameters": {"factor_translational": np.float64(0.3)},
               "gain_db": np.float64(12.6), "significant": np.bool_(True), "adequate": False, "evidence": "long"}]
    base = {"verdict": "joint_stiffness", "named": [{"effect": "joint_stiffness", "parameters": {"f": 1.0}}],
            "causes": causes}
    s = diagnosis_summary(base)
    assert s["trace"] == [{"effect": "joint_stiffness", "parameters": {"factor_translational": 0.3}, "gain_db": 12.6,
                           "significant": True, "adequate": False}]
    json.dumps(s)                                                   # plain JSON, no NumPy scalars
    trace = [{"rule": "adequacy", "cause": "joint_stiffness", "values": {"gain_db": 12.6}, "outcome": "named"}]
    assert diagnosis_summary({**base, "trace": trace})["trace"] == trace


def test_structure_and_modes_checks_name_what_differs():
    outs, refs = ("a:1:X", "b:2:Y"), ("c:3:Z",)
    f = np.linspace(0.0, 800.0, 801)
    assert structure_problem(outs, refs, (0.0, 800.0), outs[::-1], refs, f, 1.0) is None
    assert "points" in (structure_problem(outs, refs, (0.0, 800.0), outs[:1], refs, f, 1.0) or "")
    assert "points" in (structure_problem(outs, refs, (0.0, 800.0), outs, ("a:1:X",), f, 1.0) or "")
    assert "frequency range" in (structure_problem(outs, refs, (0.0, 1000.0), outs, refs, f, 1.0) or "")
    assert structure_problem(outs, refs, (0.0, 1000.0), outs, refs, None, 1.0) is None   # a model: any lines
    ref = UnitModes(freq_hz=np.array([10.0, 30.0, 70.0, 120.0]), damping=np.full(4, 0.01), freq_std_hz=np.zeros(4),
                    damping_std=np.zeros(4), shapes=np.eye(2, 4, dtype=complex), outputs=outs)
    assert modes_problem(ref, ref) is None
    shifted = UnitModes(ref.freq_hz * 1.07, ref.damping, ref.freq_std_hz, ref.damping_std, ref.shapes, outs)
    assert modes_problem(ref, shifted) is None                      # a common shift (material) still pairs
    dense_f = np.geomspace(9.0, 130.0, 24)                          # another structure: far more modes
    dense = UnitModes(dense_f, np.full(24, 0.01), np.zeros(24), np.zeros(24), np.ones((2, 24), complex), outs)
    assert "pair" in (modes_problem(ref, dense) or "")



def test_a_flagged_unit_is_compared_with_the_sim_whose_global_cause_is_the_fleets_scatter(fleet_dir):
    from analysis.batch.scatter import ScatterSimulation
    from analysis.cli_batch import fleet_simulation, shared_simulation
    from analysis.inputs import load_input

    unit = load_input(str(sorted(fleet_dir.glob("unit-*.h5"))[0]))
    toml = str(fleet_dir / "nominal.toml")
    sim = fleet_simulation(toml, unit)
    assert isinstance(sim, ScatterSimulation) and sim.simulation is shared_simulation(toml, unit)
    f0 = sim.modes(None, {}, 2000.0)[0][:8]
    # every frequency by the square root of the factor: the springs scaled with the members
    np.testing.assert_allclose(sim.modes("stiffness_shift", {"stiffness_factor": 1.02}, 2000.0)[0][:8] / f0,
                               np.sqrt(1.02), rtol=1e-6)
    # the FE model's own modulus leaves the springs: its modes move unevenly
    ratio = sim.simulation.modes("stiffness_shift", {"stiffness_factor": 1.02}, 2000.0)[0][:8] / f0
    assert float(np.ptp(ratio)) > 3e-4
