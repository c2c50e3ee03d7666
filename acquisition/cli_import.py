"""``python -m acquisition import``: measured time data or an analyser's FRF exports -> a recording.

    python -m acquisition import FILE [FILE...] --out REC.h5 [--format NAME] [--reference POINT] [--outputs P1,P2]
        [time data: --force-channel K --responses K,K --force-window W --exp-window W --windowed --describe D]
        [FRF exports: --points MAP.csv --variables NAME,... --analyser-exp-window W] [--overwrite]

The formats are the rows of :data:`acquisition.importers_registry.IMPORT_FORMATS` (one row each:
reader, extensions, options, help text): the format comes from ``--format`` or from the first
file's extension and content, the options a format does not take are refused, and ``--help``
and the error of an unknown file list the rows. Channel numbers are 1-based. Raw blocks get
capture's windows unless ``--force-window``/``--exp-window`` say otherwise (:func:`import_windows`).
An analyser's FRF exports are written as they are (``docs/recording-format.md``, "Importing
analyser FRF exports"); ``--points MAP.csv`` labels a roving test's files.

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
from analysis.outputs import check_outputs

from .errors import ImportDataError, RecordingError, UsageError
from .importers_registry import ImportFormat, ReadOptions, check_options, format_for, format_names, formats_help
from .window_options import DEFAULT_EXP_WINDOW, DEFAULT_FORCE_WINDOW, parse_windows

__all__ = ["main", "build_parser"]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m acquisition import", description=__doc__.split("\n\n")[0])
    with_examples(p)
    p.add_argument("files", nargs="*", metavar="FILE",
                   help="the measured time data (several files of one format are one test: their hits add up), or "
                        "an analyser's FRF exports (several files: a roving test, see --points)")
    p.add_argument("--out", required=True, metavar="REC.h5", help="the recording to write (HDF5)")
    p.add_argument("--format", choices=format_names(), metavar="NAME",
                   help="input format, one of: " + formats_help().replace("%", "%%"))
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


def _check_files(files: Sequence[str], row: ImportFormat, error: type[Exception]) -> None:
    """Refuse an input that is not a regular file (a FIFO would block the reader, a device never end)
    or larger than its parsing may take: text formats within
    :func:`analysis.input_limits.text_data_limit_bytes`, arrays within the memory one computation may use."""
    from analysis.input_limits import check_input_file, text_data_limit_bytes
    from analysis.work_limits import memory_budget_bytes

    limit = text_data_limit_bytes() if row.text else memory_budget_bytes()
    for f in files:
        if Path(f).exists():  # a missing file is named by its reader
            check_input_file(f, f"input file ({row.name})", limit, error)


def _given_options(parser: argparse.ArgumentParser, args: argparse.Namespace) -> list[str]:
    """The long options of ``args`` set to something other than their default."""
    return [a.option_strings[-1] for a in parser._actions
            if a.option_strings and a.dest != "help" and getattr(args, a.dest, a.default) not in (a.default, None)]


def import_windows(force: str | None, exp: str | None, windowed: bool) -> tuple[str, str]:
    """The ``--force-window`` and ``--exp-window`` texts of an import: as given, else capture's
    defaults (raw time data get the windows a capture of the same hits would: the force window keeps
    the pulse and drops the noise of the rest of the block, so the force spectrum, and with it the
    fit's band, is the pulse's); ``none`` for blocks the analyser already windowed or a shaker's
    continuous excitation (``windowed``)."""
    default_force, default_exp = ("none", "none") if windowed else (DEFAULT_FORCE_WINDOW, DEFAULT_EXP_WINDOW)
    return (force if force is not None else default_force), (exp if exp is not None else default_exp)


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from .frf_importers import read_point_map
    from .importers import channel_roles, combine_imports, write_imported

    with errors_to_exit("import", (UsageError, ImportDataError, RecordingError, ValueError)):
        point_map = read_point_map(args.points) if args.points else None
        if point_map is not None:
            if args.files:
                raise UsageError("give the files either on the command line or in --points MAP.csv, not both")
            args.files = [str(r.file) for r in point_map]
        if not args.files:
            raise UsageError("no input file: give FILE(s), or --points MAP.csv for a roving test's FRF exports")
        check_outputs([args.out], [*args.files, args.describe, args.points])
        given = _given_options(parser, args)
        row = format_for(args.format, Path(args.files[0]), given)
        check_options(row, given)
        _check_files(args.files, row, ImportDataError)
        options = ReadOptions(windowed=args.windowed, describe=args.describe, drop_nonfinite=args.drop_nonfinite,
                              variables=tuple(v.strip() for v in args.variables.split(",")) if args.variables else None)
        if row.kind == "frf":
            return _import_frfs(row, options, args, point_map)
        tests = row.read([Path(f) for f in args.files], options)
        test = combine_imports(tests)
        continuous = test.meta.get("excitation") == "continuous"  # a shaker's blocks: no hammer windows
        windows = parse_windows(*import_windows(args.force_window, args.exp_window, args.windowed or continuous),
                                test.fs_hz)
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


def _import_frfs(row: ImportFormat, options: ReadOptions, args: argparse.Namespace, point_map: list | None) -> int:
    """``import`` of an analyser's FRF export (``row``: its registry row): each file's H1 and
    coherence, relabelled with ``--reference``/``--outputs`` or the ``--points`` map's row
    (``point_map``), written as a recording."""
    from .frf_importers import combine_frf_imports, relabel, with_analyser_window, write_frf_recording

    outs = [x.strip() for x in args.outputs.split(",")] if args.outputs else None
    if args.reference and (len(args.files) > 1 or point_map):
        raise UsageError("--reference labels the reference of one file; several files need --points MAP.csv")
    if point_map:
        imports = [relabel(imp, r.reference, r.outputs or outs)
                   for r in point_map for imp in row.read([r.file], options)]
    else:
        imports = [relabel(imp, args.reference, outs) for imp in row.read([Path(f) for f in args.files], options)]
    if args.analyser_exp_window:
        window = parse_windows(None, args.analyser_exp_window, imports[0].sets[0].sample_rate_hz)
        if window.exp_window_tau_s is None and window.exp_window_end_fraction is None:
            raise UsageError("--analyser-exp-window none: leave the option out when the analyser applied no window")
        imports = [with_analyser_window(i, window) for i in imports]
    imp = combine_frf_imports(imports)
    write_frf_recording(imp, args.out, overwrite=args.overwrite)
    for s, n in zip(imp.sets, imp.n_averages):
        print(f"imported {s.n_outputs} FRF(s) {s.unit or '(unit not stated)'} of reference {s.references[0]}: outputs "
              f"{', '.join(s.outputs)}; {'averages not stated in the file' if n is None else f'{n} averages'}"
              + ("" if s.coherence is not None else "; no coherence in the file"))
    print(f"recording written: {args.out}")
    return 0
