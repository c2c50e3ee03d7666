"""Throughput of ``analysis batch``: a serial loop vs a Dask LocalCluster of 1 and 2 workers.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/speed/bench_batch.py [--units 200] [--fleet DIR]

Makes a fleet with ``simulator fleet`` (timed: the fleet command's own throughput), then fits every
unit four ways (a serial loop, a plain pool of 2 processes as the machine's ceiling, Dask with 1
and 2 workers) and prints a table: wall time, units per second, speed-up over the serial loop,
the scheduling overhead (wall x workers - the fits' own summed time) / the fits' summed time,
with the workers set up as ``analysis batch`` sets them (:func:`analysis.batch.run.dask_settings`),
and the peak resident memory of each worker process (ru_maxrss). Every run starts from an empty
results folder (no reuse). Run by hand on an otherwise idle machine; nothing here is a test.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/speed/bench_batch.py --diagnose [--units 12] [--fleet DIR]

times what ``--diagnose`` adds instead: the fleet (by default 12 units, 3 defective) goes through
``python -m analysis batch 'DIR/unit-*.h5' --out OUT --workers 2 --diagnose nominal.toml`` as a user
runs it, once without and once with ``--diagnose`` (each into an empty folder), and the table gives the
fits' own time per unit and the diagnoses' own time per flagged unit (wall and CPU seconds of the work,
from fleet.json's ``run``), and the two batches' wall times.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository, for benchmarks.results
from benchmarks.results import add_write_option, recorded  # noqa: E402

#: this benchmark's results file (``--write`` replaces it with the run's figures)
RESULTS = Path(__file__).with_name("bench_batch.md")

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "error")


def _peak_rss_mb(_: object = None) -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=200)
    ap.add_argument("--fleet", help="an existing fleet folder (default: make one in a temporary folder)")
    ap.add_argument("--diagnose", action="store_true",
                    help="time what 'analysis batch --diagnose' adds per flagged unit (default fleet: 12 units)")
    add_write_option(ap, RESULTS)
    args = ap.parse_args()
    with recorded(RESULTS, args.write):
        if args.diagnose:
            diagnose_timing(args.units if args.units != ap.get_default("units") else 12, args.fleet)
        else:
            _run(args)


def _run(args: argparse.Namespace) -> None:
    """The run itself (what :func:`main` records with ``--write``)."""

    import dask.config
    from distributed import Client, LocalCluster

    from analysis.batch.run import dask_settings, plan_inputs, run_batch, run_serial

    with tempfile.TemporaryDirectory() as tmp:
        fleet = Path(args.fleet) if args.fleet else Path(tmp) / "fleet"
        t0 = time.perf_counter()
        if not args.fleet:
            subprocess.run([sys.executable, "-m", "simulator", "fleet", "--units", str(args.units), "--defects",
                            str(max(1, args.units // 20)), "--out", str(fleet), "--seed", "3", "-q"], check=True)
        t_fleet = time.perf_counter() - t0
        inputs = plan_inputs(sorted(fleet.glob("*.h5"))[: args.units])
        rows = []
        serial = run_serial(inputs, Path(tmp) / "serial")
        rows.append(("serial loop", 1, serial.seconds, serial.fit_seconds, _peak_rss_mb()))
        # the machine's own ceiling: the same fits in a plain pool of 2 processes, no scheduler at all
        import concurrent.futures

        from analysis.batch.task import fit_one

        t0 = time.perf_counter()
        with concurrent.futures.ProcessPoolExecutor(2) as pool:
            docs = list(pool.map(fit_one, [str(i.path) for i in inputs], [i.name for i in inputs],
                                 [i.sha256 for i in inputs], chunksize=4))
            peak = max(pool.map(_peak_rss_mb, range(2)))   # type: ignore[arg-type]
        rows.append(("process pool, 2 processes (no Dask)", 2, time.perf_counter() - t0,
                     float(sum(d["seconds"] for d in docs)), peak))
        for n in (1, 2):
            with dask.config.set(dask_settings()), \
                    LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
                    Client(cluster) as client:
                t0 = time.perf_counter()
                run = run_batch(inputs, Path(tmp) / f"dask{n}", client)
                wall = time.perf_counter() - t0
                peaks = client.run(_peak_rss_mb)
            rows.append((f"Dask LocalCluster, {n} worker{'s' if n > 1 else ''}", n, wall, run.fit_seconds,
                         max(peaks.values())))
    print(f"fleet of {len(inputs)} units made by 'simulator fleet' in {t_fleet:.1f} s "
          f"({len(inputs) / max(t_fleet, 1e-9):.1f} units/s on {os.cpu_count()} cores)" if not args.fleet else
          f"fleet {fleet}: {len(inputs)} units")
    print("\n| run | workers | wall (s) | units/s | speed-up vs serial | fit time (s, summed) | overhead | "
          "peak memory per process (MB) |")
    print("|---|---|---|---|---|---|---|---|")
    base = rows[0][2]
    for name, n, wall, fit_s, mem in rows:
        overhead = (wall * n - fit_s) / fit_s
        print(f"| {name} | {n} | {wall:.1f} | {len(inputs) / wall:.2f} | {base / wall:.2f}x | {fit_s:.1f} | "
              f"{100 * overhead:.1f} % | {mem:.0f} |")
    per_fit = rows[0][3] / len(inputs)
    print(f"\nmean fit time per unit (serial loop): {per_fit:.3f} s; cluster start-up is inside the Dask wall times")


def diagnose_timing(units: int, fleet_dir: str | None) -> None:
    """The fits' own time per unit against the diagnoses' own time per flagged unit (module docs)."""
    import json

    with tempfile.TemporaryDirectory() as tmp:
        fleet = Path(fleet_dir) if fleet_dir else Path(tmp) / "fleet"
        if not fleet_dir:
            subprocess.run([sys.executable, "-m", "simulator", "fleet", "--units", str(units), "--defects",
                            str(max(1, units // 4)), "--out", str(fleet), "--seed", "3", "-q"], check=True)
        sim = Path(tmp) / "nominal.toml"
        sim.write_text("# the frame as designed: simulator/frame.toml's defaults\n")
        runs = {}
        for name, extra in (("fits only", []), ("fits + --diagnose", ["--diagnose", str(sim)])):
            out = Path(tmp) / name.replace(" ", "_")
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "analysis", "batch", str(fleet / "unit-*.h5"), "--out", str(out),
                            "--workers", "2", "-q", *extra], check=True, capture_output=True)
            runs[name] = (time.perf_counter() - t0, json.loads((out / "fleet.json").read_text())["run"])
    info = runs["fits + --diagnose"][1]
    n, k = int(info["fitted"]), int(info.get("diagnosed", 0))
    print(f"fleet {fleet_dir or f'of {units} units (simulator fleet --seed 3)'}: {n} units fitted, {k} flagged and diagnosed")
    print("\n| batch | wall (s) | fits: work per unit (s) | fits: CPU per unit (s) | diagnoses: work per flagged "
          "unit (s) | diagnoses: CPU per flagged unit (s) |")
    print("|---|---|---|---|---|---|")
    for name, (wall, r) in runs.items():
        d = int(r.get("diagnosed", 0))
        diag = (f"{r['diagnosis_seconds'] / d:.1f} | {r['diagnosis_cpu_seconds'] / d:.1f}" if d else "- | -")
        print(f"| {name} | {wall:.1f} | {r['fit_seconds'] / n:.2f} | {r['fit_cpu_seconds'] / n:.2f} | {diag} |")
    if k:
        print(f"\nper flagged unit the diagnosis adds {info['diagnosis_seconds'] / k:.1f} s of work "
              f"({info['diagnosis_seconds'] / k / (info['fit_seconds'] / n):.1f} x one unit's fit, "
              f"{info['diagnosis_seconds'] / k / info['fit_seconds']:.2f} x the whole fleet's fits); wall time of the "
              f"batch {runs['fits + --diagnose'][0] - runs['fits only'][0]:+.1f} s with --diagnose on 2 workers")


if __name__ == "__main__":
    main()
