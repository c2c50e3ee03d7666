"""``python -m acquisition import``: measured time data or an analyser's FRF exports -> a recording.

    python -m acquisition import FILE [FILE...] --out REC.h5 [--format lvm|mat|npy|sep005] [--describe DESC.json|toml]
        [--force-channel K] [--responses K,K] [--reference POINT] [--outputs P1,P2] [--windowed]
        [--force-window WIDTH[,TAPER]|none] [--exp-window TAU|PCT%|none] [--overwrite]

Formats (by extension unless ``--format``): LabVIEW ``.lvm`` (segments = hits), DataPhysics
``.mat`` (``X1..Xn`` blocks, or the analyser-windowed ``W1..Wn`` with ``--windowed``), numpy
``.npy`` (one file per hit, needs ``--describe``). Channel numbers are 1-based. Raw blocks get
capture's windows unless ``--force-window``/``--exp-window`` say otherwise (:func:`import_windows`).

Analyser FRF exports (H1 and coherence, :data:`acquisition.frf_importers.FRF_FORMATS`, one row per
format): ``--format signalcalc-frf|testlab-frf`` or detected from a ``.mat`` file's variables;
``--variables`` picks FRFs, ``--points MAP.csv`` labels a roving test's files
(``docs/recording-format.md``, "Importing analyser FRF exports").

The recording holds the file's numbers or is not written: what cannot be stored as read (complex
values, an infinite sensitivity, hits sampled or ordered differently, a glitch 16-bit samples
cannot hold beside the rest of its channel) is refused with one line naming the file and the field
(exit 2). ``.lvm`` columns are matched by heading and SEP005 channels by name in every hit.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from analysis.command_line import add_overwrite, cli_entry, errors_to_exit, with_examples
from analysis.outputs import check_outputs

from .errors import ImportDataError, RecordingError, UsageError
from .frf_importers import FRF_FORMATS
from .window_options import DEFAULT_EXP_WINDOW, DEFAULT_FORCE_WINDOW, parse_windows

__all__ = ["main", "build_parser", "FORMATS"]

#: the input formats ``--format`` names (by extension otherwise; ``.json`` is SEP005)
FORMATS = ("lvm", "mat", "npy", "sep005") + tuple(r.name for r in FRF_FORMATS)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m acquisition import", description=__doc__.split("\n\n")[0])
    with_examples(p)
    p.add_argument("files", nargs="*", metavar="FILE",
                   help="the measured time data (several files of one format are one test: their hits add up), or "
                        "an analyser's FRF exports (several files: a roving test, see --points)")
    p.add_argument("--out", required=True, metavar="REC.h5", help="the recording to write (HDF5)")
    p.add_argument("--format", choices=FORMATS,
                   help="input format: lvm (LabVIEW text), mat (DataPhysics SignalCalc export), npy (numpy "
                        "arrays with --describe), sep005 (SEP005 JSON); analyser FRF exports: "
                        + "; ".join(f"{r.name} ({r.description})" for r in FRF_FORMATS)
                        + "; default: from the extension and content")
    p.add_argument("--points", metavar="MAP.csv",
                   help="analyser FRF exports of a roving test: CSV 'file,reference[,outputs]' giving each file "
                        "(relative to the map) its reference point and, optionally, its channels' output points")
    p.add_argument("--analyser-exp-window", metavar="TAU|PCT%",
                   help="analyser FRF exports: the exponential window the analyser applied to the responses, as "
                        "its time constant (e.g. 14.4s) or its value at the block end (e.g. 32.9%%); recorded, and "
                        "removed from the damping by the fit (the exports do not store it)")
    p.add_argument("--variables", metavar="NAME[,NAME]",
                   help="analyser FRF exports: the FRF variables to import (e.g. H1_2,H1_3 or FRF)")
    p.add_argument("--describe", metavar="DESC.json|toml", help="JSON/TOML channel description (needed for .npy)")
    p.add_argument("--force-channel", type=int, metavar="K",
                   help="1-based index of the hammer channel (default: the one channel with a force unit)")
    p.add_argument("--responses", metavar="K,K",
                   help="1-based response channel indices, e.g. 2,3 (default: every channel with a motion unit)")
    p.add_argument("--reference", metavar="POINT", help="point label of the hammer (e.g. n:1:Z)")
    p.add_argument("--outputs", metavar="P1,P2", help="point labels of the responses, comma-separated")
    p.add_argument("--windowed", action="store_true", help="DataPhysics: import the analyser-windowed blocks Wk")
    p.add_argument("--force-window", metavar="WIDTH[,TAPER]|none",
                   help="force window after the trigger, e.g. 10ms,2ms (s, ms or samples; default: capture's, "
                        f"{DEFAULT_FORCE_WINDOW}; none with --windowed, whose blocks carry the analyser's windows)")
    p.add_argument("--exp-window", metavar="TAU|PCT%|none",
                   help="exponential window on the responses: the time constant (e.g. 0.3s) or the value it "
                        f"decays to at the block end (e.g. 5%%); default: capture's, {DEFAULT_EXP_WINDOW.replace('%', '%%')}; "
                        "none with --windowed")
    p.add_argument("--drop-nonfinite", action="store_true",
                   help="leave out hits holding NaN or infinite samples (counted) instead of refusing the file")
    add_overwrite(p, "replace an existing --out file")
    return p


def _check_files(files: Sequence[str], fmt: str, error: type[Exception]) -> None:
    """Refuse an input that is not a regular file (a FIFO would block the reader, a device never end)
    or larger than its parsing may take: text (.lvm, SEP005) within
    :func:`analysis.input_limits.text_data_limit_bytes`, arrays within the memory one computation may use."""
    from analysis.input_limits import check_input_file, text_data_limit_bytes
    from analysis.work_limits import memory_budget_bytes

    limit = text_data_limit_bytes() if fmt in ("lvm", "sep005", "json") else memory_budget_bytes()
    for f in files:
        if Path(f).exists():  # a missing file is named by its reader
            check_input_file(f, f"input file (.{fmt})", limit, error)


def import_windows(force: str | None, exp: str | None, windowed: bool) -> tuple[str, str]:
    """The ``--force-window`` and ``--exp-window`` texts of an import: as given, else capture's
    defaults (raw time data get the windows a capture of the same hits would: the force window keeps
    the pulse and drops the noise of the rest of the block, so the force spectrum, and with it the
    fit's band, is the pulse's); ``none`` for blocks the analyser already windowed (``windowed``)."""
    default_force, default_exp = ("none", "none") if windowed else (DEFAULT_FORCE_WINDOW, DEFAULT_EXP_WINDOW)
    return (force if force is not None else default_force), (exp if exp is not None else default_exp)


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from .frf_importers import frf_format_for, read_point_map
    from .importers import (
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
        point_map = read_point_map(args.points) if args.points else None
        if point_map is not None:
            if args.files:
                raise UsageError("give the files either on the command line or in --points MAP.csv, not both")
            args.files = [str(r.file) for r in point_map]
        if not args.files:
            raise UsageError("no input file: give FILE(s), or --points MAP.csv for a roving test's FRF exports")
        check_outputs([args.out], [*args.files, args.describe, args.points])
        frf_row = frf_format_for(args.format, args.files[0])
        if frf_row is None and point_map is not None:
            raise UsageError("--points maps analyser FRF exports (--format "
                             + "|".join(r.name for r in FRF_FORMATS) + "); time data take --reference/--outputs")
        frf_only = [o for o, v in (("--variables", args.variables), ("--analyser-exp-window", args.analyser_exp_window))
                    if v]
        if frf_row is None and frf_only:
            raise UsageError(f"{', '.join(frf_only)}: for analyser FRF exports only (--format "
                             + "|".join(r.name for r in FRF_FORMATS) + ")")
        if frf_row is not None:
            return _import_frfs(frf_row, args, point_map)
        fmt = args.format or Path(args.files[0]).suffix.lower().lstrip(".")
        _check_files(args.files, fmt, ImportDataError)
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
            raise UsageError(f"unknown input format {fmt!r}: use .lvm, .mat, .npy or SEP005 .json, or --format "
                             + "|".join(r.name for r in FRF_FORMATS) + " for an analyser's FRF export")
        test = combine_imports(tests)
        windows = parse_windows(*import_windows(args.force_window, args.exp_window, args.windowed), test.fs_hz)
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


def _import_frfs(row: Any, args: argparse.Namespace, point_map: list | None) -> int:
    """``import`` of an analyser's FRF export (``row``: its :data:`FRF_FORMATS` row): each file's
    H1 and coherence, relabelled with ``--reference``/``--outputs`` or the ``--points`` map's row
    (``point_map``), written as a recording."""
    from .frf_importers import combine_frf_imports, relabel, with_analyser_window, write_frf_recording

    time_only = [o for o, v in (("--describe", args.describe), ("--force-channel", args.force_channel),
                                ("--responses", args.responses), ("--windowed", args.windowed),
                                ("--force-window", args.force_window), ("--exp-window", args.exp_window),
                                ("--drop-nonfinite", args.drop_nonfinite)) if v]
    if time_only:
        raise UsageError(f"{', '.join(time_only)}: for time data only; {row.name} holds the analyser's FRFs"
                         + (" (the window it applied: --analyser-exp-window)" if args.exp_window else ""))
    _check_files(args.files, "mat", ImportDataError)
    variables = [v.strip() for v in args.variables.split(",")] if args.variables else None
    outs = [x.strip() for x in args.outputs.split(",")] if args.outputs else None
    if args.reference and (len(args.files) > 1 or point_map):
        raise UsageError("--reference labels the reference of one file; several files need --points MAP.csv")
    if point_map:
        imports = [relabel(row.read(r.file, variables), r.reference, r.outputs or outs) for r in point_map]
    else:
        imports = [relabel(row.read(Path(f), variables), args.reference, outs) for f in args.files]
    if args.analyser_exp_window:
        window = parse_windows(None, args.analyser_exp_window, imports[0].sets[0].sample_rate_hz)
        if window.exp_window_tau_s is None and window.exp_window_end_fraction is None:
            raise UsageError("--analyser-exp-window none: leave the option out when the analyser applied no window")
        imports = [with_analyser_window(i, window) for i in imports]
    imp = combine_frf_imports(imports)
    write_frf_recording(imp, args.out, overwrite=args.overwrite)
    for s, n in zip(imp.sets, imp.n_averages):
        print(f"imported {s.n_outputs} FRF(s) {s.unit} of reference {s.references[0]}: outputs "
              f"{', '.join(s.outputs)}; {'averages not stated in the file' if n is None else f'{n} averages'}")
    print(f"recording written: {args.out}")
    return 0
