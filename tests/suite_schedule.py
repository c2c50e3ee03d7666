"""How long ``make test`` would take on an idle machine with N processes, from a run measured on a loaded one.

Reads the files that ``-p cpu_per_test --cpu-per-test FILE`` wrote (``FILE.gw0``, ``FILE.gw1``, ...) and replays the
suite the way ``--dist loadfile`` with ``tests/conftest.py``'s SPREAD and HEAVY hands it out: each test is its CPU
seconds (own + waited-for children; the cores shared by the processes that compute, at most one each) followed by
its wait (the seconds its thread was blocked beyond its children's work at the measured load: a server or browser
starting, a timeout the test provokes). Run from the repository root::

    python tests/suite_schedule.py cpu.tsv            # cores 2, processes 2, 3 and 4

A model, not a measurement: CPU that no test waited for (a browser, a killed Dask worker) counts as a wait, and a
child that lives across tests (a module's server) is counted at the test that ends it. Only the speed depends on it.
"""
from __future__ import annotations

import argparse
import glob
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from conftest import HEAVY, SPREAD, _file, _rank  # noqa: E402


def read(prefix: str) -> list[list[str]]:
    """The rows of every process's file of one run."""
    rows = []
    for path in sorted(glob.glob(prefix + ".gw*")) or [prefix]:
        rows += [line.rstrip("\n").split("\t") for line in open(path, encoding="utf-8")]
    return rows


def units_of(rows: list[list[str]]) -> list[list[tuple[float, float]]]:
    """The units of work in the order they are handed out, each a list of (CPU s, wait s) per test."""
    load = _load(rows)
    cost = {r[0]: (float(r[1]) + float(r[2]), max(0.0, float(r[5]) - float(r[2]) * load)) for r in rows}
    units: dict[str, list[tuple[float, float]]] = {}
    for nodeid in sorted(cost, key=lambda n: (_rank(n), n.split("::")[0])):
        units.setdefault(nodeid if _file(nodeid) in SPREAD else nodeid.split("::")[0], []).append(cost[nodeid])
    return list(units.values())


def _load(rows: list[list[str]]) -> float:
    """How many times its CPU time a test's thread took in wall time while it could run (1: an idle machine)."""
    queued = sum(float(r[4]) for r in rows)
    ran = sum(float(r[3]) - float(r[4]) - float(r[5]) for r in rows)
    return 1.0 + queued / max(ran, 1e-9)


def wall(units: list[list[tuple[float, float]]], processes: int, cores: float = 2.0) -> float:
    """Seconds until the last unit ends: the processes take the next unit when free; those computing share the cores."""
    queue = list(units)
    work: list[list[list[float]]] = [[] for _ in range(processes)]
    t = 0.0
    while True:
        for todo in work:
            while todo and todo[0][0] <= 1e-12 and todo[0][1] <= 1e-12:
                todo.pop(0)
            while not todo and queue:
                todo.extend([c, w] for c, w in queue.pop(0))
        if not any(work):
            return t
        computing = sum(1 for todo in work if todo and todo[0][0] > 1e-12)
        rate = min(1.0, cores / computing) if computing else 0.0
        step = min(todo[0][0] / rate if todo[0][0] > 1e-12 else todo[0][1] for todo in work if todo)
        for todo in work:
            if todo:
                if todo[0][0] > 1e-12:
                    todo[0][0] -= rate * step
                else:
                    todo[0][1] -= step
        t += step


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("prefix", help="the --cpu-per-test FILE of a run")
    parser.add_argument("--cores", type=float, default=2.0)
    parser.add_argument("--processes", default="2,3,4", help="comma-separated process counts")
    args = parser.parse_args(argv)
    rows = read(args.prefix)
    if not rows or len(rows[0]) < 6:
        print(f"{args.prefix}: no rows with the wait columns (a run with -p cpu_per_test)", file=sys.stderr)
        return 2
    units = units_of(rows)
    cpu = sum(c for u in units for c, _ in u)
    waits = sum(w for u in units for _, w in u)
    print(f"{len(rows)} tests in {len(units)} units (HEAVY: {len(HEAVY)} files); CPU {cpu:.0f} s, waits {waits:.0f} s "
          f"(measured at {_load(rows):.1f}x load)")
    for n in (int(x) for x in args.processes.split(",")):
        print(f"  {n} processes on {args.cores:g} cores: {wall(units, n, args.cores):.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
