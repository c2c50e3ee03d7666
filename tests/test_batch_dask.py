"""Batch analysis on Dask's own scheduler and workers: a LocalCluster of 2 processes, a worker
killed mid-run, ``dask scheduler`` / ``dask worker`` started as separate processes, a corrupt
input, restarts by content hash. The fleet is made by ``simulator fleet`` (FE frames with scatter
and a physical defect, captured through the simulated analyser).

Dask runs in child processes only (the commands, tests/dask_kill_driver.py): a process that has used
a Dask client keeps its threads, and the rest of the session forks child processes for isolated
readers (analysis._isolated), which it only does from a single-threaded process."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("distributed")
pq = pytest.importorskip("pyarrow.parquet")

from analysis.cli_batch import main as batch  # noqa: E402
from simulator.cli_fleet import main as fleet  # noqa: E402

ENV = {**{k: v for k, v in os.environ.items() if k != "MALLOC_TRIM_THRESHOLD_"}, "DASK_LOGGING__DISTRIBUTED": "error"}


def _batch_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "analysis", "batch", *args], capture_output=True, text=True,
                          timeout=240, env=ENV)

N_UNITS = 8


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("fleet")
    assert fleet(["--units", str(N_UNITS), "--defects", "1", "--out", str(out), "--seed", "11", "--jobs", "1",
                  "-q"]) == 0
    return out


def _inputs(fleet_dir: Path, tmp: Path, corrupt: bool = False) -> list[str]:
    """Copies of the fleet's recordings in ``tmp`` (tests change them), plus a corrupt one."""
    src = tmp / "in"
    src.mkdir()
    for f in sorted(fleet_dir.glob("unit-*.h5")):
        shutil.copy(f, src / f.name)
    if corrupt:
        good = (src / "unit-001.h5").read_bytes()
        (src / "broken.h5").write_bytes(good[: len(good) // 3])      # a transfer cut short
    return sorted(str(p) for p in src.glob("*.h5"))


def _truth(fleet_dir: Path) -> dict:
    return {u["name"]: u["defect"] for u in json.loads((fleet_dir / "truth.json").read_text())["units"]}


def test_fleet_command_writes_recordings_and_truth(fleet_dir, capsys):
    truth = json.loads((fleet_dir / "truth.json").read_text())
    assert [u["name"] for u in truth["units"]] == [f"unit-{i:03d}" for i in range(1, N_UNITS + 1)]
    assert all((fleet_dir / u["file"]).is_file() for u in truth["units"])
    bad = [u for u in truth["units"] if u["defect"]]
    assert len(bad) == 1 and bad[0]["defect"]["kind"] in ("soft_joint", "cracked_member", "loose_support")
    assert not list(fleet_dir.glob(".*.part"))                       # nothing half-written left behind
    # the same command again captures nothing: every unit is already on disk
    assert fleet(["--units", str(N_UNITS), "--defects", "1", "--out", str(fleet_dir), "--seed", "11", "--jobs", "1"]) == 0
    assert f"{N_UNITS} of {N_UNITS} units already on disk" in capsys.readouterr().err


def test_local_cluster_batch_with_a_corrupt_input_then_restart(fleet_dir, tmp_path):
    inputs = _inputs(fleet_dir, tmp_path, corrupt=True)
    out = tmp_path / "out"
    done = _batch_cli(*inputs, "--out", str(out), "--workers", "2", "-q")
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr and "heartbeat" not in done.stderr, done.stderr  # a clean teardown
    text = done.stdout
    assert f"batch of {N_UNITS + 1}: {N_UNITS} done ({N_UNITS + 1} fitted, 0 reused), 1 failed" in text
    fits = sorted(p.name for p in (out / "fits").glob("*.json"))
    assert fits == sorted(f"{Path(p).stem}.json" for p in inputs)        # exactly one result per input
    broken = json.loads((out / "fits" / "broken.json").read_text())
    assert broken["status"] == "error" and "broken.h5" in broken["error"]
    table = pq.read_table(out / "modes.parquet").to_pylist()
    assert {r["input"] for r in table} == {Path(p).name for p in inputs}
    err = [r for r in table if r["input"] == "broken.h5"]
    assert len(err) == 1 and err[0]["status"] == "error" and err[0]["error"]
    good = [r for r in table if r["status"] == "ok"]
    assert all(r["f_hz"] > 0 and r["zeta"] > 0 for r in good)
    assert sum(r["ref_mode"] > 0 and r["mac"] > 0.9 for r in good) > 0.8 * len(good)
    doc = json.loads((out / "fleet.json").read_text())
    flagged = {u["name"] for u in doc["units"] if u["flagged"]}
    truth = _truth(fleet_dir)
    assert flagged == {n for n, d in truth.items() if d}                 # the defective unit, and only it
    assert all(u["reasons"] for u in doc["units"] if u["flagged"])
    assert {u["name"]: u["status"] for u in doc["units"]}["broken"] == "error"
    assert doc["modes"] and all(m["ref_freq_hz"] > 0 for m in doc["modes"])
    assert (out / "fleet.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    stamp = {p.name: p.stat().st_mtime_ns for p in (out / "fits").glob("*.json")}

    # again with one input's content changed: only it is fitted again, every other result (the failed one too)
    # is reused and left untouched (a run with nothing changed, "0 fitted, all reused", is
    # tests/test_batch_diagnose.py::test_a_restart_reuses_the_stored_diagnosis)
    shutil.copy(inputs[1], inputs[0])
    changed_run = _batch_cli(*inputs, "--out", str(out), "--workers", "1", "-q")
    assert changed_run.returncode == 0 and f"(1 fitted, {N_UNITS} reused)" in changed_run.stdout, changed_run.stderr
    changed = {p.name for p in (out / "fits").glob("*.json") if p.stat().st_mtime_ns != stamp[p.name]}
    assert changed == {f"{Path(inputs[0]).stem}.json"}
    assert not list((out / "fits").glob(".*.part")) and not list(out.glob(".*.part"))


_TEARDOWN = """
import logging, sys
from analysis.batch.run import HEARTBEAT_FAILED, close_client, open_client, quiet_heartbeat
client = open_client(workers=2)
first = client.run(lambda dask_worker: dask_worker.periodic_callbacks["heartbeat"].is_running())
quiet = client.run(quiet_heartbeat)
after = client.run(lambda dask_worker: dask_worker.periodic_callbacks["heartbeat"].is_running())
def cut_heartbeat_logged():  # the record a heartbeat cut off by the teardown makes on a worker
    log = logging.getLogger("distributed.worker")
    return all(f.filter(logging.makeLogRecord({"msg": HEARTBEAT_FAILED})) for f in log.filters)
shown = client.run(cut_heartbeat_logged)
close_client(client)
print(sorted(first.values()), sorted(quiet.values()), sorted(after.values()), sorted(shown.values()))
"""


def test_the_local_cluster_closes_without_a_heartbeat_traceback():
    """The workers' heartbeats stop before the cluster closes, and a heartbeat cut off by the teardown is
    not logged: the stderr of a good run stays clean (the race shows only now and then)."""
    done = subprocess.run([sys.executable, "-c", _TEARDOWN], capture_output=True, text=True, timeout=240, env=ENV)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("\n")[0] == "[True, True] [True, True] [False, False] [False, False]", done.stdout
    assert "Traceback" not in done.stderr and "heartbeat" not in done.stderr, done.stderr


def test_worker_killed_mid_batch_loses_and_doubles_nothing(fleet_dir, tmp_path):
    inputs = _inputs(fleet_dir, tmp_path)
    out = tmp_path / "out"
    driver = Path(__file__).with_name("dask_kill_driver.py")
    done = subprocess.run([sys.executable, str(driver), str(out), *inputs], capture_output=True, text=True,
                          timeout=240, env=ENV)
    assert done.returncode == 0, done.stderr
    rep = json.loads(done.stdout.strip().splitlines()[-1])
    assert rep["killed"] and not rep["alive_after"]                   # that worker is really gone
    assert [r[0] for r in rep["results"]] == rep["names"]
    assert all(r[1] == "ok" for r in rep["results"]) and not rep["lost"]
    assert sorted(p.name for p in (out / "fits").glob("*.json")) == sorted(rep["result_files"])
    assert len({r[2] for r in rep["results"]}) >= 2                   # the work went on elsewhere


def _wait_for(path: Path, proc: subprocess.Popen, what: str) -> None:
    for _ in range(600):
        if path.exists() and path.stat().st_size > 0:
            return
        if proc.poll() is not None:
            raise AssertionError(f"{what} ended early: {proc.stderr.read() if proc.stderr else ''}")
        time.sleep(0.1)
    raise AssertionError(f"{what} did not start")


def test_dask_scheduler_and_worker_processes_through_scheduler_option(fleet_dir, tmp_path):
    dask = Path(sys.executable).with_name("dask")
    if not dask.exists():
        pytest.skip("the 'dask' command is not installed beside this Python")
    inputs = _inputs(fleet_dir, tmp_path)[:3]
    sfile = tmp_path / "scheduler.json"
    from analysis.batch.run import DASK_CONFIG_DIR

    env = {**ENV, "DASK_CONFIG": str(DASK_CONFIG_DIR)}                # a shell as docs/batch.md says
    sched = subprocess.Popen([str(dask), "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                              "--scheduler-file", str(sfile)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                             text=True, env=env)
    worker = None
    try:
        _wait_for(sfile, sched, "dask scheduler")
        address = json.loads(sfile.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        worker = subprocess.Popen([str(dask), "worker", address, "--nworkers", "1", "--nthreads", "1",
                                   "--no-dashboard", "--name", "stand-1"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
        probe = ("import os, json; from distributed import Client\n"
                 f"c = Client({address!r}, timeout='30s'); c.wait_for_workers(1, timeout=60)\n"
                 "print(json.dumps(list(c.run(lambda: os.environ.get('MALLOC_TRIM_THRESHOLD_')).values()))); c.close()")
        seen = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, env=ENV)
        # the worker is up and took impactlab's Dask settings (docs/batch.md): glibc's adaptive malloc kept
        assert seen.returncode == 0 and json.loads(seen.stdout.strip().splitlines()[-1]) == [None], seen.stderr
        out = tmp_path / "out"
        done = _batch_cli(*inputs, "--out", str(out), "--scheduler", address, "-q")
        assert done.returncode == 0, done.stderr
        assert "3 done (3 fitted, 0 reused), 0 failed" in done.stdout
        run = json.loads((out / "fleet.json").read_text())["run"]
        assert run["scheduler"] == address and run["workers"] == 1
        workers = {json.loads(p.read_text())["worker"] for p in (out / "fits").glob("*.json")}
        assert len(workers) == 1 and str(os.getpid()) not in next(iter(workers))   # fitted in the worker process
    finally:
        for p in (worker, sched):
            if p is not None:
                p.terminate()
                try:
                    p.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
                if p.stderr is not None:
                    p.stderr.close()


def test_batch_usage_errors(tmp_path, capsys):
    assert batch([str(tmp_path / "none-*.h5"), "--out", str(tmp_path / "o")]) == 2
    assert "no input matches" in capsys.readouterr().err
    assert batch([str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert "is a folder" in capsys.readouterr().err
    (tmp_path / "a.h5").write_bytes(b"x")
    assert batch([str(tmp_path / "a.h5"), "--out", str(tmp_path / "o"), "--reference", str(tmp_path / "no.json")]) == 2
    assert "reference fit" in capsys.readouterr().err
    assert batch([str(tmp_path / "a.h5"), "--out", str(tmp_path / "o"), "--band", "9"]) == 2
