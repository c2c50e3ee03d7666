"""Wall and CPU time of the commands a user runs, idle and beside two CPU-bound programs.

Each command runs as a process with the user's environment, on an idle machine and with two
CPU-bound programs running beside it; then the automatic fit at scanning-vibrometer scale (time
and peak memory, in a child process).

The commands (each a fresh ``python -m ...`` process, the BLAS thread variables
``OPENBLAS_NUM_THREADS``/``OMP_NUM_THREADS``/``MKL_NUM_THREADS`` removed from its environment, as a
user who never heard of them runs it; ``IMPACTLAB_THREADS`` is passed on when set):

* ``capture``: ``acquisition capture --device sim://?seed=1 --hits 5 --auto`` (the default test:
  one hammer point, three accelerometers, 3 FRFs);
* ``fit``: ``analysis fit rec.h5 --json fit.json`` on that capture;
* ``report``: ``analysis report rec.h5 --out report/`` (the fit inside) and ``report --fit``:
  the same from the fit's JSON (the report's own work);
* ``stabilization``: ``analysis stabilization rec.h5 --png stab.png``;
* ``diagnose``: one physical change (the supports' rotational springs x 0.4, written as a changed
  frame configuration and captured through ``sim://?config=...``; not timed) diagnosed against the
  unchanged ``simulator/frame.toml``; ``diagnose pair``: two changes at once (a 1.3 kg steel block
  clamped at ``top:2``, built as an extra member on joint springs, and the supports' rotational springs
  x 0.264: the first pair case of ``bench_diagnosis_large.py``, rounded), the same way. The verdict and the named causes are printed under the times (the same
  verdicts before and after a speed change are part of what the benchmark shows).

"busy" runs them while two ``python -c "while True: pass"`` processes, started and stopped by this
script, keep the cores busy. ``scan`` runs ``bench_fit_scale.py`` in a child process (``--scan-outputs``
x 3 FRFs x 8000 lines x 40 modes; the child's wall time of ``fit_auto`` and its maximum resident
memory from ``resource.getrusage``).

Run (at most about 10 minutes with the defaults on 2 cores: the scanning case is stopped after
``--scan-timeout`` seconds)::

    .venv/bin/python benchmarks/speed/bench_user_commands.py [--only fit,report] [--conditions idle,busy]
        [--repeat 1] [--scan-outputs 1000 --scan-conditions idle --scan-timeout 240 | --no-scan] [--keep DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PY = sys.executable
COMMANDS = ("capture", "fit", "report", "report --fit", "stabilization", "diagnose", "diagnose pair")
#: the issue's targets (s); None: no target, shown for information
TARGETS: dict[str, float | None] = {"capture": None, "fit": 1.0, "report": 2.0, "report --fit": 2.0,
                                        "stabilization": None, "diagnose": 5.0, "diagnose pair": 15.0}
BLAS_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def user_env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in BLAS_VARS}
    env.setdefault("MPLBACKEND", "Agg")
    return env


def _children_cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def run(argv: list[str], cwd: Path) -> tuple[float, float]:
    """Wall time and CPU time (user + system, s) of one command; a failing command stops the
    benchmark with its stderr. On a machine shared with other work the CPU time is close to what
    the wall time would be on an idle machine for a single-threaded command."""
    c0, t0 = _children_cpu_s(), time.perf_counter()
    out = subprocess.run(argv, cwd=cwd, env=user_env(), capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, _children_cpu_s() - c0
    if out.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({out.returncode}):\n{out.stderr[-2000:]}")
    return wall, cpu


def changed_frame(work: Path) -> Path:
    """The physical change: the supports' rotational springs x 0.4 (a changed frame configuration)."""
    sys.path.insert(0, str(ROOT))
    from simulator.config import FrameConfig, overrides_to_toml

    k = list(FrameConfig.load().supports.stiffness)
    cfg = work / "changed.toml"
    cfg.write_text(overrides_to_toml({"supports": {"stiffness": k[:3] + [0.4 * x for x in k[3:]]}}))
    return cfg


def changed_pair(work: Path) -> Path:
    """Two physical changes: a 1.3 kg steel block at ``top:2`` (an extra member on joint springs) and the
    supports' rotational springs x 0.264."""
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(ROOT / "benchmarks" / "accuracy"))
    from bench_diagnosis_physical import steel_block

    from simulator.config import FrameConfig, overrides_to_toml

    cfg = FrameConfig.load()
    k = list(cfg.supports.stiffness)
    over = {**steel_block(cfg, "top:2", 1.3), "supports": {"stiffness": k[:3] + [0.264 * x for x in k[3:]]}}
    path = work / "changed_pair.toml"
    path.write_text(overrides_to_toml(over))
    return path


def command_line(name: str, work: Path) -> list[str]:
    a, m = [PY, "-m", "acquisition"], [PY, "-m", "analysis"]
    return {
        "capture": a + ["capture", "--device", "sim://?seed=1", "--out", "rec_timed.h5", "--hits", "5", "--auto", "-q"],
        "fit": m + ["fit", "rec.h5", "--json", "fit.json", "--overwrite", "-q"],
        "report": m + ["report", "rec.h5", "--out", "report", "-q"],
        "report --fit": m + ["report", "rec.h5", "--out", "report_fit", "--fit", "fit.json", "-q"],
        "stabilization": m + ["stabilization", "rec.h5", "--png", "stab.png", "-q"],
        "diagnose": m + ["diagnose", "--measured", "changed.h5", "--simulated", str(ROOT / "simulator" / "frame.toml"),
                         "--json", "diag.json", "-q"],
        "diagnose pair": m + ["diagnose", "--measured", "changed_pair.h5", "--simulated",
                              str(ROOT / "simulator" / "frame.toml"), "--json", "diag_pair.json", "-q"],
    }[name]


def prepare(work: Path, names: list[str]) -> None:
    """The inputs the timed commands read (not timed)."""
    need = {"fit", "report", "report --fit", "stabilization"} & set(names)
    if need:
        run([PY, "-m", "acquisition", "capture", "--device", "sim://?seed=1", "--out", "rec.h5", "--hits", "5",
             "--auto", "-q"], work)
    if "report --fit" in names:
        run(command_line("fit", work), work)
    points = "right:6:-X,right:4:-X,left:6:X,top:4:Z,top:2:Z,left:9:Y"
    for name, make, seed, out in (("diagnose", changed_frame, 22, "changed.h5"),
                                  ("diagnose pair", changed_pair, 877201, "changed_pair.h5")):
        if name in names:
            cfg = make(work)
            run([PY, "-m", "acquisition", "capture", "--device", f"sim://?seed={seed}&config={cfg}", "--out", out,
                 "--points", points, "--hits", "3", "--auto", "-q"], work)


class Busy:
    """Two CPU-bound processes for the duration of a ``with`` block."""

    def __init__(self, n: int = 2) -> None:  # n = 0: nothing started
        self.n = n
        self.procs: list[subprocess.Popen] = []

    def __enter__(self) -> Busy:
        self.procs = [subprocess.Popen([PY, "-c", "while True: pass"]) for _ in range(self.n)]
        if self.n:
            time.sleep(1.0)
        return self

    def __exit__(self, *exc: object) -> None:
        for p in self.procs:
            p.terminate()
        for p in self.procs:
            p.wait()


def time_commands(names: list[str], work: Path, repeat: int) -> dict[str, tuple[float, float]]:
    """Per command: the best (wall, CPU) time in seconds over ``repeat`` runs."""
    out = {}
    for name in names:
        times = []
        for _ in range(repeat):
            if name == "capture":
                (work / "rec_timed.h5").unlink(missing_ok=True)
            if name.startswith("report"):
                shutil.rmtree(work / ("report" if name == "report" else "report_fit"), ignore_errors=True)
            times.append(run(command_line(name, work), work))
        out[name] = min(times)
        print(f"  {name:14s} wall {out[name][0]:7.2f} s, CPU {out[name][1]:7.2f} s", flush=True)
        if name.startswith("diagnose"):
            print(f"  {'':14s} {verdict_line(work / ('diag.json' if name == 'diagnose' else 'diag_pair.json'))}")
    return out


def verdict_line(path: Path) -> str:
    """The verdict and the named causes with their parameters (4 digits) of a diagnosis JSON."""
    doc = json.loads(path.read_text())
    named = [f"{c['effect']}(" + ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                                           for k, v in c["parameters"].items()) + ")" for c in doc.get("named", [])]
    return f"verdict {doc['verdict']}: {'; '.join(named) or '-'}"


def _peak_rss_gib(pid: int) -> float:
    """The process's peak resident memory so far (``VmHWM`` of ``/proc/PID/status``), GiB; NaN if unknown."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return float(line.split()[1]) / 2**20
    except OSError:
        pass
    return float("nan")


def scan_case(outputs: int, busy: bool, timeout_s: float) -> dict[str, float]:
    """bench_fit_scale.py in a child process: fit_auto's wall time and the child's peak memory
    (``resource.getrusage`` in the child). A run longer than ``timeout_s`` is stopped; its time is
    then reported as more than the limit and its memory as the peak until then."""
    argv = [PY, str(ROOT / "benchmarks" / "speed" / "bench_fit_scale.py"), "--outputs", str(outputs)]
    with Busy(2 if busy else 0):
        t0 = time.perf_counter()  # the child prints its own fit time; this bounds the whole run
        child = subprocess.Popen(argv, env=user_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        peak = float("nan")
        while child.poll() is None and time.perf_counter() - t0 < timeout_s:
            peak = _peak_rss_gib(child.pid)
            time.sleep(0.5)
        if child.poll() is None:
            child.kill()
            child.communicate()
            print(f"    stopped after {timeout_s:.0f} s (peak memory until then {peak:.2f} GiB)")
            return {"wall_s": float("inf"), "peak_gib": peak, "stopped_after_s": timeout_s}
        stdout, stderr = child.communicate()
    if child.returncode != 0:
        raise SystemExit(f"the scanning-vibrometer case failed:\n{stderr[-2000:]}")
    print("\n".join("    " + line for line in stdout.splitlines()))
    wall = float(re.search(r"wall ([0-9.]+) s", stdout).group(1))          # type: ignore[union-attr]
    gib = float(re.search(r"peak memory ([0-9.]+) GiB", stdout).group(1))  # type: ignore[union-attr]
    return {"wall_s": wall, "peak_gib": gib}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=",".join(COMMANDS),
                    help=f"comma-separated commands to time (default all: {', '.join(COMMANDS)}); 'none' for only the scan")
    ap.add_argument("--conditions", default="idle,busy", help="idle, busy or both (default idle,busy)")
    ap.add_argument("--repeat", type=int, default=1, help="runs per command; the best is shown (default 1)")
    ap.add_argument("--scan-outputs", type=int, default=1000,
                    help="outputs of the scanning-vibrometer case (x 3 references; default 1000 = 3000 FRFs)")
    ap.add_argument("--no-scan", action="store_true", help="skip the scanning-vibrometer case")
    ap.add_argument("--scan-conditions", default="idle", help="idle, busy or both for the scanning case (default idle)")
    ap.add_argument("--scan-timeout", type=float, default=240.0, metavar="S",
                    help="stop the scanning case after S seconds and report '> S s' (default 240)")
    ap.add_argument("--keep", metavar="DIR", help="work in DIR and keep it (default: a temporary folder)")
    ap.add_argument("--json", metavar="OUT.json", help="also write the figures as JSON")
    a = ap.parse_args(argv)
    names = [] if a.only.strip() == "none" else [n.strip() for n in a.only.split(",") if n.strip()]
    bad = [n for n in names if n not in COMMANDS]
    conditions = [c.strip() for c in a.conditions.split(",") if c.strip()]
    if bad or any(c not in ("idle", "busy") for c in conditions):
        ap.error(f"unknown command or condition: {bad or conditions}")
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f} at the start; "
          f"removed from the commands' environment: {', '.join(BLAS_VARS)}; "
          f"IMPACTLAB_THREADS={os.environ.get('IMPACTLAB_THREADS', '(unset)')}")
    work = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="impactlab-bench-"))
    work.mkdir(parents=True, exist_ok=True)
    results: dict[str, dict] = {}
    try:
        prepare(work, names)
        for cond in conditions:
            print(f"{cond}:", flush=True)
            if cond == "busy":
                with Busy():
                    results[cond] = time_commands(names, work, a.repeat)
            else:
                results[cond] = time_commands(names, work, a.repeat)
        if not a.no_scan:
            for cond in [c.strip() for c in a.scan_conditions.split(",") if c.strip()]:
                print(f"scanning vibrometer ({a.scan_outputs * 3} FRFs x 8000 lines x 40 modes), {cond}:", flush=True)
                results.setdefault("scan", {})[cond] = scan_case(a.scan_outputs, cond == "busy", a.scan_timeout)
    finally:
        if not a.keep:
            shutil.rmtree(work, ignore_errors=True)
    if names:
        print("\n| command | " + " | ".join(f"{c}: wall (CPU)" for c in conditions) + " | target |")
        print("|---|" + "---|" * len(conditions) + "---|")
    for name in names:
        t = TARGETS[name]
        cells = [f"{results[c][name][0]:.2f} s ({results[c][name][1]:.2f} s)" for c in conditions]
        print(f"| {name} | " + " | ".join(cells) + f" | {f'< {t:g} s' if t else '-'} |")
    if "scan" in results:
        print("\n| scanning-vibrometer case | wall, peak memory | target |\n|---|---|---|")
        for c, r in results["scan"].items():
            t = f"> {r['stopped_after_s']:.0f} s" if "stopped_after_s" in r else f"{r['wall_s']:.1f} s"
            print(f"| fit_auto, {a.scan_outputs * 3} FRFs x 8000 lines x 40 modes, {c} | {t}, {r['peak_gib']:.2f} GiB "
                  "| < 10 s, < 4 GB |")
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    if a.json:
        Path(a.json).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
