"""Crash safety: SIGKILL the capture process at points the trial controls; the recording keeps every hit.

    .venv/bin/python benchmarks/crash_kill.py [--kills 50] [--resume-every 5] [--seed N] [--json]

Each trial starts ``python -m acquisition capture`` (operator mode, answers read from standard
input) on a simulated analyser with light link faults and feeds it the answers for exactly ``k``
hits (``k`` drawn from the trial's seeded generator; ``k = 0`` is a kill during start-up). The
capture cannot finish on its own: after the ``k``-th accepted hit it arms, captures the next hit and
waits for an answer that never comes. The trial reads the progress log line by line from stdout
(the session prints ``progress: ... N accepted ...`` after a hit is written and flushed, before the
next arm) and, once ``k`` accepted hits are reported, kills the process with SIGKILL after a short
random delay, so the kill lands inside the next hit's transfers or at the operator prompt. Nothing
depends on how fast the machine is: every trial is a kill. Then:

* when at least one accepted hit was reported, the recording must open and hold at least that
  many complete accepted hits, each passing its CRC-32 check (a hit cut short by the kill may be
  missing or incomplete: it was never reported);
* every ``--resume-every``-th trial runs ``capture --resume --auto`` on the killed recording, which
  must finish the plan (every point's average complete) and keep the hits from before the kill.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FAULTS = "phase_error:0.01,garbage:0.005,check_condition:0.01,double_hit:0.02"
_ACCEPTED = re.compile(r"progress: .* (\d+) accepted and (\d+) rejected in total")


@dataclass
class KillTrial:
    index: int
    kill_after_s: float
    phase: str
    reported_accepted: int = 0
    recorded_accepted: int = 0
    file_opened: bool = False
    resumed: bool | None = None
    problems: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems


def _reader(stream, lines: list) -> None:
    for line in stream:
        lines.append((time.monotonic(), line))


def _reported(lines: list) -> int:
    best = 0
    for _, line in lines:
        m = _ACCEPTED.search(line)
        if m:
            best = max(best, int(m.group(1)))
    return best


def one_trial(index: int, tmp: Path, rng: random.Random, *, hits: int = 30, resume: bool = False,
              start_timeout_s: float = 120.0) -> KillTrial:
    """Run, kill and check one capture (see the module docstring)."""
    from acquisition.errors import RecordingError
    from analysis.recording import Recording

    out = tmp / f"kill{index:03d}.h5"
    cmd = [sys.executable, "-m", "acquisition", "capture", "--device", f"sim://?seed={index}&faults={FAULTS}",
           "--out", str(out), "--hits", str(hits), "--points", "right:6:-X,top:4:X", "--timeout", "3"]
    # k answers, then the capture waits at the prompt of hit k+1: it can never finish by itself
    k = 0 if rng.random() < 0.2 else rng.randint(1, min(2 * hits - 1, 8))
    trial = KillTrial(index, 0.0, "start-up" if k == 0 else f"after hit {k}")
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(cmd, cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True, env=env)
    assert proc.stdin is not None
    proc.stdin.write("a\n" * k)
    proc.stdin.flush()
    lines: list = []
    th = threading.Thread(target=_reader, args=(proc.stdout, lines), daemon=True)
    th.start()
    t0 = time.monotonic()
    try:
        if k == 0:
            # start-up: the device is opened, configured and the first hit captured in this window
            time.sleep(rng.uniform(0.0, 1.0))
        else:
            while _reported(list(lines)) < k and proc.poll() is None:
                if time.monotonic() - t0 > start_timeout_s:
                    trial.problems.append(f"{k} accepted hits not reported within {start_timeout_s:.0f} s")
                    break
                time.sleep(0.005)
            time.sleep(rng.uniform(0.0, 0.05))  # inside the next hit's transfers, or at its prompt
        trial.kill_after_s = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
        proc.wait(30)
        th.join(10)
        proc.stdout.close()
        proc.stdin.close()
    if proc.returncode != -signal.SIGKILL:
        trial.phase += f" (ended by itself with exit code {proc.returncode})"
        trial.problems.append(f"the capture ended by itself (exit {proc.returncode}) before the kill")
    trial.reported_accepted = _reported(lines)
    try:
        with Recording(out) as rec:
            trial.file_opened = True
            hits_ok = [h for h in rec.hits(skip_damaged=True) if h.accepted]
            trial.recorded_accepted = len(hits_ok)
            if not all(h.crc_ok for h in hits_ok):
                trial.problems.append("a recorded hit fails its CRC")
    except RecordingError as exc:
        if trial.reported_accepted > 0:
            trial.problems.append(f"the recording does not open: {exc}")
    if trial.recorded_accepted < trial.reported_accepted:
        trial.problems.append(f"{trial.reported_accepted} hits reported accepted, only {trial.recorded_accepted} "
                              "in the recording")
    if resume and trial.file_opened:
        trial.resumed = _resume_ok(out, index, hits, trial)
    return trial


def _resume_ok(out: Path, index: int, hits: int, trial: KillTrial) -> bool:
    from analysis.recording import Recording

    proc = subprocess.run([sys.executable, "-m", "acquisition", "capture", "--resume", str(out), "--device",
                           f"sim://?seed={index + 5000}", "--auto", "--timeout", "3"], cwd=ROOT, capture_output=True,
                          text=True, timeout=600)
    if proc.returncode != 0:
        trial.problems.append(f"resume failed (exit {proc.returncode}): {proc.stderr.strip()[-300:]}")
        return False
    with Recording(out) as rec:
        names = rec.measurement_names()
        averages = [int(rec.frf_group(n)["n_averages"]) for n in names]
        accepted = [h for h in rec.hits() if h.accepted]
    if averages != [hits, hits]:
        trial.problems.append(f"after resume the averages are {averages}, expected [{hits}, {hits}]")
        return False
    if len(accepted) < trial.recorded_accepted:
        trial.problems.append("resume lost hits recorded before the kill")
        return False
    return True


def run_kills(n: int, tmp: Path, *, seed: int = 0, resume_every: int = 5, hits: int = 30,
              workers: int = 1) -> list[KillTrial]:
    """``n`` trials (``workers`` at a time); trial i uses ``random.Random(seed * 100003 + i)``."""
    from concurrent.futures import ThreadPoolExecutor

    def trial(i: int) -> KillTrial:
        return one_trial(i, tmp, random.Random(seed * 100003 + i), hits=hits,
                         resume=bool(resume_every) and i % resume_every == 0)

    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        return list(pool.map(trial, range(n)))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--kills", type=int, default=50)
    p.add_argument("--resume-every", type=int, default=5)
    p.add_argument("--hits", type=int, default=30, help="accepted hits per point (two points)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        trials = run_kills(args.kills, Path(tmp), seed=args.seed, resume_every=args.resume_every, hits=args.hits)
    if args.json:
        print(json.dumps([t.__dict__ for t in trials], indent=1))
    else:
        print("| trial | phase | killed after s | reported accepted | recorded accepted | resumed | ok |")
        print("|---:|---|---:|---:|---:|---|---|")
        for t in trials:
            print(f"| {t.index} | {t.phase} | {t.kill_after_s:.2f} | {t.reported_accepted} | {t.recorded_accepted} | "
                  f"{'-' if t.resumed is None else t.resumed} | {'yes' if t.ok else 'NO: ' + '; '.join(t.problems)} |")
    survived = sum(t.ok for t in trials)
    killed = sum("ended by itself" not in t.phase for t in trials)
    print(f"kills: {killed}, trials passed: {survived}/{len(trials)}, hits reported before the kills: "
          f"{sum(t.reported_accepted for t in trials)}, lost: "
          f"{sum(max(0, t.reported_accepted - t.recorded_accepted) for t in trials)}, "
          f"resumes passed: {sum(bool(t.resumed) for t in trials)}/{sum(t.resumed is not None for t in trials)}")
    return 0 if survived == len(trials) else 1


if __name__ == "__main__":
    sys.exit(main())
