"""``python -m analysis diagnose --measured M [M2 ...] [--levels L1,L2,...] --simulated S [--json OUT.json] [--report DIR]``.

M is a recording (``.h5``) or a UFF 58 file; several, with ``--levels`` (one drive level each), are one
structure measured at several drive levels: the lowest level is compared with S, and the levels with one
another mode by mode (:func:`analysis.diagnosis.joint_nonlinearity.measured_levels`); modes that move beyond
their uncertainty are named ``joint_nonlinearity`` (an amplitude-dependent stiffness and damping) with
their shifts per level. S is a recording or UFF 58 file with the same points
(matched by ``component:node:direction`` labels of outputs and references), or a simulator
configuration (``.toml``), simulated on the fly at M's points and lines; then the physical causes
(:mod:`simulator.physical`: added mass, support and joint stiffness, member mass and stiffness,
accelerometer mass, modulus) are fitted by re-running the FE model. A TOML with an ``[fe]`` table is the
user's own FE model (:mod:`analysis.fe_model`: Matrix Market K and M, a DOF map) with the causes of any FE
model. The kinds of simulation are the rows of :data:`SIMULATION_KINDS`. A simulated FRF file is
first turned into a modal model by the automatic fit (:func:`analysis.pipeline.fit_auto`), so the
modal effects can act on it. Exit codes: 0 done, 2 bad input (message on stderr), 1 an FE model whose
files cannot be used (one line naming the file and row).
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from simulator.physical import FrameVariants

    from .diagnosis import Diagnosis
    from .diagnosis.joint_nonlinearity import JointSimulation, JointSimulationFactory
    from .fe_model import FEVariants
    from .frf import FRFSet

from .command_line import Parser as _Parser
from .command_line import add_estimator, add_threads, check_out_dir, cli_entry, parse_args, with_examples
from .outputs import check_outputs

__all__ = ["main", "build_parser", "load_simulations", "joint_simulation", "run_diagnosis", "SIMULATION_KINDS",
           "simulation_kind"]

log = logging.getLogger(__name__)


def _json_default(x: Any) -> Any:
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"{type(x).__name__} is not JSON serialisable")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="python -m analysis diagnose",
                description="Compare a measurement with a simulation, name the physical cause of the "
                            "difference from a catalogue of effects, extend the model and measure the gain.")
    with_examples(p)
    p.add_argument("--measured", required=True, nargs="+", metavar="M",
                   help="recording (.h5) or UFF 58 file; or several, one structure at several drive levels "
                        "(with --levels)")
    p.add_argument("--levels", metavar="LA,LB,...",
                   help="the drive level of each --measured file, in their order (any unit: N, V...): the lowest "
                        "level is compared with the simulation, the levels with one another (an amplitude-"
                        "dependent stiffness and damping is named joint_nonlinearity)")
    p.add_argument("--simulated", required=True, metavar="S",
                   help="recording or UFF 58 file with the same points, a simulator config (.toml), or "
                        "a TOML with an [fe] table: your own FE model (Matrix Market K, M and a DOF map)")
    p.add_argument("--json", metavar="OUT.json",
                   help="also write the diagnosis as JSON (default: the verdict on the terminal only)")
    p.add_argument("--report", metavar="DIR", help="write report.md and plots into DIR")
    p.add_argument("--band", metavar="LO:HI",
                   help="frequency band in Hz (default: from the data: the analyser's band, the hammer's "
                        "excitation band and the coherence)")
    p.add_argument("--effects", metavar="A,B,...", help="only these effects of the catalogue")
    add_estimator(p)
    add_threads(p)
    return p


def _is_fe_config(path: Path) -> bool:
    from .fe_model import is_fe_config

    return is_fe_config(path)


def _is_frame_config(path: Path) -> bool:
    return path.suffix.lower() == ".toml"


def _fe_simulation(path: Path, measured: FRFSet) -> FEVariants:
    """The user's FE model (:class:`analysis.fe_model.FEVariants`) at the measured points; its modes reach
    the model's ``[modes] max_freq_hz``, else twice the measurement's top line."""
    from .fe_model import FEVariants, load_fe_model

    fe = load_fe_model(path)
    return FEVariants(fe, measured.outputs, measured.references,
                      fe.max_freq_hz if fe.max_freq_hz is not None else 2.0 * float(measured.freq_hz[-1]))


def _frame_simulation(path: Path, measured: FRFSet) -> FrameVariants:
    """The simulator's frame of the config ``path`` split by physical cause at the measured points."""
    from simulator.config import ConfigError, FrameConfig
    from simulator.fem import ModelError
    from simulator.physical import FrameVariants, check_diagnosis_size

    from .inputs import InputError

    try:
        config = FrameConfig.load(path)
        check_diagnosis_size(config)
        return FrameVariants(config, measured.outputs, measured.references)
    except (ConfigError, ModelError, OSError) as exc:
        raise InputError(f"simulator config {path}: {exc}") from None


#: The kinds of simulation ``--simulated`` accepts, tried in order: (name, is it this kind?, the simulation
#: built at the measured points). A path no row claims is an FRF file, read by the library.
SIMULATION_KINDS: tuple[tuple[str, Callable[[Path], bool], Callable[[Path, FRFSet], Any]], ...] = (
    ("fe_model", _is_fe_config, _fe_simulation),
    ("frame_config", _is_frame_config, _frame_simulation),
)


def simulation_kind(path: str) -> str:
    """The name of the row of :data:`SIMULATION_KINDS` that claims ``path``; ``"frf_file"`` when none does."""
    return next((name for name, claims, _ in SIMULATION_KINDS if claims(Path(path))), "frf_file")


def load_simulations(path: str, measured: FRFSet, estimator: str | None = None) -> Any:
    """The simulation for :func:`analysis.diagnosis.diagnose`: the row of :data:`SIMULATION_KINDS` that
    claims ``path`` builds it at the measured points (a simulator config: its FE model split by physical
    cause, :class:`simulator.physical.FrameVariants`; a TOML with ``[fe]``: the user's FE model,
    :class:`analysis.fe_model.FEVariants`); otherwise the path itself (an FRF file, read by the library)."""
    p = Path(path)
    for _, claims, build in SIMULATION_KINDS:
        if claims(p):
            return build(p, measured)
    return p


def joint_simulation(path: str) -> JointSimulationFactory | None:
    """For a simulator config (``.toml`` without ``[fe]``): the factory that re-simulates the recorded test's hits with
    :class:`simulator.nonlinear_simulation.JointHitSimulation` (the ``joint_nonlinearity`` cause); None
    for FRF files."""
    if simulation_kind(path) != "frame_config":
        return None

    def build(hits: Sequence[Any], levels: Sequence[float], sets: Sequence[FRFSet]) -> JointSimulation:
        from simulator.nonlinear_simulation import JointHitSimulation

        points = tuple(dict.fromkeys(h.point for h in hits))
        return JointHitSimulation(path, points, hits[0].outputs, levels, hits[0].fs_hz, hits[0].force.size,
                                  hits[0].trigger_index, sets[0].quantity, sets[0].unit)

    return build


def run_diagnosis(measured_path: str | Path | Sequence[str | Path], simulated_path: str | Path, *,
                  band: Sequence[float] | None = None, effects: Sequence[str] | None = None,
                  estimator: str | None = None, levels: Sequence[float] | None = None,
                  load: Callable[[str, FRFSet, str | None], Any] | None = None) -> Diagnosis:
    """The diagnosis of ``python -m analysis diagnose --measured M --simulated S``: load M (a recording
    or UFF 58 file, FRFs by ``estimator``), S (an FRF file, or a simulator config simulated at M's
    points), and compare them in ``band`` (Hz; None: the band the data support) with the catalogue's
    ``effects`` (None: all). With ``levels``: M is one file per drive level (``--measured A B --levels
    LA,LB``), the lowest compared with S and the levels with one another. ``load(S, M, estimator)``
    builds S at M's points (None: :func:`load_simulations`; a batch hands one that keeps what it built
    for the next unit). Raises the library's errors (InputError, EffectError, ValueError, FitError) for
    bad input."""
    from .diagnosis import EFFECTS, diagnose
    from .inputs import InputError, load_input

    paths = [measured_path] if isinstance(measured_path, (str, Path)) else list(measured_path)
    if levels is None and len(paths) != 1:
        raise InputError(f"{len(paths)} measured files: give --levels (one drive level per file) to compare one "
                         "structure at several levels, or one --measured file")
    if levels is not None and len(levels) != len(paths):
        raise InputError(f"--levels gives {len(levels)} level(s) for {len(paths)} measured file(s): give one level "
                         "per file, in their order")
    if levels is not None and len(paths) < 2:
        raise InputError("--levels needs at least two --measured files (one per drive level)")
    lowest = str(paths[int(np.argmin(levels))] if levels is not None else paths[0])
    measured = load_input(lowest, estimator=estimator)
    simulated = (load or load_simulations)(str(simulated_path), measured, estimator)
    if effects is not None and hasattr(simulated, "causes"):
        # the catalogue's effects and the simulation's own physical causes
        known = [*EFFECTS, *(c.name for c in simulated.causes() if c.name not in EFFECTS)]
        bad = [e for e in effects if e not in known]
        if bad:
            raise InputError(f"unknown effect(s) {bad}; the catalogue has {', '.join(known)}")
    common: dict[str, Any] = {"band": tuple(band) if band is not None else "data",
                              "effects": list(effects) if effects is not None else None, "estimator": estimator,
                              "joint_simulation": joint_simulation(str(simulated_path))}
    if levels is not None:
        return diagnose([str(p) for p in paths], simulated, levels=list(levels), **common)
    return diagnose(measured, simulated, recording=_recording(lowest), **common)


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    """Run the command; returns the exit code (0 done, 2 bad input)."""
    from .bands import FitError
    from .diagnosis import EFFECTS, EffectError
    from .diagnosis.param_range import parameters_text
    from .diagnosis.rule import why_lines
    from .errors import FEModelError
    from .inputs import InputError, parse_band_text, parse_float_list

    parser = build_parser()
    args = parse_args(parser, argv)
    if isinstance(args, int):
        return args
    try:
        if args.json:
            check_out_dir(args.json, error=InputError)
        check_outputs([args.json, *_report_files(args.report)], [*args.measured, args.simulated])
        effects = None
        if args.effects:
            effects = [e.strip() for e in args.effects.split(",") if e.strip()]
            bad = [e for e in effects if e not in EFFECTS]
            # an FE simulation's physical causes are checked once it is loaded (run_diagnosis)
            if bad and simulation_kind(args.simulated) == "frf_file":
                raise InputError(f"unknown effect(s) {bad}; the catalogue has {', '.join(EFFECTS)}")
        levels = parse_float_list(args.levels, "levels") if args.levels else None
        diag = run_diagnosis(args.measured, args.simulated, band=parse_band_text(args.band), effects=effects,
                             estimator=args.estimator, levels=levels)
    except FEModelError as exc:
        print(f"analysis diagnose: {exc}", file=sys.stderr)
        return 1
    except (InputError, EffectError, ValueError, FitError) as exc:
        print(f"analysis diagnose: {exc}", file=sys.stderr)
        return 2
    doc = diag.to_json()
    if args.json:
        from .atomic import write_text_atomic

        write_text_atomic(args.json, json.dumps(doc, indent=1, default=_json_default))
    if args.report:
        from .diagnosis.report import write_report

        write_report(diag, args.report)
    for c in diag.time_data:
        if c["present"]:
            print(f"  time data ({c['reference']}): {c['evidence']}")
    if diag.level_dependence is not None and "cause" in diag.level_dependence:
        print(f"  level dependence: {diag.level_dependence['cause']['evidence']}")
        for row in diag.level_dependence["cause"].get("per_level", []):
            print(f"    level {row['level']:.4g}: " + ", ".join(
                f"{m['freq_hz']:.4g} Hz {m['df_percent']:+.2f} % (+-{m['df_std_percent']:.2f})"
                for m in row["modes"] if m["determined"]))
    print(f"verdict: {doc['verdict']}" + (f" ({diag.reason})" if diag.reason else ""))
    for c in diag.named:
        print(f"  named: {c['effect']} ({parameters_text(c['parameters'])})")
    print("why this verdict:")
    for line in why_lines(diag.trace):
        print(f"  {line}")
    if diag.next_measurement:
        nm = diag.next_measurement
        print(f"  next measurement: {nm['point']} ({nm['why']}; {nm['separation_db']:.1f} dB apart)")
    print(f"error before {diag.error_before_db:.1f} dB, after {diag.error_after_db:.1f} dB "
          f"(noise {diag.noise_level_db:.1f} dB)")
    for c in diag.causes[:5]:
        print(f"  {'*' if c['significant'] else ' '} {c['evidence']}" + ("" if c["significant"] else NOT_SIGNIFICANT))
    from .diagnosis.effect_types import NOT_APPLICABLE

    for name, why in diag.skipped.items():
        if why.startswith(NOT_APPLICABLE):
            print(f"    {name}: {why}")
    return 0


def _report_files(folder: str | None) -> list[Path]:
    """The files ``--report DIR`` writes that can be named before the diagnosis runs (its FRF plots:
    those already there)."""
    if folder is None:
        return []
    out = Path(folder)
    return [out / "report.md", out / "diagnosis.json", out / "bands.png", *sorted(out.glob("frf_*.png"))]


#: the words after a cause of the list that is not significant (its held-out gain is too small to name it)
NOT_SIGNIFICANT = " (not significant)"


def _recording(path: str) -> Path | None:
    """``path`` when it is a recording (its hits feed the noise estimate and the time-data stage)."""
    from .inputs import detect_format

    return Path(path) if detect_format(path) == "recording" else None
