"""``python -m analysis linearity INPUTS... [--levels 0.05,0.30] [--band LO:HI] [--json L.json]``.

Is the structure linear? INPUTS are recordings (``.h5``) or UFF 58 files measured at different
excitation levels, one level each (``--levels``, in the data's own unit: N, V...; a recording's level
is otherwise the median peak force of its accepted hits), or one recording whose hits span force
levels (grouped by peak force). Per mode: the frequency and damping change from the lowest to the
highest level, its standard deviation from the fits and its significance
(:func:`analysis.linearity.compare_levels`). ``--json`` contract::

    {"verdict": "linear" | "nonlinear",
     "modes": [{"freq_hz", "df_percent", "df_std_percent", "dzeta_percent", "significant", ...}],
     "levels": [...], "band_hz": [lo, hi], ...}

``freq_hz`` at the lowest level, changes from lowest to highest. Exit codes: 0 done, 1 the levels' modes
do not pair by frequency and MAC (not one structure: no verdict), 2 bad input.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence

import numpy as np

from .command_line import Parser as _Parser
from .command_line import add_estimator, check_out_dir, parse_args, with_examples
from .errors import OutputBusy
from .outputs import check_outputs

__all__ = ["main", "build_parser"]


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="python -m analysis linearity",
                description="Compare FRFs taken at different excitation levels mode by mode: frequency and "
                            "damping change with their standard deviations, and a verdict (linear within the "
                            "noise, or nonlinear: which modes, how much per decade of level).")
    with_examples(p)
    p.add_argument("inputs", nargs="+", metavar="INPUT",
                   help="recordings (.h5) or UFF 58 files, one per level; or one recording whose hits span levels")
    p.add_argument("--levels", metavar="L1,L2,...",
                   help="excitation level of each input in its own unit (N, V...), in the order of the inputs")
    p.add_argument("--band", metavar="LO:HI", help="frequency band in Hz (default: the band every level's data support)")
    p.add_argument("--z", type=_z_value, default=3.0,
                   help="significance in standard deviations, a finite number > 0 (default 3)")
    p.add_argument("--json", metavar="L.json", help="write the comparison as JSON")
    add_estimator(p)
    return p


def _z_value(text: str) -> float:
    """``--z``: a finite number of standard deviations > 0 (a usage error otherwise)."""
    try:
        z = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of standard deviations (e.g. 3)") from None
    if not (math.isfinite(z) and z > 0):
        raise argparse.ArgumentTypeError(f"{text} must be a finite number of standard deviations > 0 (e.g. 3)")
    return z


def _levels(args: argparse.Namespace, n: int) -> list[float] | None:
    from .inputs import InputError, parse_float_list

    if not args.levels:
        return None
    lv = parse_float_list(args.levels, "levels")
    if len(lv) != n:
        raise InputError(f"--levels gives {len(lv)} level(s) for {n} input(s): give one level per input")
    return lv


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command; returns the exit code (0 done, 1 the levels' modes do not pair, 2 bad input)."""
    from .bands import FitError
    from .inputs import InputError, load_input, parse_band_text
    from .linearity import LevelsDoNotPair, compare_levels, recording_hits
    from .recording import RecordingError

    args = parse_args(build_parser(), argv)
    if isinstance(args, int):
        return args
    try:
        check_out_dir(args.json, error=InputError)
        check_outputs([args.json], args.inputs)
        band = parse_band_text(args.band)
        levels = _levels(args, len(args.inputs))
        if len(args.inputs) == 1:
            if levels is not None:
                raise InputError("--levels needs one input per level; one recording's hits are grouped by force")
            got = recording_hits(args.inputs[0])
            if got is None:
                raise InputError(f"{args.inputs[0]}: one input must be a recording with hits (its hits are grouped "
                                 "by force); otherwise give one input per level")
            _, levels, sets = got
            if len(sets) < 2:
                raise InputError(f"{args.inputs[0]}: the hits' peak forces do not spread enough to compare levels "
                                 "(strike soft and hard hits at each point)")
        else:
            sets = [load_input(p, estimator=args.estimator) for p in args.inputs]
            if levels is None:
                found = [recording_hits(p) for p in args.inputs]
                if any(f is None for f in found):
                    raise InputError("give --levels (one per input): the level cannot be read from every input")
                levels = [float(np.median([np.max(np.abs(h.force)) for h in f[0]])) for f in found if f is not None]
        result = compare_levels(sets, levels, band=band, z=args.z)
    except (OutputBusy, LevelsDoNotPair) as exc:
        print(f"analysis linearity: {exc}", file=sys.stderr)
        return 1
    except (InputError, RecordingError, FitError, ValueError, OSError) as exc:
        print(f"analysis linearity: {exc}", file=sys.stderr)
        return 2
    if args.json:
        from .atomic import write_text_atomic

        write_text_atomic(args.json, json.dumps(result.to_dict(), indent=1))
    lv = result.levels
    print(f"levels {', '.join(f'{v:.4g}' for v in lv)}; band {result.band[0]:.5g}-{result.band[1]:.5g} Hz")
    print(f"{'f [Hz]':>10s} {'df [%]':>8s} {'+-':>6s} {'dzeta [%]':>9s} {'+-':>6s} {'df/dec':>7s}  significant")
    for m in result.modes:
        print(f"{m.freq_hz:10.4f} {m.df_percent:+8.3f} {m.df_std_percent:6.3f} {m.dzeta_percent:+9.1f} "
              f"{m.dzeta_std_percent:6.1f} {m.df_percent_per_decade:+7.3f}  {'yes' if m.significant else 'no'}")
    for note in result.notes:
        print(f"note: {note}")
    print(f"verdict: {result.summary()}")
    return 0
