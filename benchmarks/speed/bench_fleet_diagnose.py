"""What a fleet's flagged unit costs to diagnose, against what a unit costs to fit.

Run by hand (not a test; on 2 cores a few minutes)::

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/speed/bench_fleet_diagnose.py [--units 12]
        [--defects 4] [--seed 159536] [--fleet DIR] [--ways shared|both] [--write]

A fleet of ``simulator fleet`` (by default 12 units, 4 defective, 2 % scatter) is fitted unit by unit as a
batch worker fits it (:func:`analysis.batch.task.fit_one`), flagged (:func:`analysis.batch.fleet.assess_fleet`),
and each flagged unit is diagnosed against the frame as designed, in this one process, one unit after the
other as a worker takes them, and as a worker does it: one process (no forked cause fits) and one BLAS thread
(``IMPACTLAB_THREADS=1``). By default one way:

* ``shared simulation``: the worker's one simulation of the SIM (:func:`analysis.cli_batch.shared_simulation`)
  as a fleet's unit is compared with (:func:`analysis.cli_batch.fleet_simulation`: its global cause scales every
  stiffness alike), as ``analysis batch --diagnose`` runs it; the first unit builds it;

and with ``--ways both`` first also

* ``own simulation``: each unit builds the SIM's simulation afresh (``analysis diagnose``'s own, whose global
  cause is the modulus alone), so its causes and parameters may differ a little from the shared way's.

The table gives each flagged unit's diagnosis CPU and wall time (s) against the fits' CPU time per unit, the CPU
of its two stages (every cause alone at every place, cross-validated: ``one cause``; the search of a second
cause on top of the first: ``pair search``; the rest, the unit's modal fit and its FRFs, is the difference; of the one
cause stage, its held-out folds, each mode left out and a cause's variant fitted again without it: ``of which folds``), and the
simulation's solves for it (candidates' modes solved in a reduced space, on the full model, with their
derivatives; reduced bases built); with both ways, whether they name the same causes with the same parameters
(1e-6). On a busy machine the wall time also counts the waiting, and the CPU time grows a little with the load
(the machine's load average is printed). ``--write`` replaces ``bench_fleet_diagnose.md`` beside the script with
this run's command line and output.
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
os.environ["IMPACTLAB_THREADS"] = "1"         # as in a Dask worker: one process, one BLAS thread
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from benchmarks.results import add_write_option, recorded  # noqa: E402

RESULTS = Path(__file__).with_name("bench_fleet_diagnose.md")
#: the simulation's work counted per unit: (class, method, column)
_COUNTED = (("simulator.physical", "FrameVariants", "_modes_reduced", "reduced solves"),
            ("simulator.physical", "FrameVariants", "exact_modes_of", "full solves"),
            ("simulator.physical", "FrameVariants", "_modes_jac", "solves with derivatives"),
            ("simulator.ritz", "RitzReduction", "space", "bases built"))


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


def _cell(col: str, v: float) -> str:
    """A table cell of column ``col``: a stage's CPU time (s) to 0.1 s, a count (or its mean) to 1."""
    return f"{v:.1f}" if col.endswith("(s)") else f"{v:.0f}"


def cpu() -> float:
    """CPU time (s) of this process and of its children that have ended (the forked cause fits)."""
    import resource

    c = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + c.ru_utime + c.ru_stime


def count_solves() -> dict[str, int]:
    """Count the simulation's solves from now on (module docstring): the counts, updated as they come."""
    import importlib

    counts = {col: 0 for *_, col in _COUNTED}
    for module, cls, name, col in _COUNTED:
        owner = getattr(importlib.import_module(module), cls)
        real = getattr(owner, name)

        def run(*a: object, _real: object = real, _col: str = col, **k: object) -> object:
            counts[_col] += 1
            return _real(*a, **k)  # type: ignore[operator]

        setattr(owner, name, run)
    return counts


#: the diagnosis' stages timed per unit: (module, function, column)
_STAGES = (("analysis.diagnosis.physical_verdict", "physical_causes", "one cause CPU (s)"),
           ("analysis.diagnosis.physical", "_held_out", "of which folds CPU (s)"),
           ("analysis.diagnosis.physical_verdict", "_pair_search", "pair search CPU (s)"))


def time_stages() -> dict[str, float]:
    """The CPU time (s) of this process in each stage of :data:`_STAGES` from now on, updated as they run."""
    import importlib

    spent = {col: 0.0 for *_, col in _STAGES}
    for module, name, col in _STAGES:
        owner = importlib.import_module(module)
        real = getattr(owner, name)

        def run(*a: object, _real: object = real, _col: str = col, **k: object) -> object:
            t0 = time.process_time()
            try:
                return _real(*a, **k)  # type: ignore[operator]
            finally:
                spent[_col] += time.process_time() - t0

        setattr(owner, name, run)
    return spent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=12)
    ap.add_argument("--defects", type=int, default=4)
    ap.add_argument("--seed", type=int, default=159536)
    ap.add_argument("--fleet", help="an existing fleet folder (default: make one in a temporary folder)")
    ap.add_argument("--ways", choices=("both", "shared"), default="shared", help="diagnose each flagged unit both "
                    "ways or only with the shared simulation (default)")
    add_write_option(ap, RESULTS)
    args = ap.parse_args()
    with recorded(RESULTS, args.write):
        run(args)


def run(args: argparse.Namespace) -> None:
    warnings.simplefilter("ignore")
    from analysis.batch.diagnose import diagnosis_summary
    from analysis.batch.fleet import assess_fleet
    from analysis.batch.task import fit_one
    from analysis.batch.unit_modes import modes_from_fit
    from analysis.cli_batch import diagnose_unit
    from analysis.cli_diagnose import run_diagnosis

    counts = count_solves()
    stages = time_stages()
    load0 = os.getloadavg()[0]
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
        rows: dict[str, dict] = {}
        ways = (("own", run_diagnosis), ("shared", diagnose_unit))[1 if args.ways == "shared" else 0:]
        for way, diagnose in ways:
            for p in flagged:
                t0, c0, n0, s0 = time.perf_counter(), cpu(), dict(counts), dict(stages)
                diag = diagnose(str(p), str(sim), band=None, estimator=None)
                rows.setdefault(p.stem, {})[way] = (cpu() - c0, time.perf_counter() - t0,
                                                    diagnosis_summary(diag.to_json()),
                                                    {**{k: counts[k] - n0[k] for k in counts},
                                                     **{k: stages[k] - s0[k] for k in stages}})
                print(f"... {p.stem} {way}: {rows[p.stem][way][0]:.1f} s CPU", file=sys.stderr, flush=True)
    n_fit = len(fits)
    fit_unit = sum(fit_cpu) / n_fit
    print(f"fleet of {n_fit} units ({args.defects} defective, seed {args.seed}); {len(flagged)} flagged; "
          f"fits: {fit_unit:.2f} s CPU, {sum(fit_wall) / n_fit:.2f} s wall per unit; load average "
          f"{load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end\n")
    cols = [*stages, *counts]
    both = args.ways == "both"
    print("| unit | defect | diagnosis CPU (s) | wall (s) | CPU / fit CPU per unit | " + " | ".join(cols)
          + (" | CPU, own simulation (s) | same causes and parameters" if both else "") + " | named |")
    print("|---|---|---|---|---|" + "---|" * len(cols) + ("---|---|" if both else "") + "---|")
    none: tuple[float, float, dict, dict] = (float("nan"), float("nan"), {}, {})
    own_cpu, cpu_sum, wall_sum = 0.0, 0.0, 0.0
    count_sum = dict.fromkeys(cols, 0.0)
    for name, r in rows.items():
        d = truth.get(name)
        what = "good" if not d else f"{d['kind']} {d.get('support') or d.get('joint') or d.get('element')}"
        own, shared = r.get("own", none), r["shared"]
        own_cpu += own[0]
        cpu_sum += shared[0]
        wall_sum += shared[1]
        for c in cols:
            count_sum[c] += shared[3][c]
        named = " + ".join(f"{e} {p.get('support') or p.get('joint') or p.get('element') or p.get('component') or ''}"
                           for e, p in _named(shared[2])) or shared[2]["verdict"]
        extra = ""
        if both:
            same = "yes" if (_same(_named(own[2]), _named(shared[2])) and own[2]["verdict"] == shared[2]["verdict"]) else "NO"
            extra = f" | {own[0]:.1f} | {same}"
        print(f"| {name} | {what} | {shared[0]:.1f} | {shared[1]:.1f} | {shared[0] / fit_unit:.0f}x | "
              + " | ".join(_cell(c, shared[3][c]) for c in cols) + f"{extra} | {named} |")
    k = max(len(rows), 1)
    print(f"| per flagged unit | | {cpu_sum / k:.1f} | {wall_sum / k:.1f} | "
          f"{cpu_sum / k / fit_unit:.0f}x | " + " | ".join(_cell(c, count_sum[c] / k) for c in cols)
          + (f" | {own_cpu / k:.1f} | " if both else "") + " | |")
    print(f"\nper unit of fit: {fit_unit:.2f} s CPU, {sum(fit_wall) / n_fit:.2f} s wall")


if __name__ == "__main__":
    main()
