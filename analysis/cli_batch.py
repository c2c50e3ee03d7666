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
``--diagnose SIM`` (the fleet's frame config ``.toml`` or a good unit's recording) then diagnoses every
flagged unit on the same workers (``analysis diagnose --measured UNIT --simulated SIM``), stores each in
``diagnoses/<unit>.json`` (reused like the fits), and adds ``units[i].diagnosis`` to ``fleet.json``;
a SIM that is not the fleet's structure (other points, or resonances that do not pair with the first
unit's) is refused (exit 2) before the cluster starts and any fit runs.
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
from dataclasses import dataclass
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
    p.add_argument("--diagnose", metavar="SIM",
                   help="diagnose every flagged unit against SIM: the fleet's frame config (.toml) or a good "
                        "unit's recording (as 'analysis diagnose --measured UNIT --simulated SIM')")
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
    """The files a batch writes into ``out`` (its fits and diagnoses: those already there)."""
    stored = [p for d in ("fits", "diagnoses") if (out / d).is_dir() for p in sorted((out / d).glob("*.json"))]
    return [out / "modes.parquet", out / "fleet.json", out / "fleet.png", *stored]


@dataclass(frozen=True)
class SimCheck:
    """The ``--diagnose SIM`` of a batch, checked against the fleet's structure: the SIM's path, its
    content hash, what the modes check needs (a simulator config's FE model at the fleet's points,
    or None for a recording or UFF file, whose modes come from its fit) and the fleet's band (Hz)."""

    path: Path
    sha256: str
    variants: Any
    band_hz: tuple[float, float]


def check_sim_points(sim: str, inputs: Sequence[Path], estimator: str | None,
                     band: tuple[float, float] | None) -> SimCheck:
    """Refuse (InputError, one line) a ``--diagnose`` SIM whose points or frequency range are not the
    fleet's, before any work: compared with the first input that loads (a simulator config must have
    the fleet's points as nodes; an FRF file the same outputs and references, and lines covering the
    fleet's band). No input loads: nothing to compare with, the check is left to the modes."""
    from .batch.diagnose import structure_problem
    from .batch.task import file_sha256
    from .cli_diagnose import load_simulations
    from .errors import ImpactlabError
    from .inputs import load_input

    p = Path(sim)
    if not p.is_file():
        raise InputError(f"--diagnose {sim}: not found: give the fleet's frame config (.toml) or a good unit's recording")
    measured = None
    for path in inputs:
        try:
            measured = load_input(str(path), estimator=estimator)
            break
        except (ImpactlabError, OSError, ValueError, KeyError):  # a bad input: its own error row later
            continue
    sha = file_sha256(p)
    if measured is None:
        return SimCheck(p, sha, None, band or (0.0, float("inf")))
    fleet_band = band or (float(measured.freq_hz[0]), float(measured.freq_hz[-1]))
    refuse = (f"--diagnose {sim} is not the fleet's structure: {{}}; give the fleet's frame config or a good "
              "unit's recording")
    simulated = load_simulations(str(p), measured, estimator)      # a config: raises for points it lacks
    if isinstance(simulated, Path):
        try:
            sim_frf = load_input(str(p), estimator=estimator)
        except (ImpactlabError, OSError, ValueError, KeyError) as exc:
            raise InputError(f"--diagnose {sim}: not readable ({exc}): give the fleet's frame config (.toml) "
                             "or a good unit's recording") from None
        why = structure_problem(measured.outputs, measured.references, fleet_band, sim_frf.outputs,
                                sim_frf.references, sim_frf.freq_hz, measured.line_spacing_hz)
        if why:
            raise InputError(refuse.format(why))
    why = _resonances_problem(measured, None if isinstance(simulated, Path) else simulated,
                              sim_frf if isinstance(simulated, Path) else None, band)
    if why:
        raise InputError(refuse.format(why))
    return SimCheck(p, sha, None if isinstance(simulated, Path) else simulated, fleet_band)


def _resonances_problem(measured: Any, physical: Any, sim_frf: Any, band: tuple[float, float] | None) -> str | None:
    """Why the SIM's resonances are not those of the fleet's first unit (``measured``), or None, before any
    fit: the peaks of the first CMIF curve (:func:`~analysis.batch.diagnose.peaks_problem`) of the unit in
    ``band`` (None: the band its data support, as its fit's) and of the SIM there: a simulation's
    (``physical``: its FRFs synthesised at the unit's points and lines) or a recording's (``sim_frf``)."""
    from .bands import default_band
    from .batch.diagnose import cmif_peaks_hz, peaks_problem
    from .diagnosis.effects import predict
    from .errors import ImpactlabError

    try:
        lo, hi = band or default_band(measured)
        unit = measured.band(lo, hi)
        sim = (predict(physical.model(None, {}), unit.freq_hz, unit.quantity) if physical is not None
               else sim_frf.band(lo, hi))
    except (ImpactlabError, ValueError):        # too few lines in the band: the unit's own fit says so in its row
        return None
    return peaks_problem(cmif_peaks_hz(unit), cmif_peaks_hz(sim))


def sim_modes(check: SimCheck, client: Any, band: tuple[float, float] | None, estimator: str | None) -> Any:
    """The SIM's modes as :class:`~analysis.batch.unit_modes.UnitModes`: a config's FE modes in the
    fleet's band at the fleet's points (shapes: the products with the first reference), or the fit of
    a recording (on the cluster, as a fleet unit's). InputError when the SIM has none."""
    import numpy as np

    from .batch.task import fit_one
    from .batch.unit_modes import UnitModes, modes_from_fit

    v = check.variants
    if v is not None:
        f, products = v.modes(None, {}, check.band_hz[1])
        keep = f >= check.band_hz[0]
        shapes = np.asarray(products).reshape(len(v.outputs), len(v.references), -1)[:, 0, :][:, keep]
        nan = np.full(int(keep.sum()), np.nan)
        return UnitModes(freq_hz=np.asarray(f)[keep], damping=nan, freq_std_hz=nan, damping_std=nan,
                         shapes=shapes.astype(complex), outputs=tuple(v.outputs))
    doc = client.submit(fit_one, str(check.path), "simulated", check.sha256, band, estimator, pure=False).result()
    if doc.get("status") != "ok":
        raise InputError(f"--diagnose {check.path}: its fit failed ({doc.get('error')}): give a good unit's recording")
    return modes_from_fit(doc["fit"])


#: the simulations a worker process built for the flagged units it diagnosed, by what they depend on: the
#: SIM's content (SHA-256), the measured points and the FRF estimator (:func:`shared_simulation`)
_SIMULATIONS: dict[tuple[str, tuple[str, ...], tuple[str, ...], str | None], Any] = {}
#: simulations kept per process (a worker of a shared cluster may serve batches against other SIMs)
_SIMULATIONS_KEPT = 2


def shared_simulation(path: str, measured: Any, estimator: str | None = None) -> Any:
    """:func:`~analysis.cli_diagnose.load_simulations` once per SIM content and measured points in this
    process: every flagged unit of a fleet is compared with the same SIM, so what depends on it alone (the
    FE model's parts, its nominal and finer-mesh modes, the Ritz bases and factorizations of every cause
    at every place, the answers of the screens' grids, kept by the simulation) is built by a worker once
    and used for every unit it diagnoses. The diagnosis never changes the simulation (its answers are
    functions of their arguments), so a unit's result is the same as with a simulation of its own."""
    from .batch.task import file_sha256
    from .cli_diagnose import load_simulations

    key = (file_sha256(path), tuple(measured.outputs), tuple(measured.references), estimator)
    sim = _SIMULATIONS.get(key)
    if sim is None:
        sim = load_simulations(path, measured, estimator)
        if isinstance(sim, Path):                   # an FRF file: read with the unit, nothing to keep
            return sim
        while len(_SIMULATIONS) >= _SIMULATIONS_KEPT:
            _SIMULATIONS.pop(next(iter(_SIMULATIONS)))
        _SIMULATIONS[key] = sim
    return sim


def fleet_simulation(path: str, measured: Any, estimator: str | None = None) -> Any:
    """The worker's simulation of the SIM (:func:`shared_simulation`) as a fleet's flagged unit is compared
    with: its global cause scales every stiffness alike, as the fleet's scatter does
    (:func:`~analysis.batch.scatter.for_fleet`)."""
    from .batch.scatter import for_fleet

    return for_fleet(shared_simulation(path, measured, estimator))


def diagnose_unit(measured: str, simulated: str, *, band: Sequence[float] | None = None,
                  estimator: str | None = None) -> Any:
    """A flagged unit's diagnosis on a worker: :func:`~analysis.cli_diagnose.run_diagnosis` with the
    worker's simulation of the SIM as a fleet's unit is compared with (:func:`fleet_simulation`)."""
    from .cli_diagnose import run_diagnosis

    return run_diagnosis(measured, simulated, band=band, estimator=estimator, load=fleet_simulation)


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(build_parser(), argv)
    if isinstance(args, int):
        return args
    from .batch.unit_modes import read_reference

    skipped: list[str] = []
    with errors_to_exit("analysis batch", (InputError, UsageError)):
        paths = expand_inputs(args.inputs, skipped)
        check_outputs(_written(Path(args.out)), [*paths, args.reference, args.diagnose])
        if skipped:
            print(f"analysis batch: skipped {len(skipped)} match(es) that are not regular files: "
                  f"{', '.join(skipped[:10])}{' ...' if len(skipped) > 10 else ''}", file=sys.stderr)
        band = parse_band_text(args.band) if args.band else None
        reference = read_reference(args.reference) if args.reference else None
        if args.workers is not None and args.workers < 1:
            raise InputError("--workers must be at least 1")
        sim = check_sim_points(args.diagnose, paths, args.estimator, band) if args.diagnose else None
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
        return _run(args, paths, skipped, out, band, reference, sim)
    finally:
        lock.release()


def _run(args: argparse.Namespace, paths: list[Path], skipped: list[str], out: Path, band: Any, reference: Any,
         sim: SimCheck | None) -> int:
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
        units = [modes_from_fit(d["fit"]) if d.get("status") == "ok" else None for d in run.results]
        errors = [d.get("error") for d in run.results]
        files = [i.path.name for i in inputs]
        with errors_to_exit("analysis batch", ValueError, code=1):
            fleet = assess_fleet(units, [i.name for i in inputs], files, reference=reference,
                                 reference_name=str(args.reference or ""), errors=errors,
                                 z_limit=args.z_limit, min_shift_pct=args.min_shift)
        if reference is None:            # the fleet's median unit
            reference = next(u for u, f in zip(units, fleet.units) if f.name == fleet.reference and u is not None)
        diag = _diagnose_flagged(args, sim, client, inputs, fleet, reference, band, out) if sim is not None else None
    finally:
        close_client(client)
    ref_f = reference.freq_hz
    wall = time.perf_counter() - t0
    info = {"inputs": len(inputs), "fitted": run.fitted, "reused": run.reused, "failed": run.failed,
            "flagged": sum(u.flagged for u in fleet.units), "seconds": round(wall, 3),
            "fit_seconds": round(run.fit_seconds, 3), "fit_cpu_seconds": round(run.fit_cpu_seconds, 3),
            "workers": run.workers, "scheduler": run.where}
    summaries: dict[str, Any] = {}
    phrases: dict[str, str] = {}
    if diag is not None:
        from .batch.diagnose import describe_diagnosis

        info.update(diagnosed=diag.done, diagnoses_reused=diag.reused, diagnosis_failed=diag.failed,
                    diagnosis_seconds=round(diag.seconds, 3), diagnosis_cpu_seconds=round(diag.cpu_seconds, 3),
                    simulated=str(sim.path if sim else ""))
        for name, doc in diag.results.items():
            summaries[name] = doc["diagnosis"] if doc.get("status") == "ok" else \
                {"verdict": "error", "named": [], "trace": [], "error": doc.get("error")}
            phrases[name] = describe_diagnosis(name, doc)
    with errors_to_exit("analysis batch", (OSError, ValueError), code=1, prefix="cannot write the outputs: "):
        write_modes_parquet(out / "modes.parquet", modes_rows(fleet, units, files, ref_f))
        write_json_atomic(out / "fleet.json", fleet_document(fleet, info, summaries))
        plot_fleet(out / "fleet.png", fleet, [phrases[u.name] for u in fleet.units if u.name in phrases])
    for u in fleet.units:
        if u.flagged:
            print(f"flagged {u.name}: " + "; ".join(u.reasons[:3]) + (" ..." if len(u.reasons) > 3 else ""))
            if u.name in phrases:
                print(phrases[u.name])
    diag_text = "" if diag is None else (f"; {diag.done + diag.reused} flagged unit(s) diagnosed ({diag.done} new, "
                                         f"{diag.reused} reused, {diag.failed} failed; {diag.seconds:.1f} s of work)")
    print(f"batch of {len(inputs)}{f' ({len(skipped)} non-file matches skipped)' if skipped else ''}: "
          f"{len(inputs) - run.failed} done ({run.fitted} fitted, {run.reused} reused), "
          f"{run.failed} failed, {info['flagged']} flagged; {wall:.1f} s on {run.workers} worker(s) "
          f"(fits {run.fit_seconds:.1f} s of work){diag_text}; results in {out}/ "
          f"(fits/, {'diagnoses/, ' if diag is not None else ''}modes.parquet, fleet.json, fleet.png)")
    lost = run.lost + (diag.lost if diag is not None else [])
    if lost:
        print(f"analysis batch: {len(lost)} task(s) have no result (the cluster gave up on them): "
              f"{', '.join(lost[:5])}; run the same command again to retry them", file=sys.stderr)
        return 1
    return 0


@dataclass
class _Diagnoses:
    """The flagged units' diagnoses of a run: result documents by unit name, counts, and the new
    diagnoses' wall and CPU times summed (s)."""

    results: dict[str, dict[str, Any]]
    done: int
    reused: int
    failed: int
    seconds: float
    cpu_seconds: float
    lost: list[str]


def _diagnose_flagged(args: argparse.Namespace, sim: SimCheck, client: Any, inputs: Sequence[Any], fleet: Any,
                      reference: Any, band: Any, out: Path) -> _Diagnoses:
    """Check the SIM's modes against the fleet's reference modes (exit 2 in one line before any
    diagnosis when they do not pair), then diagnose each flagged unit on the cluster: a stored result
    for the same unit content, SIM and options is reused; each new one is written to
    ``diagnoses/<unit>.json`` as it arrives."""
    from .atomic import write_json_atomic
    from .batch.diagnose import DIAGNOSIS_SCHEMA, diagnose_one, diagnosis_is_current, diagnosis_key, modes_problem
    from .batch.run import run_tasks

    with errors_to_exit("analysis batch", InputError):
        why = modes_problem(reference, sim_modes(sim, client, band, args.estimator))
        if why:
            raise InputError(f"--diagnose {sim.path} is not the fleet's structure: {why}; give the fleet's frame "
                             "config or a good unit's recording")
    folder = out / "diagnoses"
    folder.mkdir(parents=True, exist_ok=True)
    key = diagnosis_key(sim.sha256, band, args.estimator)
    flagged = {u.name for u in fleet.units if u.flagged and u.status == "ok"}
    targets = [i for i in inputs if i.name in flagged]
    have = {i.name: d for i in targets if (d := diagnosis_is_current(folder / i.result_file, i.sha256, key)) is not None}
    todo = [i for i in targets if i.name not in have]
    by_name = {i.name: i for i in todo}
    tasks = [(i.name, f"impactlab-diagnose-{i.name}-{i.sha256[:12]}-{key}", diagnose_one,
              (str(i.path), i.name, i.sha256, str(sim.path), key, diagnose_unit, band, args.estimator)) for i in todo]

    def store(name: str, doc: dict[str, Any]) -> None:
        write_json_atomic(folder / by_name[name].result_file, doc)

    def lost(name: str, exc: BaseException) -> dict[str, Any]:
        i = by_name[name]
        return {"schema": DIAGNOSIS_SCHEMA, "input": name, "path": str(i.path), "sha256": i.sha256, "key": key,
                "status": "error", "error": f"the task failed on the cluster ({type(exc).__name__}: {exc}); "
                                            "run the same command again to retry it", "diagnosis": None, "seconds": 0.0}

    def progress(doc: dict[str, Any], done: int, total: int) -> None:
        if not args.quiet:
            print(f"... {done}/{total} diagnosed ({doc.get('input')}: "
                  f"{(doc.get('diagnosis') or {}).get('verdict') or doc.get('error')})", file=sys.stderr)

    if todo and not args.quiet:
        print(f"... diagnosing {len(todo)} flagged unit(s) against {sim.path} ({len(have)} reused)", file=sys.stderr)
    got, gone = run_tasks(client, tasks, store, lost, progress)
    results = {i.name: (have.get(i.name) or got[i.name]) for i in targets}
    return _Diagnoses(results=results, done=len(todo) - len(gone), reused=len(have),
                      failed=sum(d.get("status") != "ok" for d in results.values()),
                      seconds=float(sum(float(got[n].get("seconds") or 0.0) for n in got)),
                      cpu_seconds=float(sum(float(got[n].get("cpu_seconds") or 0.0) for n in got)), lost=gone)
