"""``python -m analysis fit INPUT --json OUT.json [options]``: the whole automatic modal fit.

INPUT is a recording (``.h5``) or a UFF file with dataset-58 FRFs. The terminal shows the
paper's Table 1 for one FRF; the JSON holds every FRF's parameters. Exit codes: 0 done
(check ``success`` in the JSON), 2 bad input or a fit that cannot start (message on stderr).
"""
from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

__all__ = ["main", "build_parser"]


from .command_line import Parser as _Parser
from .command_line import UsageError as _UsageError
from .command_line import add_estimator, add_threads, check_out_dir, cli_entry, errors_to_exit, parse_args, with_examples
from .outputs import check_outputs

if TYPE_CHECKING:
    from .frf import FRFSet
    from .geometry import Geometry
    from .lsfd import LSFDResult


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="python -m analysis fit",
        description="Automatic modal fit: band, stabilization (LSCF/LSCE), pole selection, nonlinear LSFD "
                    "(Gauss-Newton or Levenberg-Marquardt).",
    )
    with_examples(p)
    p.add_argument("input", metavar="INPUT", help="recording (.h5) or UFF file with dataset-58 FRFs")
    p.add_argument("--json", metavar="OUT.json",
                   help="also write the fit results as JSON (the table is printed either way)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace existing --json/--plot/--uff files (without it an existing file stops the command)")
    p.add_argument("--band", metavar="LO:HI", help="frequency band in Hz (default: automatic, see docs/fitting.md)")
    p.add_argument("--modes", type=int, metavar="N", help="number of modes to keep (the N most stable clusters)")
    p.add_argument("--order", type=int, metavar="N",
                   help="largest model order of the stabilization, in modes (polynomial order 2N)")
    p.add_argument("--method", choices=("gn", "lm"), default="lm", help="LSFD iteration (default lm)")
    p.add_argument("--initial", choices=("lscf", "lsce"), default="lscf",
                   help="initial-pole method of the stabilization (default lscf)")
    p.add_argument("--poles", metavar="F1,F2,...|FILE",
                   help="natural frequencies (Hz) to fit instead of automatic selection (poles the data show "
                        "beyond them are added), or a file of poles picked on the report's stabilization diagram "
                        "(fitted exactly: no pole is added; see docs/report.md)")
    p.add_argument("--residuals", choices=("physical", "paper", "none"), default="physical",
                   help="residual terms (default physical)")
    p.add_argument("--per-frf", action="store_true", help="also fit every FRF alone (results in the JSON)")
    p.add_argument("--max-iter", type=int, default=100, metavar="N", help="LSFD iteration cap (default 100)")
    p.add_argument("--plot", metavar="PNG", help="measured vs synthesised FRFs with the relative error (paper Fig. 7) "
                                                  "and the mode indicator (CMIF, or MIF for one reference) beneath")
    p.add_argument("--log-freq", action="store_true", help="logarithmic frequency axis in --plot")
    p.add_argument("--uff", metavar="OUT.uff",
                   help="write the test geometry (UFF 15 nodes, 82 trace lines), UFF 55 mode shapes (in order of "
                        "frequency) and UFF 58 synthesised FRFs: other tools can animate the shapes")
    p.add_argument("--geometry", metavar="frame|CONFIG.toml|GEOMETRY.uff",
                   help="geometry written with --uff (default: the simulated frame for recordings made on sim:// "
                        "or usbsim://, else the measured points on a line)")
    p.add_argument("--frf-weights", choices=("rms", "none"), default="rms",
                   help="LSFD weight of each FRF: 1/noise level from coherence or RMS (default), or none "
                        "(the paper's unweighted S); see docs/fitting.md")
    p.add_argument("--scatter-std", action="store_true",
                   help="also estimate the pole spread from refits of each reference's FRFs (or output groups); "
                        "costs one LSFD per group, see docs/fitting.md")
    p.add_argument("--exclude-lines", metavar="F1,F2,...",
                   help="leave the lines within 2 lines of these frequencies (Hz) out of the LSFD (zero weight)")
    p.add_argument("--mains", metavar="auto|50|60|none", default="auto",
                   help="the mains grid (Hz) whose narrow harmonic lines are never fitted as modes: auto (default) "
                        "finds it from the narrow lines in the FRFs and coherence (both 50 and 60 Hz when they do not "
                        "tell), 50 or 60 gives it, none turns the check off; see docs/fitting.md")
    p.add_argument("--exclude-mains", metavar="HZ", type=float,
                   help="leave every harmonic of this mains frequency (Hz) in the band out of the LSFD")
    add_estimator(p)
    add_threads(p)
    p.add_argument("--frf", metavar="OUTPUT",
                   help="output point shown in the terminal table (default: the strongest FRF)")
    return p


def _geometry(args: argparse.Namespace) -> Geometry | None:
    """The geometry for ``--uff`` (``--geometry``, else the simulated frame for a simulated test,
    else None: the points on a line)."""
    from .cli_report import choose_geometry
    from .inputs import detect_format
    from .report_html import recording_device

    device = recording_device(args.input) if detect_format(args.input) == "recording" else ""
    return choose_geometry(args.geometry, device)


def _write_uff(path: str, frf: FRFSet, result: LSFDResult, geometry: Geometry | None = None) -> None:
    """UFF 55 mode shapes (the structure: window-corrected poles), then the geometry (UFF 15 nodes
    and 82 trace lines; ``geometry`` or the measured points on a line), then UFF 58 synthesised FRFs
    appended in the same file. The FRFs are synthesised *as measured* (raw poles, the exponential
    window's damping included, comparable with the input FRFs); their ID line 2 says which."""
    from .atomic import atomic_path, temporary_beside
    from .geometry import points_on_a_line, write_uff_geometry
    from .modal import synthesize
    from .uff import write_uff55, write_uff58

    model = result.model
    sel = (frf.freq_hz >= result.band[0]) & (frf.freq_hz <= result.band[1])
    shapes = result.mode_shapes
    if shapes is None:
        shapes = model.residues[:, 0, :]
    synth = synthesize(result.model_raw, frf.freq_hz[sel])
    which = (f"exp. window tau {frf.exp_window_tau_s:.6g} s: raw poles, as measured" if frf.exp_window_tau_s
             else "no window: model poles")
    synth = replace(synth, exp_window_tau_s=frf.exp_window_tau_s)
    points = list(dict.fromkeys(list(model.outputs) + list(model.references)))
    if geometry is None or geometry.covers(points):
        geometry = points_on_a_line(points)
    with atomic_path(path) as whole:  # the three parts make one file, replaced at the end
        geo, part = temporary_beside(path), temporary_beside(path)
        try:
            write_uff55(whole, model.poles, np.asarray(shapes), list(model.outputs), overwrite=True)
            write_uff_geometry(geo, geometry)
            write_uff58(part, synth, id_lines=("impactlab LSFD synthesised FRF", which, "synthesis"))
            with open(whole, "ab") as out:
                for piece in (geo, part):
                    out.write(piece.read_bytes())
        finally:
            geo.unlink(missing_ok=True)
            part.unlink(missing_ok=True)


def _given_poles(text: str) -> tuple:
    """``--poles``: a picked-poles file (when ``text`` names a file or looks like a path) or a list
    of frequencies in Hz. Returns (complex poles (rad/s) or frequencies (Hz) for
    ``fit_auto(initial=...)``, whether they came from a file of picked poles, the band (Hz) they
    were picked in or None)."""
    from .inputs import parse_float_list
    from .picks import read_picks

    if Path(text).exists() or "/" in text or Path(text).suffix.lower() in (".json", ".txt"):
        picks = read_picks(text)
        return picks.initial(), True, picks.band_hz
    return parse_float_list(text), False, None


def _check_options(args: argparse.Namespace) -> tuple:
    """The options checked and parsed before the input is read: (band or None, given poles or
    frequencies or None, whether they are picked poles, excluded lines (Hz), mains frequencies (Hz)).
    Raises InputError naming the option."""
    from .inputs import InputError, parse_band_text, parse_float_list
    from .mains_grid import parse_mains_option

    band = parse_band_text(args.band)
    for name in ("modes", "order", "max_iter"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise InputError(f"--{name.replace('_', '-')} must be >= 1; got {v}")
    freqs, picked, picked_band = _given_poles(args.poles) if args.poles else (None, False, None)
    if band is None and picked_band is not None:
        band = picked_band  # the band of the diagram the poles were picked on
    exclude = parse_float_list(args.exclude_lines) if args.exclude_lines else []
    try:
        mains = parse_mains_option(args.mains)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    if args.exclude_mains is not None and not args.exclude_mains > 0:
        raise InputError(f"--exclude-mains {args.exclude_mains:g}: the mains frequency must be > 0 Hz (50 or 60)")
    check_outputs([args.json, args.plot, args.uff], [args.input, args.poles, args.geometry])
    for path, what in ((args.json, "JSON"), (args.plot, "plot"), (args.uff, "UFF file")):
        check_out_dir(path, what)
        if path and Path(path).exists() and not args.overwrite:
            raise InputError(f"{path} exists: choose another {what} file or add --overwrite")
    return band, freqs, picked, exclude, mains


def _load(args: argparse.Namespace, band: tuple[float, float] | None) -> tuple[FRFSet, list[tuple[int, int]]]:
    """The input's FRFs and their (output, reference) pairs by level, the one shown first (``--frf``'s
    strongest FRF, else the strongest of all). Raises InputError for a band outside the data or an
    unknown ``--frf``."""
    from .frf import frf_pairs_by_level
    from .inputs import InputError, load_input

    frf = load_input(args.input, estimator=args.estimator)
    if band is not None:
        f = frf.freq_hz
        if band[1] <= f[0] or band[0] >= f[-1]:
            whence = "" if args.band else f" (the band the --poles file {args.poles} was picked in)"
            raise InputError(f"band {band[0]:.6g}..{band[1]:.6g} Hz{whence} lies outside the data "
                             f"({f[0]:.6g}..{f[-1]:.6g} Hz): give --band LO:HI within it")
    if args.frf is not None and args.frf not in frf.outputs:
        raise InputError(f"--frf {args.frf!r} is not an output of {args.input}; outputs: {', '.join(frf.outputs)}")
    return frf, frf_pairs_by_level(frf, args.frf)


def _print_notes(notes: list[str], caught: list[str], quiet: bool) -> None:
    """The fit's notes and the warnings caught during it on stderr (with ``-q`` only their count)."""
    all_notes = notes + [c for c in caught if c not in notes]
    if quiet and all_notes:
        print(f"{len(all_notes)} note(s) about the fit: in the JSON's 'warnings', or run without -q", file=sys.stderr)
    else:
        for msg in all_notes:
            print(f"note: {msg}", file=sys.stderr)


def _write_outputs(args: argparse.Namespace, frf: FRFSet, result: LSFDResult, doc: dict,
                   pairs: list[tuple[int, int]]) -> None:
    """The JSON, the plot (the first four FRFs of ``pairs``) and the UFF file the options ask for."""
    from .report import write_json

    if args.json:
        write_json(args.json, doc)
        print(f"results written to {args.json}")
    if args.plot:
        from .plots import plot_fit

        plot_fit(frf, result, args.plot, pairs=pairs[:4], band=result.band, log_freq=args.log_freq, indicator=True)
        print(f"plot written to {args.plot}")
    if args.uff:
        _write_uff(args.uff, frf, result, _geometry(args))
        print(f"mode shapes (UFF 55) and synthesised FRFs (UFF 58) written to {args.uff}")


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    """Run the command; returns the exit code (0 done, 2 bad input)."""
    from .inputs import InputError

    parser = build_parser()
    args = parse_args(parser, argv)
    if isinstance(args, int):
        return args
    with errors_to_exit("analysis fit", (InputError, _UsageError)):
        band, freqs, picked, exclude, mains = _check_options(args)
        frf, pairs = _load(args, band)
    shown = pairs[0]

    from .pipeline import fit_auto
    from .report import format_table, result_to_dict

    if args.exclude_mains is not None:
        from .pipeline import mains_harmonics

        exclude = list(exclude) + mains_harmonics(args.exclude_mains, band or (frf.freq_hz[0], frf.freq_hz[-1]))
    caught: list[str] = []
    with errors_to_exit("analysis fit", ValueError):
        with warnings.catch_warnings(record=True) as wlist:
            warnings.simplefilter("always")
            fit = fit_auto(
                frf, band=band, max_modes=args.order, n_modes=args.modes, method=args.method,
                residual_form=args.residuals, initial=freqs if freqs is not None else args.initial,
                per_frf=args.per_frf, max_iter=args.max_iter, frf_weighting=args.frf_weights,
                mains_hz=mains, exclude_hz=exclude or None,
                add_missing=not picked,
            )
        caught = [str(w.message) for w in wlist]
    result, stab = fit.lsfd, fit.stabilization
    notes = list(fit.warnings)
    _print_notes(notes, caught, args.quiet)
    if not fit.success:
        print(f"warning: {fit.message}", file=sys.stderr)
    initial = fit.selected_poles if stab is not None else None
    label = (stab.method.split("+")[0].upper() if stab is not None and freqs is None else "start")
    print(format_table(result, frf, output=shown[0], reference=shown[1], initial=initial, initial_label=label,
                       status=fit.status))
    scatter = None
    if args.scatter_std:
        from .scatter import subset_scatter

        try:
            scatter = subset_scatter(frf, result)
        except ValueError as exc:
            print(f"warning: no scatter estimate: {exc}", file=sys.stderr)
    from .mif import indicator_summary

    doc = result_to_dict(fit, frf, extra={"input": str(args.input), "warnings": notes + caught,
                                          "mode_indicator": indicator_summary(frf, result.band, max_points=256)},
                         scatter=scatter)
    with errors_to_exit("analysis fit", (OSError, ValueError), prefix="cannot write the outputs: "):
        _write_outputs(args, frf, result, doc, pairs)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
