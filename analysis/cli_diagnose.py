"""``python -m analysis diagnose --measured M --simulated S [--json OUT.json] [--report DIR]``.

M is a recording (``.h5``) or a UFF 58 file. S is a recording or UFF 58 file with the same points
(matched by ``component:node:direction`` labels of outputs and references), or a simulator
configuration (``.toml``), simulated on the fly at M's points and lines; then the physical causes
(:mod:`simulator.physical`: added mass, support and joint stiffness, member mass and stiffness,
accelerometer mass, modulus) are fitted by re-running the FE model. A simulated FRF file is
first turned into a modal model by the automatic fit (:func:`analysis.pipeline.fit_auto`), so the
modal effects can act on it. Exit codes: 0 done, 2 bad input (message on stderr).
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from simulator.physical import FrameVariants

    from .diagnosis import Diagnosis
    from .diagnosis.joint_nonlinearity import JointSimulation, JointSimulationFactory
    from .frf import FRFSet

from .command_line import Parser as _Parser
from .command_line import add_estimator, add_threads, check_out_dir, cli_entry, parse_args, with_examples
from .outputs import check_outputs

__all__ = ["main", "build_parser", "load_simulations", "joint_simulation", "run_diagnosis"]

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
    p.add_argument("--measured", required=True, metavar="M", help="recording (.h5) or UFF 58 file")
    p.add_argument("--simulated", required=True, metavar="S",
                   help="recording or UFF 58 file with the same points, or a simulator config (.toml)")
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


def load_simulations(path: str, measured: FRFSet, estimator: str | None = None) -> Path | FrameVariants:
    """The simulation for :func:`analysis.diagnosis.diagnose`: for a simulator config (``.toml``) its FE
    model split by physical cause (:class:`simulator.physical.FrameVariants`) at the measured points;
    otherwise the path itself (an FRF file, read by the library)."""
    from .inputs import InputError

    p = Path(path)
    if p.suffix.lower() != ".toml":
        return p
    from simulator.config import ConfigError, FrameConfig
    from simulator.fem import ModelError
    from simulator.physical import FrameVariants, check_diagnosis_size

    try:
        config = FrameConfig.load(p)
        check_diagnosis_size(config)
        return FrameVariants(config, measured.outputs, measured.references)
    except (ConfigError, ModelError, OSError) as exc:
        raise InputError(f"simulator config {p}: {exc}") from None


def joint_simulation(path: str) -> JointSimulationFactory | None:
    """For a simulator config (``.toml``): the factory that re-simulates the recorded test's hits with
    :class:`simulator.nonlinear_simulation.JointHitSimulation` (the ``joint_nonlinearity`` cause); None
    for FRF files."""
    if Path(path).suffix.lower() != ".toml":
        return None

    def build(hits: Sequence[Any], levels: Sequence[float], sets: Sequence[FRFSet]) -> JointSimulation:
        from simulator.nonlinear_simulation import JointHitSimulation

        points = tuple(dict.fromkeys(h.point for h in hits))
        return JointHitSimulation(path, points, hits[0].outputs, levels, hits[0].fs_hz, hits[0].force.size,
                                  hits[0].trigger_index, sets[0].quantity, sets[0].unit)

    return build


def run_diagnosis(measured_path: str | Path, simulated_path: str | Path, *, band: Sequence[float] | None = None,
                  effects: Sequence[str] | None = None, estimator: str | None = None) -> Diagnosis:
    """The diagnosis of ``python -m analysis diagnose --measured M --simulated S``: load M (a recording
    or UFF 58 file, FRFs by ``estimator``), S (an FRF file, or a simulator config simulated at M's
    points), and compare them in ``band`` (Hz; None: the band the data support) with the catalogue's
    ``effects`` (None: all). Raises the library's errors (InputError, EffectError, ValueError, FitError)
    for bad input."""
    from .diagnosis import diagnose
    from .inputs import load_input

    measured = load_input(str(measured_path), estimator=estimator)
    simulated = load_simulations(str(simulated_path), measured, estimator)
    return diagnose(measured, simulated, band=tuple(band) if band is not None else "data",
                    effects=list(effects) if effects is not None else None, estimator=estimator,
                    recording=_recording(str(measured_path)), joint_simulation=joint_simulation(str(simulated_path)))


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    """Run the command; returns the exit code (0 done, 2 bad input)."""
    from .bands import FitError
    from .diagnosis import EFFECTS, EffectError
    from .inputs import InputError, parse_band_text

    parser = build_parser()
    args = parse_args(parser, argv)
    if isinstance(args, int):
        return args
    try:
        if args.json:
            check_out_dir(args.json, error=InputError)
        check_outputs([args.json, *_report_files(args.report)], [args.measured, args.simulated])
        effects = None
        if args.effects:
            effects = [e.strip() for e in args.effects.split(",") if e.strip()]
            bad = [e for e in effects if e not in EFFECTS]
            if bad:
                raise InputError(f"unknown effect(s) {bad}; the catalogue has {', '.join(EFFECTS)}")
        diag = run_diagnosis(args.measured, args.simulated, band=parse_band_text(args.band), effects=effects,
                             estimator=args.estimator)
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
    print(f"verdict: {doc['verdict']}" + (f" ({diag.reason})" if diag.reason else ""))
    for c in diag.named:
        print(f"  named: {c['effect']} {c['parameters']}")
    if diag.next_measurement:
        nm = diag.next_measurement
        print(f"  next measurement: {nm['point']} ({nm['why']}; {nm['separation_db']:.1f} dB apart)")
    print(f"error before {diag.error_before_db:.1f} dB, after {diag.error_after_db:.1f} dB "
          f"(noise {max(diag.noise_db.values()):.1f} dB)")
    for c in diag.causes[:5]:
        print(f"  {'*' if c['significant'] else ' '} {c['evidence']}" + ("" if c["significant"] else NOT_SIGNIFICANT))
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
