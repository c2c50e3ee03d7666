"""``python -m acquisition import``: measured time data from other systems -> a recording.

    python -m acquisition import FILE [FILE...] --out REC.h5 [--format lvm|mat|npy] [--describe DESC.json|toml]
        [--force-channel K] [--responses K,K] [--reference POINT] [--outputs P1,P2] [--windowed]
        [--force-window WIDTH[,TAPER]|none] [--exp-window TAU|PCT%|none] [--overwrite]

Formats (by extension unless ``--format``): LabVIEW ``.lvm`` (segments = hits), DataPhysics
``.mat`` (``X1..Xn`` blocks, or the analyser-windowed ``W1..Wn`` with ``--windowed``), numpy
``.npy`` (one file per hit, needs ``--describe``). Channel numbers are 1-based.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Optional, Sequence

from analysis.command_line import with_examples
from analysis.command_line import add_overwrite, cli_entry, errors_to_exit

from .cli_capture import UsageError, parse_windows
from .errors import RecordingError

__all__ = ["main"]


@cli_entry
def main(argv: Optional[Sequence[str]] = None) -> int:
    p = argparse.ArgumentParser(prog="python -m acquisition import", description=__doc__.split("\n\n")[0])
    with_examples(p)
    p.add_argument("files", nargs="+")
    p.add_argument("--out", required=True)
    p.add_argument("--format", choices=("lvm", "mat", "npy", "sep005"),
                   help="input format (default: from the extension; .json is SEP005)")
    p.add_argument("--describe", help="JSON/TOML channel description (needed for .npy)")
    p.add_argument("--force-channel", type=int, help="1-based index of the hammer channel")
    p.add_argument("--responses", help="1-based response channel indices, e.g. 2,3")
    p.add_argument("--reference", help="point label of the hammer (e.g. n:1:Z)")
    p.add_argument("--outputs", help="point labels of the responses, comma-separated")
    p.add_argument("--windowed", action="store_true", help="DataPhysics: import the analyser-windowed blocks Wk")
    p.add_argument("--force-window", default="none")
    p.add_argument("--exp-window", default="none")
    p.add_argument("--drop-nonfinite", action="store_true",
                   help="leave out hits holding NaN or infinite samples (counted) instead of refusing the file")
    add_overwrite(p)
    args = p.parse_args(argv)
    from .importers import ImportDataError, load_description, read_dataphysics_mat, read_lvm, read_numpy, \
        read_sep005_test, write_imported
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
        test = tests[0]
        for t in tests[1:]:
            if t.fs_hz != test.fs_hz or t.hits[0].shape != test.hits[0].shape:
                raise UsageError(f"{t.source} differs in sample rate or block size from {test.source}")
            test.hits += t.hits
            test.trigger_indices = (test.trigger_indices + t.trigger_indices
                                    if len(test.trigger_indices) == len(test.hits) - len(t.hits) else [])
        windows = parse_windows(args.force_window, args.exp_window, test.fs_hz)
        fch = args.force_channel - 1 if args.force_channel else None
        rch = [int(x) - 1 for x in args.responses.split(",")] if args.responses else None
        outs = [x.strip() for x in args.outputs.split(",")] if args.outputs else None
        averages = write_imported(test, args.out, windows=windows, reference=args.reference, outputs=outs,
                                  force_channel=fch, response_channels=rch, overwrite=args.overwrite)
    dropped = sum(int(t.meta.get("dropped_nonfinite_hits", 0)) for t in tests)
    if dropped:
        print(f"left out {dropped} hit(s) holding non-finite samples")
    for a in averages:
        print(f"imported {a.n_averages} accepted hit(s): reference {a.reference}, outputs {', '.join(a.outputs)}")
    print(f"recording written: {args.out}")
    return 0
