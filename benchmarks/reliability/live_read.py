"""Live reading: a capture writes a recording while another process exports it every second.

    .venv/bin/python benchmarks/reliability/live_read.py [--hits 200] [--points 4] [--period 1.0] [--door sim]

The capture (``python -m acquisition capture --auto``, a simulated analyser) writes ``--hits``
accepted hits in all over ``--points`` roving-hammer points. While it runs, a second process, every
``--period`` seconds, opens the recording (read live while it is written), reads every hit (each
checked against its CRC-32) and runs ``acquisition export REC --uff OUT.uff`` (the FRFs of the
points finished so far; before the first one is finished the command must answer that the
recording holds no FRF results). Checked: every export valid; the number of hits and of FRFs it
sees never decreases; every hit an export read equals the final recording's hit of that index;
the capture completes. Prints a table and exits 1 on any failure.
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

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
POINTS = ["left:9:Y", "top:4:X", "right:6:-X", "left:3:Y", "top:2:X", "right:2:-X"]

#: the exporting process (see module doc): one JSON line per export until the file STOP exists
EXPORTER = """
import contextlib, io, json, sys, time
import numpy as np
from pathlib import Path
from acquisition.cli_export import main
from analysis.recording import Recording
from analysis.uff import read_uff58
rec, workdir, period = Path(sys.argv[1]), Path(sys.argv[2]), float(sys.argv[3])
print("ready", flush=True)
k, t0 = 0, time.monotonic()
while not (workdir / "STOP").exists():
    time.sleep(max(0.0, period - (time.monotonic() - t0) % period))
    if not rec.exists():
        continue
    out, err = workdir / f"export-{k:04d}.uff", io.StringIO()
    start = time.monotonic()
    row = {"t_s": round(start - t0, 2)}
    try:
        with Recording(rec) as r:
            hits = list(r.hits())  # raises on a hit that fails its CRC-32
            row.update(live=r.live, hits=len(hits), sums=[int(h.counts.astype(np.int64).sum()) for h in hits])
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = main([str(rec), "--uff", str(out), "--overwrite", "-q"])
        text = err.getvalue().strip()
        if code == 0:
            frf = read_uff58(out)
            row.update(code=0, frfs=int(np.sum(~np.all(np.isnan(frf.H), axis=2))), error="")
        elif "holds no FRF results" in text:
            row.update(code=0, frfs=0, error="")  # the right answer before the first point is finished
        else:
            row.update(code=code, frfs=0, error=text)
    except Exception as exc:
        row.update(code=-1, frfs=0, error=f"{type(exc).__name__}: {exc}")
    row["seconds"] = round(time.monotonic() - start, 3)
    print(json.dumps(row), flush=True)
    out.unlink(missing_ok=True)
    k += 1
"""


def run(hits: int, n_points: int, period: float, door: str, workdir: Path) -> dict:
    """Run the capture and the exporter side by side; the rows of every export and the problems found."""
    from analysis.recording import Recording

    rec = workdir / "live.h5"
    per_point = max(1, hits // n_points)
    env = dict(os.environ, PYTHONUNBUFFERED="1", MPLBACKEND="Agg")
    exporter = subprocess.Popen([sys.executable, "-c", EXPORTER, str(rec), str(workdir), str(period)], cwd=ROOT,
                                env=env, stdout=subprocess.PIPE, text=True)
    assert exporter.stdout is not None and exporter.stdout.readline().strip() == "ready"
    capture = subprocess.Popen([sys.executable, "-m", "acquisition", "capture", "--auto", "--device",
                                f"{door}://?seed=1", "--out", str(rec), "--points", ",".join(POINTS[:n_points]),
                                "--hits", str(per_point)],
                               cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    t0 = time.monotonic()
    try:
        capture_out = capture.communicate(timeout=3600)[0]
        capture_end = time.monotonic() - t0
        (workdir / "STOP").touch()
        lines = exporter.communicate(timeout=600)[0].splitlines()
    finally:
        for proc in (capture, exporter):
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    exports = [json.loads(line) for line in lines if line.startswith("{")]
    for row in exports:
        row["during_capture"] = row["t_s"] + row["seconds"] < capture_end
    with Recording(rec) as r:
        final_sums = [int(h.counts.astype(np.int64).sum()) for h in r.hits()]
        final_accepted = sum(h.accepted for h in r.hits())
    ok = [r for r in exports if r["code"] == 0]
    counts, frfs = [r["hits"] for r in ok], [r["frfs"] for r in ok]
    problems = []
    if capture.returncode != 0:
        problems.append(f"capture exited {capture.returncode}: {capture_out[-500:]}")
    problems += [f"export at {r['t_s']} s failed: {r['error']}" for r in exports if r["code"] != 0]
    if any(b < a for a, b in zip(counts, counts[1:])):
        problems.append(f"hit counts not monotone: {counts}")
    if any(b < a for a, b in zip(frfs, frfs[1:])):
        problems.append(f"FRF counts not monotone: {frfs}")
    for row in ok:
        if row["sums"] != final_sums[: len(row["sums"])]:
            problems.append(f"the export at {row['t_s']} s holds hits that differ from the final recording")
    return {"exports": exports, "ok": ok, "counts": counts, "frfs": frfs, "final_hits": len(final_sums),
            "final_accepted": final_accepted, "planned": per_point * n_points, "problems": problems,
            "during": sum(r["during_capture"] for r in exports), "live": sum(bool(r.get("live")) for r in exports),
            "wall_s": time.monotonic() - t0}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--hits", type=int, default=200)
    p.add_argument("--points", type=int, default=4)
    p.add_argument("--period", type=float, default=1.0)
    p.add_argument("--door", default="sim", choices=("sim", "usbsim", "loopback"))
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        r = run(args.hits, args.points, args.period, args.door, Path(tmp))
    secs = [x["seconds"] for x in r["ok"]]
    seen = r["counts"]
    shown = ", ".join(str(c) for c in seen) if len(seen) <= 8 else \
        ", ".join(str(c) for c in seen[:4]) + " ... " + ", ".join(str(c) for c in seen[-3:])
    monotone = "yes" if not any(b < a for a, b in zip(seen, seen[1:])) else "NO"
    print("| accepted hits (planned / recorded) | hits recorded | exports | during the capture (read live) | valid | "
          "monotone | hit counts seen | FRFs seen (first, last) | export s (median / max) | wall s |")
    print("|---:|---:|---:|---:|---:|---|---|---|---:|---:|")
    print(f"| {r['planned']} / {r['final_accepted']} | {r['final_hits']} | {len(r['exports'])} | {r['during']} "
          f"({r['live']}) | {len(r['ok'])} | {monotone} | {shown} | "
          f"{r['frfs'][0] if r['frfs'] else '-'}, {r['frfs'][-1] if r['frfs'] else '-'} | "
          f"{np.median(secs) if secs else float('nan'):.2f} / {max(secs) if secs else float('nan'):.2f} | "
          f"{r['wall_s']:.0f} |")
    for prob in r["problems"]:
        print("PROBLEM:", prob)
    return 1 if r["problems"] else 0


if __name__ == "__main__":
    sys.exit(main())
