"""``python -m simulator modes [--config F] [--json]``: the simulated frame's modes.

Prints each mode's natural frequency |lambda|/2pi (Hz), damping ratio -Re(lambda)/|lambda| and the
mass-normalised shape at the paper's points (left:9:Y, top:4:X, right:4:-Z, right:6:-X). The frame
carries the accelerometers of the default test plan when ``[sensors] mass_loading`` is on
(``--bare`` leaves them off).
"""
from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

from analysis.command_line import add_json_flag, cli_entry, errors_to_exit, with_examples

from .config import ConfigError, FrameConfig
from .fem import FrameModel, ModelError

PAPER_POINTS = ("left:9:Y", "top:4:X", "right:4:-Z", "right:6:-X")


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m simulator modes", description=__doc__.splitlines()[0])
    with_examples(ap)
    ap.add_argument("--config", metavar="F", help="TOML file merged over simulator/frame.toml")
    add_json_flag(ap, "print JSON: {\"modes\": [{freq_hz, damping, shape}, ...]}")
    ap.add_argument("--max-freq", type=float, default=None, metavar="HZ",
                    help="list modes up to HZ (default: [modes] max_freq_hz of the config)")
    ap.add_argument("--points", nargs="+", default=list(PAPER_POINTS), metavar="P",
                    help="points for the shape values (component:node:direction)")
    ap.add_argument("--bare", action="store_true", help="no accelerometer masses on the frame")
    return ap


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    with errors_to_exit("simulator modes", (ConfigError, ModelError, ValueError)):
        cfg = FrameConfig.load(args.config)
        masses = {}
        if cfg.sensors.mass_loading and not args.bare:
            sensors = cfg.test_plan.sensors if cfg.test_plan.mode == "roving_hammer" else cfg.test_plan.points[:1]
            masses = {p: cfg.sensors.accelerometer.mass_kg for p in sensors}
        model = FrameModel.from_config(cfg, masses)
        modes = model.modes(args.max_freq)
        shapes = model.shape_at(args.points, modes)
    poles = modes.poles
    rows = []
    for r in range(modes.freq_hz.size):
        rows.append({
            "freq_hz": float(abs(poles[r]) / (2 * 3.141592653589793)),
            "damping": float(-poles[r].real / abs(poles[r])) if abs(poles[r]) > 0 else 0.0,
            "shape": {p: float(shapes[i, r]) for i, p in enumerate(args.points)},
        })
    try:
        _print(rows, args, cfg.source)
    except BrokenPipeError:  # e.g. piped into `head`
        return 0
    return 0


def _print(rows: list, args: argparse.Namespace, source: str) -> None:
    if args.json:
        print(json.dumps({"modes": rows}, indent=2))
        return
    print(f"modes of the simulated frame ({source}); shapes mass-normalised (1/sqrt(kg))")
    head = f"{'#':>3} {'f [Hz]':>9} {'zeta [%]':>8}  " + " ".join(f"{p:>11}" for p in args.points)
    print(head)
    print("-" * len(head))
    for r, row in enumerate(rows, 1):
        vals = " ".join(f"{row['shape'][p]:>11.4f}" for p in args.points)
        print(f"{r:>3} {row['freq_hz']:>9.3f} {100 * row['damping']:>8.3f}  {vals}")
