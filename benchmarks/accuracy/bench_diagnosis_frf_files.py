"""The diagnosis with the simulation given as an FRF file, on FRF sets it has never seen made.

Cases from ``frf_beam_cases.py`` (a continuous pinned beam solved by dynamic stiffness, sharing no
code with the diagnosis or the simulator; families, counts and ranges in its docstring). Each case
is written as two UFF 58 files (simulation and measurement) and diagnosed as a user would:
``diagnose(measured.uff, simulated.uff)``. The table gives, per family, the cases named right (with
their parameters), the verdicts and the time per case; then the nulls' false alarms and the cases
without a driving point (right: not ``mass_loading``, and the message names the driving point).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/accuracy/bench_diagnosis_frf_files.py [--workers 2] [--only 0,5]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent))

from frf_beam_cases import FAMILIES, SEED, Case, describe, draw_cases, node_numbers, write_case  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository, for benchmarks.results
from benchmarks.results import add_write_option, recorded  # noqa: E402

#: this benchmark's results file (``--write`` replaces it with the run's figures)
RESULTS = Path(__file__).with_name("bench_diagnosis_frf_files.md")

TOL = {"mass_loading": 0.25, "stiffness_shift": 0.02, "damping_change": 0.15, "missing_mode": 0.05}


def judge(case: Case, doc: dict) -> tuple[bool, str]:
    """(right, what was named) for one diagnosis document (``Diagnosis.to_json()``)."""
    verdict = doc["verdict"]
    named = doc["named"][0]["parameters"] if doc["named"] else {}
    truth = case.truth
    if truth["effect"] == "not mass_loading":
        outs, ham = node_numbers(case)
        message = " ".join([doc.get("reason", ""), str(doc.get("skipped", {}).get("mass_loading", ""))])
        says = "driving point" in message and f"n:{ham}:Z" in message
        return verdict != "mass_loading" and says, f"{verdict}; message names n:{ham}:Z: {says}"
    if verdict == "local_resonator" and truth["effect"] == "missing_mode":
        # the resonator named as what it is: its own frequency (on a rigid base) within the same tolerance
        err = abs(float(named["frequency_hz"]) / truth["freq_hz"] - 1)
        return err <= TOL["missing_mode"], f"local_resonator {float(named['frequency_hz']):.1f} Hz (err {100 * err:.1f} %)"
    if verdict != truth["effect"]:
        return False, verdict
    if verdict == "none":
        return True, verdict
    if verdict == "mass_loading":
        want = f"n:{truth['sensor'] + 1}:Z" if "sensor" in truth else None
        got = named.get("sensor")
        err = abs(float(named["mass_kg"]) / truth["mass_kg"] - 1)
        ok = (got == want or (want is None and got in (None, "all"))) and err <= TOL[verdict]
        return ok, f"mass_loading at {got or 'all'} {float(named['mass_kg']) * 1000:.1f} g (err {100 * err:.0f} %)"
    if verdict == "stiffness_shift":
        err = abs(float(named["stiffness_factor"]) / truth["stiffness_factor"] - 1)
        return err <= TOL[verdict], f"stiffness_shift {float(named['stiffness_factor']):.4f} (err {100 * err:.1f} %)"
    if verdict == "damping_change":
        err = abs(float(named["factor"]) / truth["factor"] - 1)
        return err <= TOL[verdict], f"damping_change {float(named['factor']):.3f} (err {100 * err:.0f} %)"
    if verdict == "missing_mode":
        err = abs(float(named["freq_hz"]) / truth["freq_hz"] - 1)
        return err <= TOL[verdict], f"missing_mode {float(named['freq_hz']):.1f} Hz (err {100 * err:.1f} %)"
    return False, verdict


def run_case(case: Case) -> dict:
    """Write the case's files, diagnose them, judge the verdict."""
    from analysis.diagnosis import diagnose

    with tempfile.TemporaryDirectory(prefix="frfbeam") as tmp:
        t0 = time.perf_counter()
        sim, meas = write_case(case, Path(tmp))
        t1 = time.perf_counter()
        try:
            doc = diagnose(meas, sim).to_json()
        except Exception as exc:   # a crash is a miss, reported with its message
            doc = {"verdict": f"error: {type(exc).__name__}: {exc}", "named": [], "reason": "", "skipped": {}}
        t2 = time.perf_counter()
    right, got = judge(case, doc)
    return {"index": case.index, "family": case.family, "right": right, "got": got, "verdict": doc["verdict"],
            "t_gen": t1 - t0, "t_diag": t2 - t1}


def table(rows: list[dict]) -> str:
    L = [f"{'family':16s}{'cases':>6s}{'right':>7s}{'diag s (median)':>17s}{'max s':>7s}  verdicts"]
    for fam, _ in FAMILIES:
        sel = [r for r in rows if r["family"] == fam]
        if not sel:
            continue
        ts = sorted(r["t_diag"] for r in sel)
        v = Counter(r["verdict"] for r in sel)
        L.append(f"{fam:16s}{len(sel):6d}{sum(r['right'] for r in sel):7d}{ts[len(ts) // 2]:17.1f}{ts[-1]:7.1f}  "
                 + ", ".join(f"{k} {n}" for k, n in v.most_common()))
    eff = [r for r in rows if r["family"] not in ("null",) and not r["family"].endswith("_nodp")]
    nulls = [r for r in rows if r["family"] == "null"]
    nodp = [r for r in rows if r["family"].endswith("_nodp")]
    L.append("")
    if eff:
        L.append(f"named right (with parameters): {sum(r['right'] for r in eff)}/{len(eff)} "
                 f"({100 * sum(r['right'] for r in eff) / len(eff):.1f} %)")
    if nulls:
        L.append(f"false alarms on nulls: {sum(not r['right'] for r in nulls)}/{len(nulls)}")
    if nodp:
        L.append(f"no driving point: not named mass_loading and the message names the point to measure: "
                 f"{sum(r['right'] for r in nodp)}/{len(nodp)}")
    for r in rows:
        mark = "  " if r["right"] else "X "
        L.append(f"{mark}{r['index']:3d} {r['family']:14s} {r['got']}")
    return "\n".join(L)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=SEED)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--only", default="", help="comma-separated case indices")
    ap.add_argument("--family", default="", help="only this family")
    add_write_option(ap, RESULTS)
    args = ap.parse_args()
    with recorded(RESULTS, args.write):
        _run(args)


def _run(args: argparse.Namespace) -> None:
    """The run itself (what :func:`main` records with ``--write``)."""
    cases = draw_cases(args.seed)
    if args.only:
        keep = {int(x) for x in args.only.split(",")}
        cases = [c for c in cases if c.index in keep]
    if args.family:
        cases = [c for c in cases if c.family == args.family]
    for c in cases:
        print(describe(c), flush=True)
    t = time.perf_counter()
    if args.workers > 1:
        with ProcessPoolExecutor(args.workers) as ex:
            rows = list(ex.map(run_case, cases))
    else:
        rows = [run_case(c) for c in cases]
    print()
    print(table(rows))
    print(f"total {time.perf_counter() - t:.0f} s for {len(rows)} cases ({args.workers} worker(s))")


if __name__ == "__main__":
    main()
