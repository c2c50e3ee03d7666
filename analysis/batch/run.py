"""Run a batch of fits on Dask (``dask.distributed``) and keep exactly one result per input.

- **Cluster.** :func:`open_client` gives a client of a ``LocalCluster`` of worker processes (one per
  core, one thread each) by default, or of a running cluster by address (``tcp://HOST:PORT``) or
  scheduler file (the JSON that ``dask scheduler --scheduler-file F`` writes). The scheduling,
  the retries of tasks whose worker died and the placement are Dask's.
- **Exactly one result.** Each input is one task keyed by its name and content hash. Results come
  back to this process, which writes ``fits/<name>.json`` atomically as each arrives: a task run
  twice (its worker died after finishing) writes the same file again, so no result is doubled, and
  one that dies with its worker is run again elsewhere by Dask.
- **Restartable.** Before submitting, an input whose ``fits/<name>.json`` holds a result for the same
  content (SHA-256) and options is not fitted again. A crash (of this process, of a worker, of the
  machine) loses at most the fits in flight.
"""
from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..atomic import write_json_atomic
from .task import file_sha256, fit_one, options_key, result_is_current

__all__ = ["BatchInput", "BatchRun", "DASK_CONFIG_DIR", "HEARTBEAT_FAILED", "close_client", "dask_settings",
           "open_client", "plan_inputs", "quiet_heartbeat", "run_batch", "run_serial", "run_tasks", "Task"]

#: Dask settings for the workers (a YAML folder; for ``dask worker``: ``export DASK_CONFIG=<this folder>``)
DASK_CONFIG_DIR = Path(__file__).with_name("dask-config")


def dask_settings() -> dict[str, Any]:
    """The settings of :data:`DASK_CONFIG_DIR` as dotted keys (for ``dask.config.set``, which would
    replace a whole subtree given as a nested dictionary)."""
    import dask.config

    flat: dict[str, Any] = {}

    def walk(prefix: str, d: Any) -> None:
        if isinstance(d, dict) and d:
            for k, v in d.items():
                walk(f"{prefix}.{k}" if prefix else str(k), v)
        else:
            flat[prefix] = d

    walk("", dask.config.collect(paths=[str(DASK_CONFIG_DIR)], env={}))
    return flat


@dataclass(frozen=True)
class BatchInput:
    """One input: its path, its unique result name (file name without suffix, made unique), content hash."""

    path: Path
    name: str
    sha256: str

    @property
    def result_file(self) -> str:
        return f"{self.name}.json"


@dataclass
class BatchRun:
    """What a run did: every input's result document in input order, and the counts and times."""

    results: list[dict[str, Any]]
    reused: int = 0
    fitted: int = 0
    failed: int = 0
    seconds: float = 0.0
    fit_seconds: float = 0.0                  # the sum of the fits' own wall times (work done)
    fit_cpu_seconds: float = 0.0              # the sum of the fits' CPU times (s)
    workers: int = 0
    where: str = ""
    lost: list[str] = field(default_factory=list)   # inputs whose task Dask gave up on (no result file)


def plan_inputs(paths: Sequence[str | Path]) -> list[BatchInput]:
    """The inputs, sorted by path, with unique names (``unit-007``; a clash gets its folder's name:
    ``lineB-unit-007``) and their SHA-256 (an unreadable input gets the hash of its path's text, so
    it still gets its error row)."""
    import hashlib

    ps = sorted({Path(p).resolve() for p in paths})
    stems: dict[str, int] = {}
    for p in ps:
        stems[p.stem] = stems.get(p.stem, 0) + 1
    out = []
    used: set[str] = set()
    for p in ps:
        name = p.stem if stems[p.stem] == 1 else f"{p.parent.name}-{p.stem}"
        base, n = name, 2
        while name in used:
            name, n = f"{base}-{n}", n + 1
        used.add(name)
        try:
            sha = file_sha256(p)
        except OSError:
            sha = "unreadable-" + hashlib.sha256(str(p).encode()).hexdigest()
        out.append(BatchInput(p, name, sha))
    return out


def open_client(scheduler: str | None = None, workers: int | None = None,
                dashboard: str | None = None) -> Any:
    """A ``distributed.Client``: of the cluster at ``scheduler`` (``tcp://HOST:PORT`` or a scheduler
    file), else of a new ``LocalCluster`` with ``workers`` processes (default: one per core) of one
    thread each, with Dask's dashboard at ``dashboard`` (``HOST:PORT``) only when given (otherwise
    the scheduler's HTTP endpoint takes a free loopback port, so batches never compete for 8787).
    The caller closes it (``client.close()``, and ``client.cluster.close()`` for a local one)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ImportError("batch analysis needs Dask: pip install 'impactlab[batch]' "
                          "(dask[distributed] and pyarrow)") from None
    if scheduler:
        if "://" not in scheduler and Path(scheduler).is_file():
            return Client(scheduler_file=scheduler, timeout="20s")
        return Client(scheduler, timeout="20s")
    import dask.config

    n = workers or os.cpu_count() or 1
    with dask.config.set(dask_settings()):
        if dashboard:
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=dashboard)
        else:
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                                   scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})
    return Client(cluster)


#: the message of a worker whose heartbeat the cluster's teardown cut off (logged with a traceback)
HEARTBEAT_FAILED = "Failed to communicate with scheduler during heartbeat."


class _NoTeardownHeartbeat(logging.Filter):
    """Drops the heartbeat failure of a worker whose cluster is being closed (nothing failed)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.msg != HEARTBEAT_FAILED


def quiet_heartbeat(dask_worker: Any) -> bool:
    """On a worker of a local cluster about to close: stop its heartbeat to the scheduler, and keep a
    heartbeat already under way (cut off when the scheduler stops) out of the log. True when done."""
    beat = dask_worker.periodic_callbacks.get("heartbeat")
    if beat is not None:
        beat.stop()
    log = logging.getLogger("distributed.worker")
    if not any(isinstance(f, _NoTeardownHeartbeat) for f in log.filters):
        log.addFilter(_NoTeardownHeartbeat())
    return beat is None or not beat.is_running()


def close_client(client: Any) -> None:
    """Close ``client`` and, when it opened a local cluster, that cluster: the workers' heartbeats are
    stopped first (a heartbeat cut off by the teardown would print a traceback after a good run), then
    the client is closed before the cluster (the client would otherwise try to reconnect to a
    scheduler that is going away). A cluster given by ``--scheduler`` is left running as it was."""
    cluster = getattr(client, "cluster", None)
    try:
        if cluster is not None:
            try:
                client.run(quiet_heartbeat, on_error="ignore")
            except (OSError, TimeoutError):  # a worker already gone: nothing of it to quieten
                pass
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _reuse(inputs: Sequence[BatchInput], fits_dir: Path, key: str) -> dict[str, dict[str, Any]]:
    done = {}
    for inp in inputs:
        doc = result_is_current(fits_dir / inp.result_file, inp.sha256, key)
        if doc is not None:
            done[inp.name] = doc
    return done


#: one task of :func:`run_tasks`: (result name, Dask key, the function a worker runs, its arguments)
Task = tuple[str, str, Callable[..., dict[str, Any]], tuple[Any, ...]]


def run_tasks(client: Any, tasks: Sequence[Task], store: Callable[[str, dict[str, Any]], None],
              lost: Callable[[str, BaseException], dict[str, Any]],
              on_result: Callable[[dict[str, Any], int, int], None] | None = None
              ) -> tuple[dict[str, dict[str, Any]], list[str]]:
    """Run ``tasks`` on the Dask ``client``'s cluster and collect their result documents as they
    finish: each is handed to ``store(name, doc)`` (which puts it on disk) before ``on_result(doc,
    done, total)``. A task Dask gave up on (its workers kept dying) is not stored: its document is
    ``lost(name, exception)`` and its name is in the returned list (the next run retries it).
    Returns ``({name: doc}, lost names)``."""
    from distributed import as_completed

    futures = {client.submit(fn, *args, key=key, pure=False): name for name, key, fn, args in tasks}
    got: dict[str, dict[str, Any]] = {}
    gone: list[str] = []
    for done, fut in enumerate(as_completed(list(futures)), start=1):
        name = futures[fut]
        try:
            doc = fut.result()
        except Exception as exc:   # Dask gave up on the task: no result file, retried next run
            doc = lost(name, exc)
            gone.append(name)
        else:
            store(name, doc)
        got[name] = doc
        if on_result is not None:
            on_result(doc, done, len(futures))
    return got, gone


def run_batch(inputs: Sequence[BatchInput], out_dir: str | Path, client: Any, *,
              band: Sequence[float] | None = None, estimator: str | None = None,
              on_result: Callable[[dict[str, Any], int, int], None] | None = None) -> BatchRun:
    """Fit every input on the Dask ``client``'s cluster; results in ``out_dir/fits/``.

    ``on_result(doc, done, total)`` is called after each new result is on disk (progress)."""
    t0 = time.perf_counter()
    fits_dir = Path(out_dir) / "fits"
    fits_dir.mkdir(parents=True, exist_ok=True)
    key = options_key(band, estimator)
    have = _reuse(inputs, fits_dir, key)
    todo = [i for i in inputs if i.name not in have]
    run = BatchRun(results=[], reused=len(have), workers=len(client.scheduler_info().get("workers", {})),
                   where=str(client.scheduler.address))
    jobs = [(inp.name, f"impactlab-fit-{inp.name}-{inp.sha256[:12]}-{key}", fit_one,
             (str(inp.path), inp.name, inp.sha256, band, estimator)) for inp in todo]
    by_name = {inp.name: inp for inp in todo}

    def lost(name: str, exc: BaseException) -> dict[str, Any]:
        inp = by_name[name]
        return {"schema": "impactlab.batch-fit/1", "input": inp.name, "path": str(inp.path), "sha256": inp.sha256,
                "status": "error", "error": f"the task failed on the cluster ({type(exc).__name__}: {exc}); "
                                            "run the same command again to retry it", "fit": None, "seconds": 0.0}

    got: dict[str, dict[str, Any]] = dict(have)
    new_docs, run.lost = run_tasks(client, jobs, lambda name, doc: write_json_atomic(fits_dir / by_name[name].result_file,
                                                                                    doc), lost, on_result)
    got.update(new_docs)
    run.results = [got[i.name] for i in inputs]
    run.fitted = len(todo) - len(run.lost)
    run.failed = sum(d.get("status") != "ok" for d in run.results)
    run.fit_seconds = float(sum(float(got[i.name].get("seconds") or 0.0) for i in todo))
    run.fit_cpu_seconds = float(sum(float(got[i.name].get("cpu_seconds") or 0.0) for i in todo))
    run.seconds = time.perf_counter() - t0
    return run


def run_serial(inputs: Sequence[BatchInput], out_dir: str | Path, *, band: Sequence[float] | None = None,
               estimator: str | None = None) -> BatchRun:
    """The same work in a plain loop in this process (no Dask): the baseline of the benchmark."""
    t0 = time.perf_counter()
    fits_dir = Path(out_dir) / "fits"
    fits_dir.mkdir(parents=True, exist_ok=True)
    results = []
    for inp in inputs:
        doc = fit_one(str(inp.path), inp.name, inp.sha256, band, estimator)
        write_json_atomic(fits_dir / inp.result_file, doc)
        results.append(doc)
    run = BatchRun(results=results, fitted=len(results), workers=1, where="serial loop")
    run.failed = sum(d.get("status") != "ok" for d in results)
    run.fit_seconds = float(sum(float(d.get("seconds") or 0.0) for d in results))
    run.seconds = time.perf_counter() - t0
    return run
