"""What a fleet's flagged unit costs to diagnose, against what a unit costs to fit.

Run by hand (not a test; on 2 cores a few minutes)::

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/speed/bench_fleet_diagnose.py [--units 12]
        [--defects 4] [--seed 159536] [--fleet DIR]

A fleet of ``simulator fleet`` (by default 12 units, 4 defective, 2 % scatter) is fitted unit by unit as a
batch worker fits it (:func:`analysis.batch.task.fit_one`), flagged (:func:`analysis.batch.fleet.assess_fleet`),
and each flagged unit is diagnosed against the frame as designed, in this one process, one unit after the
other as a worker takes them, twice:

* ``own simulation``: each unit builds the SIM's simulation afresh (what ``analysis batch --diagnose`` did
  before its workers kept it),
* ``shared simulation``: the worker's one simulation of the SIM (:func:`analysis.cli_batch.shared_simulation`)
  as a fleet's unit is compared with (:func:`analysis.cli_batch.fleet_simulation`: its global cause scales every
  stiffness alike), as ``analysis batch --diagnose`` runs it now; the first unit builds it.

``--ways shared`` runs the second way only (half the time). The two ways differ in the global cause (the
modulus alone, every stiffness), so their causes and parameters may differ a little.

The table gives each flagged unit's diagnosis CPU and wall time (s) both ways against the fits' CPU and
wall time per unit, and checks that the two ways name the same causes with the same parameters (1e-6).
CPU time is this process's and its forked children's (the diagnosis fits its causes in forked processes
outside a Dask worker): on a busy machine the wall time also counts the waiting.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def _named(doc: dict) -> list[tuple[str, dict]]:
    return [(c["effect"], c.get("parameters") or {}) for c in doc.get("named") or []]


def _same(a: list[tuple[str, dict]], b: list[tuple[str, dict]], tol: float = 1e-6) -> bool:
    """The same causes with the same parameters (numbers within ``tol`` relative)."""
    if [e for e, _ in a] != [e for e, _ in b]:
        return False
    for (_, p), (_, q) in zip(a, b):
        if p.keys() != q.keys():
            return False
        for k, v in p.items():
            w = q[k]
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                if abs(float(v) - float(w)) > tol * max(1.0, abs(float(v))):
                    return False
            elif v != w:
                return False
    return True


def cpu() -> float:
    """CPU time (s) of this process and of its children that have ended (the forked cause fits)."""
    import resource

    c = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + c.ru_utime + c.ru_stime


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=12)
    ap.add_argument("--defects", type=int, default=4)
    ap.add_argument("--seed", type=int, default=159536)
    ap.add_argument("--fleet", help="an existing fleet folder (default: make one in a temporary folder)")
    ap.add_argument("--ways", choices=("both", "shared"), default="both", help="diagnose each flagged unit both ways "
                    "or only with the shared simulation")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    from analysis.batch.diagnose import diagnosis_summary
    from analysis.batch.fleet import assess_fleet
    from analysis.batch.task import fit_one
    from analysis.batch.unit_modes import modes_from_fit
    from analysis.cli_batch import diagnose_unit
    from analysis.cli_diagnose import run_diagnosis

    with tempfile.TemporaryDirectory() as tmp:
        fleet = Path(args.fleet) if args.fleet else Path(tmp) / "fleet"
        if not args.fleet:
            subprocess.run([sys.executable, "-m", "simulator", "fleet", "--units", str(args.units), "--defects",
                            str(args.defects), "--seed", str(args.seed), "--out", str(fleet), "--jobs", "2", "-q"],
                           check=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
        sim = Path(tmp) / "nominal.toml"
        sim.write_text("# the frame as designed: simulator/frame.toml's defaults\n")
        paths = sorted(fleet.glob("unit-*.h5"))
        fits = [fit_one(str(p), p.stem, "-") for p in paths]
        fit_cpu = [float(d["cpu_seconds"]) for d in fits]
        fit_wall = [float(d["seconds"]) for d in fits]
        units = [modes_from_fit(d["fit"]) if d["status"] == "ok" else None for d in fits]
        result = assess_fleet(units, [p.stem for p in paths], [p.name for p in paths])
        flagged = [p for p, u in zip(paths, result.units) if u.flagged]
        truth = {u["name"]: u["defect"] for u in json.loads((fleet / "truth.json").read_text())["units"]}
        rows = {}
        ways = (("own", run_diagnosis), ("shared", diagnose_unit))[1 if args.ways == "shared" else 0:]
        for way, run in ways:
            for p in flagged:
                t0, c0 = time.perf_counter(), cpu()
                diag = run(str(p), str(sim), band=None, estimator=None)
                rows.setdefault(p.stem, {})[way] = (cpu() - c0, time.perf_counter() - t0,
                                                    diagnosis_summary(diag.to_json()))
                print(f"... {p.stem} {way}: {rows[p.stem][way][0]:.1f} s CPU", file=sys.stderr, flush=True)
    n_fit = len(fits)
    print(f"fleet of {n_fit} units ({args.defects} defective, seed {args.seed}); {len(flagged)} flagged; "
          f"fits: {sum(fit_cpu) / n_fit:.2f} s CPU, {sum(fit_wall) / n_fit:.2f} s wall per unit\n")
    print("| unit | defect | diagnosis CPU, own simulation (s) | CPU, shared (s) | wall own (s) | "
          "wall shared (s) | CPU shared / fit CPU per unit | same causes and parameters |")
    print("|---|---|---|---|---|---|---|---|---|")
    tot = {"own": [0.0, 0.0], "shared": [0.0, 0.0]}
    fit_unit = sum(fit_cpu) / n_fit
    none = (float("nan"), float("nan"), {})
    for name, r in rows.items():
        d = truth.get(name)
        what = "good" if not d else f"{d['kind']} {d.get('support') or d.get('joint') or d.get('element')}"
        own, shared = r.get("own", none), r["shared"]
        for way, v in (("own", own), ("shared", shared)):
            tot[way][0] += v[0]
            tot[way][1] += v[1]
        same = "-" if "own" not in r else "yes" if (_same(_named(own[2]), _named(shared[2]))
                                                     and own[2]["verdict"] == shared[2]["verdict"]) else "NO"
        named = " + ".join(f"{e} {p.get('support') or p.get('joint') or p.get('element') or p.get('component') or ''}"
                           for e, p in _named(shared[2]))
        print(f"| {name} | {what} | {own[0]:.1f} | {shared[0]:.1f} | {own[1]:.1f} | "
              f"{shared[1]:.1f} | {shared[0] / fit_unit:.0f}x | {same} | {named} |")
    k = max(len(rows), 1)
    print(f"| per flagged unit | | {tot['own'][0] / k:.1f} | {tot['shared'][0] / k:.1f} | {tot['own'][1] / k:.1f} | "
          f"{tot['shared'][1] / k:.1f} | {tot['shared'][0] / k / fit_unit:.0f}x | | |")
    print(f"\nper unit of fit: {fit_unit:.2f} s CPU, {sum(fit_wall) / n_fit:.2f} s wall")


if __name__ == "__main__":
    main()
