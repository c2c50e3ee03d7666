"""Run by tests/test_batch_dask.py in a child process (Dask leaves threads behind in the process that
used it, which would make the rest of the test session fork-unsafe): a batch on a LocalCluster of
2 workers, one busy worker killed with SIGKILL at the first result. Prints one JSON line:
{"killed": pid, "alive_after": bool, "results": [[input, status, worker], ...], "lost": [...]}.

    python tests/dask_kill_driver.py OUT_DIR INPUT...
"""
from __future__ import annotations

import json
import os
import signal
import sys


def main(out_dir: str, paths: list[str]) -> None:
    import dask.config
    from distributed import Client, LocalCluster

    from analysis.batch.run import dask_settings, plan_inputs, run_batch

    inputs = plan_inputs(paths)
    killed: list[int] = []
    with dask.config.set(dask_settings()), \
            LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        def kill_a_busy_worker(doc, done, total):
            if killed:
                return
            busy = [w for w, keys in client.processing().items() if keys]
            if not busy:
                raise SystemExit("no task in flight to kill")
            pid = client.run(os.getpid, workers=[busy[0]])[busy[0]]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

        run = run_batch(inputs, out_dir, client, on_result=kill_a_busy_worker)
    try:
        os.kill(killed[0], 0)
        alive = True
    except ProcessLookupError:
        alive = False
    print(json.dumps({"killed": killed[0] if killed else None, "alive_after": alive,
                      "names": [i.name for i in inputs], "result_files": [i.result_file for i in inputs],
                      "results": [[r["input"], r["status"], r.get("worker")] for r in run.results], "lost": run.lost}))


if __name__ == "__main__":
    os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "error")
    main(sys.argv[1], sys.argv[2:])
