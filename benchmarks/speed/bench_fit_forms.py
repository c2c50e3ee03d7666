"""CPU time of the automatic fit on four problems of very different shape, and which evaluation of the
LSFD's projected problem (Gram-based or direct) it used.

The LSFD evaluates its projected problem in one of two forms (``analysis/_lsfd_kernels.py``): the
Gram-based one (semi-normal equations: one product of the basis and the derivative columns with the
data) or the direct one (the basis's Householder reflectors applied to the derivative columns and the
data). Which is cheaper depends on the problem's shape; this benchmark shows the fit's CPU time on:

* ``default``: a default ``sim://?seed=1`` capture (one hammer point, 3 FRFs, ``--hits 5 --auto``),
  fitted as ``python -m analysis fit rec.h5 --json fit.json`` does (its ``main`` called in the process;
  the capture is made once and not timed);
* ``uliege``: the ULiege plane (3 x 74 FRFs x 1601 lines, its whole recorded range), ``fit_auto``;
* ``unesp``: the UNESP bolted beam at 0.05 V (4 FRFs x 8192 lines, its whole range), ``fit_auto``;
* ``scan``: the scanning-vibrometer case of ``bench_fit_scale.py`` (3000 FRFs x 8000 lines x 40 modes),
  ``fit_auto``; its peak resident memory is shown too (about 1 GiB).

Each case runs in its own process (one BLAS thread: ``OPENBLAS_NUM_THREADS=1``), timed with
``time.process_time`` (the CPU of the fit; on a machine shared with other programs the CPU time is the
honest figure, the wall time is the machine's share). ``--repeat N`` runs each case N times and shows
the best. ``--form gram`` or ``--form direct`` forces one form wherever the fit would choose (the
evaluations that must be direct, for a verdict or where the Gram form would lose its digits, stay
direct); ``--source DIR`` runs another checkout's ``analysis`` (e.g. an older version, to compare).
``--json OUT`` writes the figures and the poles; ``--compare OLD.json`` prints how far this run's
poles are from those of OLD (the largest difference in Hz, relative, and in standard deviations).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/speed/bench_fit_forms.py [--only default,uliege,unesp,scan]
        [--repeat 3] [--form auto|gram|direct] [--source DIR] [--json OUT.json] [--compare OLD.json]

The real datasets are read from ``../shared/data`` beside the checkout (as the tests do: the variable
``IMPACTLAB_SHARED_DATA`` names another folder) or ``--data DIR``; a case whose data is absent is skipped.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CASES = ("default", "uliege", "unesp", "scan")
DEFAULT_DATA = Path(os.environ.get("IMPACTLAB_SHARED_DATA", ROOT.parent / "shared" / "data"))

# ------------------------------------------------------------------------------------------- the child
CHILD = r'''
import json, resource, sys, time, warnings
from pathlib import Path
import numpy as np
case, form, data, work, bench = sys.argv[1:6]
sys.path.insert(0, bench)
from analysis import _lsfd_kernels as K
import analysis.pipeline as pipeline
counts = {"gram": 0, "direct": 0}
_evaluate = K.ProjectedProblem.evaluate
def evaluate(self, theta, *, fast=False):
    if form == "direct":
        fast = False
    ev = _evaluate(self, theta, fast=fast)
    counts["direct" if ev.precise else "gram"] += 1
    return ev
K.ProjectedProblem.evaluate = evaluate
if form == "gram":
    if hasattr(K, "gram_form_pays"):
        K.gram_form_pays = lambda *a, **k: True
    else:
        K.ProjectedProblem.FAST_MIN_SIZE = 0
fits = []
_fit_auto = pipeline.fit_auto
def fit_auto(*a, **k):
    fit = _fit_auto(*a, **k)
    fits.append(fit)
    return fit
pipeline.fit_auto = fit_auto
warnings.simplefilter("ignore")
if case == "default":
    import analysis.cli_fit as cli_fit
    import analysis.report  # noqa: F401  (imported before the clock starts, as the other cases' modules)
    import contextlib, io
    run = lambda: cli_fit.main([str(Path(work) / "rec.h5"), "--json", str(Path(work) / "fit.json"), "--overwrite", "-q"])
    out = io.StringIO()
    redirect = lambda: contextlib.redirect_stdout(out)
elif case in ("uliege", "unesp"):
    from benchmarks.accuracy.validation.datasets import DATASETS
    d = {"uliege": "uliege_plane", "unesp": "unesp_boltedbeam"}[case]
    ds = {x.key: x for x in DATASETS}[d]
    frf = ds.load(Path(data), **ds.whole_range)
    run = lambda: pipeline.fit_auto(frf)
    import contextlib
    redirect = contextlib.nullcontext
else:
    sys.path.insert(0, str(Path(bench) / "benchmarks" / "speed"))
    from bench_fit_scale import scanning_test
    frf, _, _ = scanning_test(1000, 3, 8000, 40, 0.01, 7)
    run = lambda: pipeline.fit_auto(frf)
    import contextlib
    redirect = contextlib.nullcontext
t0 = time.process_time()
with redirect():
    run()
cpu = time.process_time() - t0
fit = fits[-1]
lsfd = fit.lsfd
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
order = np.argsort(lsfd.freq_hz)
print(json.dumps({"cpu_s": cpu, "peak_gib": peak, "counts": counts, "modes": int(lsfd.freq_hz.size),
                  "freq_hz": lsfd.freq_hz[order].tolist(), "damping": lsfd.damping[order].tolist(),
                  "freq_hz_std": lsfd.freq_hz_std[order].tolist(), "success": bool(fit.success)}))
'''


def capture(work: Path, source: Path) -> None:
    """The default capture (not timed), made once per work folder."""
    if (work / "rec.h5").exists():
        return
    env = dict(os.environ, PYTHONPATH=str(source))
    subprocess.run([sys.executable, "-m", "acquisition", "capture", "--device", "sim://?seed=1", "--out", "rec.h5",
                    "--hits", "5", "--auto", "-q"], cwd=work, env=env, check=True, capture_output=True)


def run_case(case: str, form: str, data: Path, work: Path, source: Path) -> dict:
    """One case in a fresh process: its CPU time, evaluations, peak memory and poles."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=os.pathsep.join([str(source), str(ROOT)]))
    env.pop("IMPACTLAB_THREADS", None)
    out = subprocess.run([sys.executable, "-c", CHILD, case, form, str(data), str(work), str(source)],
                         env=env, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"case {case} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def pole_difference(a: dict, b: dict) -> str:
    """The largest difference of the poles of two runs: Hz, relative, in standard deviations."""
    import numpy as np

    if a["modes"] != b["modes"]:
        return f"{a['modes']} against {b['modes']} modes"
    if not a["modes"]:
        return "no modes either way"
    fa, fb = np.array(a["freq_hz"]), np.array(b["freq_hz"])
    za, zb = np.array(a["damping"]), np.array(b["damping"])
    sd = np.array(b["freq_hz_std"])
    df = np.abs(fa - fb)
    return (f"max |df| {df.max():.2g} Hz ({(df / fb).max():.2g} rel., {np.nanmax(df / sd):.2g} sd), "
            f"max |dzeta| {np.abs(za - zb).max():.2g}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=",".join(CASES), help=f"cases, of {','.join(CASES)}")
    ap.add_argument("--repeat", type=int, default=1, help="runs per case; the best CPU time is shown")
    ap.add_argument("--form", default="auto", choices=("auto", "gram", "direct"))
    ap.add_argument("--source", default=str(ROOT), help="checkout whose analysis package is timed (default: this one)")
    ap.add_argument("--data", default=str(DEFAULT_DATA), help="the real datasets' folder")
    ap.add_argument("--work", help="folder for the default capture (kept; default a temporary one)")
    ap.add_argument("--json", metavar="OUT.json")
    ap.add_argument("--compare", metavar="OLD.json", help="print the largest pole differences from OLD.json")
    a = ap.parse_args(argv)
    cases = [c for c in a.only.split(",") if c]
    bad = set(cases) - set(CASES)
    if bad:
        ap.error(f"unknown case(s) {sorted(bad)}; choose from {CASES}")
    source, data = Path(a.source).resolve(), Path(a.data)
    old = json.loads(Path(a.compare).read_text()) if a.compare else {}
    tmp = None
    if a.work:
        work = Path(a.work)
        work.mkdir(parents=True, exist_ok=True)
    else:
        tmp = tempfile.TemporaryDirectory()
        work = Path(tmp.name)
    results: dict[str, dict] = {}
    print(f"source {source}, form {a.form}, best of {a.repeat}; load average {os.getloadavg()[0]:.1f} at the start")
    print("| case | CPU s | runs (s) | evaluations gram / direct | modes | peak GiB | poles against --compare |")
    print("|---|---|---|---|---|---|---|")
    for case in cases:
        if case in ("uliege", "unesp") and not data.is_dir():
            print(f"| {case} | skipped: no {data} | | | | | |")
            continue
        if case == "default":
            capture(work, source)
        runs = [run_case(case, a.form, data, work, source) for _ in range(a.repeat)]
        best = min(runs, key=lambda r: r["cpu_s"])
        best["runs_s"] = [r["cpu_s"] for r in runs]
        results[case] = best
        cmp = pole_difference(best, old[case]) if case in old else "-"
        print(f"| {case} | {best['cpu_s']:.2f} | {', '.join(f'{t:.2f}' for t in best['runs_s'])} | "
              f"{best['counts']['gram']} / {best['counts']['direct']} | {best['modes']} | {best['peak_gib']:.2f} | {cmp} |",
              flush=True)
    print(f"load average {os.getloadavg()[0]:.1f} at the end")
    if a.json:
        Path(a.json).write_text(json.dumps(results, indent=1))
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
