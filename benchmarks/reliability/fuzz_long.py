"""Long fuzzing run: every ``tests/test_*fuzz*.py`` test with 10 000 cases (hypothesis).

    .venv/bin/python benchmarks/reliability/fuzz_long.py [--examples 10000] [--files tests/test_uff_fuzz.py ...]

Runs pytest once per fuzz file with ``IMPACTLAB_FUZZ_EXAMPLES`` set and hypothesis statistics
on, then prints a table: test, cases run (hypothesis "passing examples"), failures, seconds.
A case counts as passing when the parser returned a consistent value or raised its documented
error (see ``docs/reliability.md``). Exit status 1 when any test failed.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
_STAT = re.compile(r"^(tests/\S+::\S+):\s*$")
_PASS = re.compile(r"(\d+) passing(?: examples?)?, (\d+) failing")


def run_file(path: Path, examples: int) -> tuple[list[tuple[str, int, int]], bool, float]:
    """([(test id, passing, failing)], pytest ok, seconds) for one fuzz file."""
    env = dict(os.environ, IMPACTLAB_FUZZ_EXAMPLES=str(examples))
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--timeout=0",
                           "--hypothesis-show-statistics", str(path.relative_to(ROOT))],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=4 * 3600)
    rows: list = []
    current = None
    for line in proc.stdout.splitlines():
        m = _STAT.match(line.strip())
        if m:
            current = m.group(1)
            continue
        m = _PASS.search(line)
        if m and current is not None:
            rows.append([current, int(m.group(1)), int(m.group(2))])
    merged: dict = {}
    for test, ok, bad in rows:  # phases (explicit, reuse, generate, shrink) add up
        a = merged.setdefault(test, [0, 0])
        a[0] += ok
        a[1] += bad
    if proc.returncode != 0:
        sys.stderr.write(proc.stdout[-5000:] + proc.stderr[-2000:])
    return [(k, v[0], v[1]) for k, v in merged.items()], proc.returncode == 0, time.monotonic() - t0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--examples", type=int, default=10000)
    p.add_argument("--files", nargs="*", default=None)
    args = p.parse_args(argv)
    files = [Path(f).resolve() for f in args.files] if args.files else sorted((ROOT / "tests").glob("test_*fuzz*.py"))
    ok_all = True
    print("| test | cases | failing | file ok | file seconds |")
    print("|---|---:|---:|---|---:|")
    total = 0
    for f in files:
        rows, ok, secs = run_file(f, args.examples)
        ok_all &= ok
        for test, n_ok, n_bad in rows:
            total += n_ok
            print(f"| {test.split('::', 1)[1]} | {n_ok} | {n_bad} | {'yes' if ok else 'NO'} | {secs:.0f} |", flush=True)
    print(f"total cases: {total}")
    return 0 if ok_all else 1


if __name__ == "__main__":
    sys.exit(main())
