"""Resonance inspection: are the defective units of a fleet flagged, and only they?

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/accuracy/bench_fleet_detection.py [--units 100]
        [--defects 10] [--scatter 2] [--seeds 1,2,3]

For each seed: ``simulator fleet`` makes the units (FE frames with manufacturing scatter; the
defective ones with a soft joint, a cracked member or a loose support, written in the FE model's
[damage] table, captured through the simulated analyser); ``analysis batch`` fits them on a local
Dask cluster and flags outliers; the flags are scored against truth.json. Prints one row per seed
and per defect kind, with the smallest defect that was flagged and the largest that was missed.
Target: >= 9 of 10 defective units flagged, <= 1 good unit flagged, per fleet of 100.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")


def run_seed(seed: int, units: int, defects: int, scatter: float, tmp: Path) -> dict:
    fleet, out = tmp / f"fleet{seed}", tmp / f"out{seed}"
    subprocess.run([sys.executable, "-m", "simulator", "fleet", "--units", str(units), "--defects", str(defects),
                    "--scatter", str(scatter), "--out", str(fleet), "--seed", str(seed), "-q"], check=True)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "analysis", "batch", str(fleet / "*.h5"), "--out", str(out), "-q"],
                   check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    truth = {u["name"]: u["defect"] for u in json.loads((fleet / "truth.json").read_text())["units"]}
    doc = json.loads((out / "fleet.json").read_text())
    flagged = {u["name"] for u in doc["units"] if u["flagged"]}
    failed = [u["name"] for u in doc["units"] if u["status"] != "ok"]
    return {"seed": seed, "truth": truth, "flagged": flagged, "failed": failed, "seconds": wall}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=100)
    ap.add_argument("--defects", type=int, default=10)
    ap.add_argument("--scatter", type=float, default=2.0)
    ap.add_argument("--seeds", default="1,2,3")
    args = ap.parse_args()
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in map(int, args.seeds.split(",")):
            results.append(run_seed(seed, args.units, args.defects, args.scatter, Path(tmp)))
    print(f"fleets of {args.units} units, {args.defects} defective, scatter +-{args.scatter:g} %\n")
    print("| seed | defective flagged | good units flagged | fits failed | batch wall (s) |")
    print("|---|---|---|---|---|")
    kinds: dict[str, list] = {}
    for r in results:
        bad = {n for n, d in r["truth"].items() if d}
        hit = bad & r["flagged"]
        false = sorted(r["flagged"] - bad)
        print(f"| {r['seed']} | {len(hit)} / {len(bad)} | {len(false)}{' (' + ', '.join(false) + ')' if false else ''} | "
              f"{len(r['failed'])} | {r['seconds']:.0f} |")
        for n in bad:
            d = r["truth"][n]
            kinds.setdefault(d["kind"], []).append((d["factor"], n in r["flagged"]))
    print("\n| defect | flagged | smallest defect flagged (factor nearest 1) | largest missed |")
    print("|---|---|---|---|")
    for kind, cases in sorted(kinds.items()):
        got = [f for f, ok in cases if ok]
        miss = [f for f, ok in cases if not ok]
        print(f"| {kind} | {len(got)} / {len(cases)} | {max(got):.3f} | " if got else f"| {kind} | 0 / {len(cases)} | - | ",
              end="")
        print(f"{min(miss):.3f} |" if miss else "none missed |")


if __name__ == "__main__":
    main()
