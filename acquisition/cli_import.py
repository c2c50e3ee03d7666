"""``python -m acquisition import``: measured time data from other systems -> a recording.

    python -m acquisition import FILE [FILE...] --out REC.h5 [--format lvm|mat|npy|sep005] [--describe DESC.json|toml]
        [--force-channel K] [--responses K,K] [--reference POINT] [--outputs P1,P2] [--windowed]
        [--force-window WIDTH[,TAPER]|none] [--exp-window TAU|PCT%|none] [--overwrite]

Formats (by extension unless ``--format``): LabVIEW ``.lvm`` (segments = hits), DataPhysics
``.mat`` (``X1..Xn`` blocks, or the analyser-windowed ``W1..Wn`` with ``--windowed``), numpy
``.npy`` (one file per hit, needs ``--describe``). Channel numbers are 1-based.

The recording holds the file's numbers or is not written: what cannot be stored as read (complex
values, an infinite sensitivity, hits sampled or ordered differently, a glitch 16-bit samples
cannot hold beside the rest of its channel) is refused with one line naming the file and the field
(exit 2). ``.lvm`` columns are matched by heading and SEP005 channels by name in every hit.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from analysis.command_line import add_overwrite, cli_entry, errors_to_exit, with_examples

from .errors import RecordingError, UsageError
from .window_options import parse_windows

__all__ = ["main", "build_parser", "FORMATS"]

#: the input formats ``--format`` names (by extension otherwise; ``.json`` is SEP005)
FORMATS = ("lvm", "mat", "npy", "sep005")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m acquisition import", description=__doc__.split("\n\n")[0])
    with_examples(p)
    p.add_argument("files", nargs="+", metavar="FILE",
                   help="the measured time data (several files of one format are one test: their hits add up)")
    p.add_argument("--out", required=True, metavar="REC.h5", help="the recording to write (HDF5)")
    p.add_argument("--format", choices=FORMATS,
                   help="input format: lvm (LabVIEW text), mat (DataPhysics SignalCalc export), npy (numpy "
                        "arrays with --describe), sep005 (SEP005 JSON); default: from the extension")
    p.add_argument("--describe", metavar="DESC.json|toml", help="JSON/TOML channel description (needed for .npy)")
    p.add_argument("--force-channel", type=int, metavar="K",
                   help="1-based index of the hammer channel (default: the one channel with a force unit)")
    p.add_argument("--responses", metavar="K,K",
                   help="1-based response channel indices, e.g. 2,3 (default: every channel with a motion unit)")
    p.add_argument("--reference", metavar="POINT", help="point label of the hammer (e.g. n:1:Z)")
    p.add_argument("--outputs", metavar="P1,P2", help="point labels of the responses, comma-separated")
    p.add_argument("--windowed", action="store_true", help="DataPhysics: import the analyser-windowed blocks Wk")
    p.add_argument("--force-window", default="none", metavar="WIDTH[,TAPER]|none",
                   help="force window after the trigger, e.g. 10ms,2ms (s, ms or samples; default none)")
    p.add_argument("--exp-window", default="none", metavar="TAU|PCT%|none",
                   help="exponential window on the responses: the time constant (e.g. 0.3s) or the value it "
                        "decays to at the block end (e.g. 5%%); default none")
    p.add_argument("--drop-nonfinite", action="store_true",
                   help="leave out hits holding NaN or infinite samples (counted) instead of refusing the file")
    add_overwrite(p, "replace an existing --out file")
    return p


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from .importers import (
        ImportDataError,
        channel_roles,
        combine_imports,
        load_description,
        read_dataphysics_mat,
        read_lvm,
        read_numpy,
        read_sep005_test,
        write_imported,
    )
    from .importers import read_dropping_nonfinite as _read
    drop = args.drop_nonfinite

    with errors_to_exit("import", (UsageError, ImportDataError, RecordingError, ValueError)):
        fmt = args.format or Path(args.files[0]).suffix.lower().lstrip(".")
        if fmt == "lvm":
            tests = [_read(read_lvm, f, drop=drop) for f in args.files]
        elif fmt == "mat":
            tests = [_read(read_dataphysics_mat, f, windowed=args.windowed, drop=drop) for f in args.files]
        elif fmt in ("sep005", "json"):
            tests = [_read(read_sep005_test, f, drop=drop) for f in args.files]
        elif fmt == "npy":
            if not args.describe:
                raise UsageError("numpy input needs --describe DESC.json|toml naming the channels and sample rate")
            tests = [_read(read_numpy, args.files, load_description(args.describe), drop=drop)]
        else:
            raise UsageError(f"unknown input format {fmt!r}: use .lvm, .mat, .npy or SEP005 .json (or --format)")
        test = combine_imports(tests)
        windows = parse_windows(args.force_window, args.exp_window, test.fs_hz)
        fch = args.force_channel - 1 if args.force_channel else None
        rch = [int(x) - 1 for x in args.responses.split(",")] if args.responses else None
        outs = [x.strip() for x in args.outputs.split(",")] if args.outputs else None
        roles = channel_roles(test, reference=args.reference, outputs=outs, force_channel=fch,
                              response_channels=rch)
        averages = write_imported(test, args.out, windows=windows, roles=roles, overwrite=args.overwrite)
    for line in roles.describe():
        print(line)
    dropped = sum(int(t.meta.get("dropped_nonfinite_hits", 0)) for t in tests)
    if dropped:
        print(f"left out {dropped} hit(s) holding non-finite samples")
    for a in averages:
        print(f"imported {a.n_averages} accepted hit(s): reference {a.reference}, outputs {', '.join(a.outputs)}")
    print(f"recording written: {args.out}")
    return 0
