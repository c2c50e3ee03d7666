"""``python -m simulator fleet --units N --out DIR``: recordings of a production fleet of frames.

Each unit (:mod:`simulator.fleet`: manufacturing scatter of modulus, density, joint and support
stiffness within +-PCT, and K units with one physical defect) is captured through the simulated
analyser like any test: ``sim://?seed=S&config=DIR/configs/unit-007.toml``, the default set-up
(hammer at right:6:-X, accelerometers at left:9:Y, top:4:X, right:4:-Z), ``--hits`` accepted hits.
DIR gets ``unit-007.h5`` per unit, ``configs/`` (each unit's frame config) and ``truth.json``
(``{"units": [{"name", "file", "defect": null or {"kind", ...}}]}``).

Each recording appears under its final name only when complete, so running the command again
after a crash captures only the units that are missing. A folder that holds another fleet (made
with other ``--units``, ``--scatter``, ``--defects`` or ``--seed``) is refused: its ``truth.json``
must keep describing its recordings. Units are captured in parallel by
``--jobs`` processes (default: one per core).
Exit status: 0 done, 1 a capture failed, 2 bad input.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import contextlib
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from analysis.atomic import atomic_path, write_json_atomic, write_text_atomic
from analysis.command_line import Parser, cli_entry, errors_to_exit, parse_args, with_examples

from .config import overrides_to_toml
from .fleet import DEFECT_KINDS, UnitSpec, fleet_folder_conflict, plan_fleet, recorded_plan

__all__ = ["main", "build_parser", "capture_unit"]


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="python -m simulator fleet", description=__doc__.splitlines()[0])
    p.add_argument("--units", type=int, required=True, help="number of units (recordings) to make")
    p.add_argument("--out", required=True, metavar="DIR", help="folder for the recordings and truth.json (created)")
    p.add_argument("--scatter", type=float, default=2.0, metavar="PCT",
                   help="manufacturing scatter: each unit's modulus, density, joint and support stiffness within "
                        "+-PCT %% of nominal (default 2)")
    p.add_argument("--defects", type=int, default=0, metavar="K",
                   help=f"number of defective units, each with one of: {', '.join(DEFECT_KINDS)} (default 0)")
    p.add_argument("--seed", type=int, default=0, help="seed of the whole fleet (default 0): same seed, same fleet")
    p.add_argument("--hits", type=int, default=3, help="accepted hits per unit (default 3)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                   help="units captured at once, in separate processes (default: one per core)")
    return with_examples(p)


def capture_unit(spec: UnitSpec, out_dir: str, hits: int) -> None:
    """Capture one unit into ``out_dir/<name>.h5`` (renamed into place when complete) with the default
    set-up and windows and every hit that passes the checks accepted; a failed capture raises
    :class:`_CaptureFailed` with its message."""
    from acquisition.capture import capture_to_file
    from acquisition.plan import TestPlan
    from acquisition.setup import default_setup
    from acquisition.window_options import DEFAULT_EXP_WINDOW, DEFAULT_FORCE_WINDOW, parse_windows
    from analysis.errors import ImpactlabError

    out = Path(out_dir)
    cfg = out / "configs" / f"{spec.name}.toml"
    write_text_atomic(cfg, overrides_to_toml(spec.overrides))
    final = out / f"{spec.name}.h5"
    setup = default_setup()
    windows = parse_windows(DEFAULT_FORCE_WINDOW, DEFAULT_EXP_WINDOW, setup.sample_rate_hz)
    with atomic_path(final) as tmp:
        try:
            capture_to_file(f"sim://?seed={spec.seed}&config={cfg}", f"{tmp}.h5", setup,
                            TestPlan(mode="roving_hammer", hits_per_point=hits), windows)
        except (ImpactlabError, OSError, ValueError) as exc:
            with contextlib.suppress(OSError):
                os.unlink(f"{tmp}.h5")
            raise _CaptureFailed(spec.name, 1, f"{type(exc).__name__}: {exc}") from None
        os.replace(f"{tmp}.h5", tmp)


class _CaptureFailed(Exception):
    def __init__(self, name: str, rc: int, text: str) -> None:
        super().__init__(name, rc, text)
        self.name, self.rc, self.text = name, rc, text


def _run(specs: list[UnitSpec], out: Path, hits: int, jobs: int, quiet: bool) -> list[str]:
    """Capture the units not yet on disk; returns the names that failed."""
    todo = [s for s in specs if not (out / f"{s.name}.h5").exists()]
    if len(todo) < len(specs) and not quiet:
        print(f"{len(specs) - len(todo)} of {len(specs)} units already on disk: capturing the other {len(todo)}",
              file=sys.stderr)
    failed: list[str] = []
    done = 0
    t0 = time.perf_counter()

    def report(name: str, ok: bool, text: str = "") -> None:
        nonlocal done
        done += 1
        if not ok:
            failed.append(name)
            print(f"simulator fleet: {name} failed: {text.strip().splitlines()[-1] if text.strip() else 'no message'}",
                  file=sys.stderr)
        elif not quiet and (done % max(1, len(todo) // 20) == 0 or done == len(todo)):
            print(f"... {done}/{len(todo)} units captured ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)

    if jobs <= 1 or len(todo) <= 1:
        for s in todo:
            try:
                capture_unit(s, str(out), hits)
                report(s.name, True)
            except _CaptureFailed as exc:
                report(exc.name, False, exc.text)
        return failed
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")          # one core per process
    with concurrent.futures.ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = {pool.submit(capture_unit, s, str(out), hits): s.name for s in todo}
        for fut in concurrent.futures.as_completed(futures):
            try:
                fut.result()
                report(futures[fut], True)
            except _CaptureFailed as exc:
                report(exc.name, False, exc.text)
    return failed


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(build_parser(), argv)
    if isinstance(args, int):
        return args
    with errors_to_exit("simulator fleet", ValueError):
        if args.hits < 1 or args.jobs < 1:
            raise ValueError("--hits and --jobs must be at least 1")
        specs = plan_fleet(args.units, args.scatter / 100.0, args.defects, args.seed)
    out = Path(args.out)
    with errors_to_exit("simulator fleet", ValueError):
        conflict = fleet_folder_conflict(out, specs)
        if conflict:
            made = recorded_plan(out)
            raise ValueError(f"{out} holds another fleet ({conflict}): nothing captured, truth.json unchanged; "
                             + (f"complete it with the options it was made with ({made}) " if made else
                                "complete it with the options it was made with ")
                             + "or give a new --out folder")
    with errors_to_exit("simulator fleet", OSError, prefix="cannot create the output folder: "):
        (out / "configs").mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    failed = _run(specs, out, args.hits, args.jobs, bool(args.quiet))
    truth = {"schema": "impactlab.fleet-truth/1", "scatter_pct": args.scatter, "seed": args.seed,
             "defects": args.defects, "hits": args.hits, "units": [s.truth(f"{s.name}.h5") for s in specs]}
    write_json_atomic(out / "truth.json", truth)
    bad = sum(s.defect is not None for s in specs)
    print(f"fleet of {len(specs)} units ({bad} defective, scatter +-{args.scatter:g} %) in {out}: "
          f"{len(specs) - len(failed)} recordings, truth.json, {time.perf_counter() - t0:.1f} s")
    if failed:
        print(f"simulator fleet: {len(failed)} capture(s) failed: {', '.join(failed)}; run the same command again "
              "to retry them", file=sys.stderr)
        return 1
    return 0
