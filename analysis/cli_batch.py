"""``python -m analysis batch INPUTS... --out DIR``: fit many tests on Dask, flag the odd units.

Every input (recordings or UFF 58 files; shell globs, or quoted patterns expanded here) gets the
automatic fit of ``analysis fit`` on a Dask cluster: by default a ``LocalCluster`` of worker
processes, one per core (``--workers N`` to choose); ``--scheduler tcp://HOST:PORT`` (or a scheduler
file) uses a cluster started with Dask's own commands::

    dask scheduler --host 10.0.0.5 --port 8786             # on one machine
    dask worker tcp://10.0.0.5:8786 --nworkers 4 --nthreads 1   # on each machine (same impactlab installed,
                                                            # the inputs and DIR on a shared file system)

DIR gets ``fits/<unit>.json`` (the ``analysis fit --json`` document of each input, with its content
hash), ``modes.parquet`` (one row per input and mode), ``fleet.json`` and ``fleet.png`` (modes
paired across units, each mode's distribution, the flagged units with the reasons). ``--reference
FIT.json`` pairs modes to a reference fit; without it the fleet's median unit is the reference.
Running the same command again reuses every result whose input content and options are unchanged.
Exit status: 0 every input has a result (a bad input's result is an error row), 1 some inputs
have none (the cluster gave up on them; run again), 2 bad usage.
"""
from __future__ import annotations

import argparse
import glob
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from .command_line import Parser, add_threads, cli_entry, errors_to_exit, exit_on, parse_args, with_examples
from .errors import UsageError
from .inputs import InputError, parse_band_text
from .outputs import check_outputs
from .threads import ENV_VAR as THREADS_ENV_VAR

__all__ = ["main", "build_parser", "expand_inputs"]


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="python -m analysis batch", description=__doc__.splitlines()[0])
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="recordings (.h5) or UFF 58 files; globs allowed")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="a running Dask scheduler: tcp://HOST:PORT, or the file of 'dask scheduler --scheduler-file'")
    where.add_argument("--workers", type=int, metavar="N", help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--dashboard", nargs="?", const="127.0.0.1:8787", metavar="HOST:PORT",
                   help="serve Dask's dashboard for the local cluster (default address 127.0.0.1:8787); off unless given")
    p.add_argument("--reference", metavar="FIT.json",
                   help="pair modes to this fit ('analysis fit --json' of a good unit); default: the fleet's median unit")
    p.add_argument("--band", metavar="LO:HI", help="fit band in Hz for every input (default: each input's own, from its data)")
    p.add_argument("--estimator", choices=("H1", "H2"), default=None, help="FRF estimate of recordings (default: their own)")
    p.add_argument("--z-limit", type=float, default=6.0,
                   help="flag a mode shift beyond this many robust standard deviations (default 6)")
    p.add_argument("--min-shift", type=float, default=0.5, metavar="PCT",
                   help="... and beyond PCT %% (default 0.5): both must hold")
    add_threads(p)
    return with_examples(p)


def _not_regular(path: Path) -> str | None:
    """Why a glob match is not an input file (a folder, a dangling or looping link...), or None."""
    try:
        st = path.stat()
    except OSError as exc:
        if path.is_symlink():
            return "a symbolic link that loops" if getattr(exc, "errno", None) == 40 else "a dangling symbolic link"
        return exc.strerror or "unreadable"
    from .input_limits import not_regular_kind

    return not_regular_kind(st.st_mode)


def expand_inputs(items: Sequence[str], skipped: list[str] | None = None) -> list[Path]:
    """Paths of the inputs: each item a file or a glob pattern; a pattern that matches nothing and a
    missing file are errors that name them. Glob matches that are not regular files are left out,
    each named with the reason in ``skipped``."""
    out: list[Path] = []
    for item in items:
        if any(ch in item for ch in "*?["):
            found = sorted(glob.glob(item))
            if not found:
                raise InputError(f"no input matches {item!r}: check the pattern")
            for f in found:
                why = _not_regular(Path(f))
                if why is None:
                    out.append(Path(f))
                elif skipped is not None:
                    skipped.append(f"{f} ({why})")
        elif Path(item).is_dir():
            raise InputError(f"{item} is a folder: give its files, e.g. '{item}/*.h5'")
        elif not Path(item).exists():
            raise InputError(f"input {item} not found: check the path")
        elif (why := _not_regular(Path(item))) is not None:
            raise InputError(f"input {item} is {why}, not a regular file: give recordings (.h5) or UFF 58 files")
        else:
            out.append(Path(item))
    if not out:
        raise InputError("no input files: give recordings (.h5) or UFF 58 files")
    return out


def _progress(quiet: bool, t0: float) -> Callable[[dict[str, Any], int, int], None]:
    failed = 0

    def show(doc: dict[str, Any], done: int, total: int) -> None:
        nonlocal failed
        if doc.get("status") != "ok":
            failed += 1
            if not quiet:
                print(f"... {doc.get('input')}: {doc.get('error')}", file=sys.stderr)
        if not quiet and (done == total or done % max(1, total // 20) == 0):
            print(f"... {done}/{total} fitted, {failed} failed ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)

    return show


def _written(out: Path) -> list[Path]:
    """The files a batch writes into ``out`` (its fits: those already there)."""
    fits = sorted((out / "fits").glob("*.json")) if (out / "fits").is_dir() else []
    return [out / "modes.parquet", out / "fleet.json", out / "fleet.png", *fits]


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(build_parser(), argv)
    if isinstance(args, int):
        return args
    from .batch.unit_modes import read_reference

    skipped: list[str] = []
    with errors_to_exit("analysis batch", (InputError, UsageError)):
        paths = expand_inputs(args.inputs, skipped)
        check_outputs(_written(Path(args.out)), [*paths, args.reference])
        if skipped:
            print(f"analysis batch: skipped {len(skipped)} match(es) that are not regular files: "
                  f"{', '.join(skipped[:10])}{' ...' if len(skipped) > 10 else ''}", file=sys.stderr)
        band = parse_band_text(args.band) if args.band else None
        reference = read_reference(args.reference) if args.reference else None
        if args.workers is not None and args.workers < 1:
            raise InputError("--workers must be at least 1")
    # Dask's own log lines (worker start and stop) only with -v; workers inherit the setting
    os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "info" if args.verbose else "error")
    if args.threads is not None:  # the local cluster's worker processes inherit it
        os.environ[THREADS_ENV_VAR] = str(args.threads)
    out = Path(args.out)
    with errors_to_exit("analysis batch", OSError, prefix="cannot create the output folder: "):
        out.mkdir(parents=True, exist_ok=True)
    from .batch.out_lock import FolderLock

    with errors_to_exit("analysis batch", OSError, code=1):
        lock = FolderLock(out)
    try:
        return _run(args, paths, skipped, out, band, reference)
    finally:
        lock.release()


def _run(args: argparse.Namespace, paths: list[Path], skipped: list[str], out: Path, band: Any, reference: Any) -> int:
    from .atomic import write_json_atomic
    from .batch.fleet import assess_fleet
    from .batch.outputs import fleet_document, modes_rows, plot_fleet, write_modes_parquet
    from .batch.run import close_client, open_client, plan_inputs, run_batch
    from .batch.unit_modes import modes_from_fit

    inputs = plan_inputs(paths)
    t0 = time.perf_counter()
    unreachable = "cannot reach the Dask scheduler (check the address, and that 'dask scheduler' runs there): "
    with exit_on("analysis batch", (ImportError, 2), (OSError, 1, unreachable)):
        client = open_client(args.scheduler, args.workers, dashboard=args.dashboard)
    try:
        if not args.quiet:
            n = len(client.scheduler_info().get("workers", {}))
            print(f"... {len(inputs)} inputs on {n} Dask worker(s) at {client.scheduler.address}", file=sys.stderr)
            if args.dashboard:
                print(f"... Dask dashboard: {client.dashboard_link}", file=sys.stderr)
        run = run_batch(inputs, out, client, band=band, estimator=args.estimator, on_result=_progress(args.quiet, t0))
    finally:
        close_client(client)
    units = [modes_from_fit(d["fit"]) if d.get("status") == "ok" else None for d in run.results]
    errors = [d.get("error") for d in run.results]
    files = [i.path.name for i in inputs]
    with errors_to_exit("analysis batch", ValueError, code=1):
        fleet = assess_fleet(units, [i.name for i in inputs], files, reference=reference,
                             reference_name=str(args.reference or ""), errors=errors,
                             z_limit=args.z_limit, min_shift_pct=args.min_shift)
    if reference is None:            # the fleet's median unit
        reference = next(u for u, f in zip(units, fleet.units) if f.name == fleet.reference and u is not None)
    ref_f = reference.freq_hz
    wall = time.perf_counter() - t0
    info = {"inputs": len(inputs), "fitted": run.fitted, "reused": run.reused, "failed": run.failed,
            "flagged": sum(u.flagged for u in fleet.units), "seconds": round(wall, 3),
            "fit_seconds": round(run.fit_seconds, 3), "workers": run.workers, "scheduler": run.where}
    with errors_to_exit("analysis batch", (OSError, ValueError), code=1, prefix="cannot write the outputs: "):
        write_modes_parquet(out / "modes.parquet", modes_rows(fleet, units, files, ref_f))
        write_json_atomic(out / "fleet.json", fleet_document(fleet, info))
        plot_fleet(out / "fleet.png", fleet)
    for u in fleet.units:
        if u.flagged:
            print(f"flagged {u.name}: " + "; ".join(u.reasons[:3]) + (" ..." if len(u.reasons) > 3 else ""))
    print(f"batch of {len(inputs)}{f' ({len(skipped)} non-file matches skipped)' if skipped else ''}: "
          f"{len(inputs) - run.failed} done ({run.fitted} fitted, {run.reused} reused), "
          f"{run.failed} failed, {info['flagged']} flagged; {wall:.1f} s on {run.workers} worker(s) "
          f"(fits {run.fit_seconds:.1f} s of work); results in {out}/ (fits/, modes.parquet, fleet.json, fleet.png)")
    if run.lost:
        print(f"analysis batch: {len(run.lost)} input(s) have no result (the cluster gave up on them): "
              f"{', '.join(run.lost[:5])}; run the same command again to retry them", file=sys.stderr)
        return 1
    return 0
