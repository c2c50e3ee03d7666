"""``python -m analysis report INPUT --out DIR [--fit FIT.json] [--diagnosis DIAG.json] [--geometry G]``.

Writes a self-contained HTML test report (``DIR/index.html`` and its assets; opens from the file
system with no network). This wiring module chooses the geometry of the mode shapes: ``--geometry``
a UFF file (data sets 15 and 82), ``frame`` (the simulated frame) or a simulator config ``.toml``;
without it, the simulated frame when the recording was made on the simulator, else the points on a
line. Exit codes: 0 written, 2 bad input.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ._cli_dispatch import Parser, parse_args
from .command_line import add_estimator, add_overwrite, add_threads, cli_entry, disk_full_line, with_examples
from .disk_space import disk_full_cause
from .errors import ImpactlabError, OutputBusy

if TYPE_CHECKING:
    from .geometry import Geometry

__all__ = ["build_parser", "choose_geometry", "main"]


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="python -m analysis report",
               description="Self-contained HTML report of an impact test: the test, FRFs, stabilization, modes, "
                           "animated mode shapes, diagnosis.")
    with_examples(p)
    p.add_argument("input", metavar="INPUT", help="recording (.h5) or UFF file with dataset-58 FRFs")
    p.add_argument("--out", required=True, metavar="DIR", help="report folder (created; DIR/index.html)")
    p.add_argument("--fit", metavar="FIT.json", help="fit from 'python -m analysis fit --json' (default: fit here)")
    p.add_argument("--diagnosis", metavar="DIAG.json", help="diagnosis from 'python -m analysis diagnose --json'")
    p.add_argument("--geometry", metavar="G",
                   help="UFF file with nodes (15) and trace lines (82), 'frame' or a simulator config .toml "
                        "(default: the simulated frame for simulator recordings, else the points on a line)")
    add_overwrite(p, "replace the report files (index.html and its assets) already in DIR")
    add_estimator(p)
    add_threads(p)
    return p


def _frame(config: str | None = None) -> Geometry:
    from simulator.config import FrameConfig
    from simulator.geometry import frame_geometry

    return frame_geometry(FrameConfig.load(config))


def choose_geometry(spec: str | None, device: str = "") -> Geometry | None:
    """The geometry named by ``--geometry`` (see module doc); None: the report puts the points on a line."""
    from .geometry import GeometryError, read_uff_geometry

    if spec is None:
        return _frame() if device.startswith(("sim", "usbsim")) else None
    if spec == "frame":
        return _frame()
    if spec.lower().endswith(".toml"):
        if not Path(spec).is_file():
            raise GeometryError(f"simulator config {spec} not found: check the path")
        return _frame(spec)
    return read_uff_geometry(spec)


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    """Run the command; returns the exit code (0 written, 2 bad input, 1 no room on the disk)."""
    args = parse_args(build_parser(), argv)
    if isinstance(args, int):
        return args
    try:
        from .inputs import detect_format
        from .report_html import make_report, recording_device

        device = ""
        if detect_format(args.input) == "recording":
            device = recording_device(args.input)
        index = make_report(args.input, args.out, fit_json=args.fit, diagnosis=args.diagnosis,
                            geometry=choose_geometry(args.geometry, device), estimator=args.estimator,
                            overwrite=args.overwrite, inputs=[args.geometry])
    except OutputBusy as exc:
        print(f"analysis report: {exc}", file=sys.stderr)
        return 1
    except (ImpactlabError, ValueError, OSError) as exc:
        if disk_full_cause(exc) is not None:
            print(disk_full_line("analysis report", exc), file=sys.stderr)
            return 1
        print(f"analysis report: {exc}", file=sys.stderr)
        return 2
    print(f"report written to {index}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
