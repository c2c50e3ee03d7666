"""``python -m analysis stabilization INPUT --png OUT.png [options]``: draw a stabilization diagram.

Prints the automatically selected poles; ``--json`` writes every order's physical poles with
their stability class. Exit codes: 0 done, 2 bad input (message on stderr).
"""
from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["main", "build_parser"]


from .command_line import Parser as _Parser
from .command_line import add_estimator, add_threads, check_out_dir, cli_entry, errors_to_exit, parse_args, with_examples
from .errors import UsageError
from .outputs import check_outputs


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="python -m analysis stabilization",
                description="Stabilization diagram (paper Fig. 8) of LSCF or LSCE poles, optionally LSFD-refined, "
                            "with the mode indicator (CMIF, or MIF for one reference) beneath.")
    with_examples(p)
    p.add_argument("input", metavar="INPUT", help="recording (.h5) or UFF file with dataset-58 FRFs")
    p.add_argument("--png", metavar="OUT.png", required=True, help="write the diagram")
    p.add_argument("--json", metavar="OUT.json", help="write the poles of every order and the selected poles")
    p.add_argument("--max-order", type=int, metavar="N", help="largest model order in modes (default: automatic)")
    p.add_argument("--method", choices=("lsce", "lscf"), default="lscf",
                   help="initial-pole method (default lscf, as 'analysis fit')")
    p.add_argument("--lsfd", action="store_true", help="refine every order with a few LSFD iterations")
    p.add_argument("--band", metavar="LO:HI", help="frequency band in Hz (default: automatic)")
    p.add_argument("--log-freq", action="store_true", help="logarithmic frequency axis")
    add_estimator(p)
    add_threads(p)
    return p


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    """Run the command; returns the exit code (0 done, 2 bad input)."""
    from .inputs import InputError, load_input, parse_band_text

    args = parse_args(build_parser(), argv)
    if isinstance(args, int):
        return args
    with errors_to_exit("analysis stabilization", (InputError, UsageError)):
        check_outputs([args.png, args.json], [args.input])
        band = parse_band_text(args.band)
        if args.max_order is not None and args.max_order < 1:
            raise InputError(f"--max-order must be >= 1; got {args.max_order}")
        for path in (args.png, args.json):
            check_out_dir(path, error=InputError, message="cannot write {label}: its folder does not exist")
        frf = load_input(args.input, estimator=args.estimator)

    from .lscf import parse_band
    from .modal import damping_ratio, natural_freq_hz
    from .pipeline import default_band, default_max_modes
    from .plots import plot_stabilization
    from .report import write_json
    from .selection import select_clusters
    from .stabilization import stabilization

    with errors_to_exit("analysis stabilization", ValueError):
        with warnings.catch_warnings(record=True) as wlist:
            warnings.simplefilter("always")
            b = parse_band(band, frf.freq_hz) if band is not None else default_band(frf)
            n = args.max_order or default_max_modes(frf, b)
            stab = stabilization(frf, n, method=args.method, band=b, refine_lsfd=args.lsfd, wide_band=True)
            clusters = select_clusters(stab)
    for w in wlist:
        print(f"warning: {w.message}", file=sys.stderr)
    poles = np.array([c.pole for c in clusters], dtype=complex)
    print(f"stabilization ({stab.method}) in {stab.band[0]:.6g}..{stab.band[1]:.6g} Hz, orders 1..{n}")
    print(f"{'pole':>4s} {'f [Hz]':>10s} {'zeta [%]':>9s} {'orders':>7s}")
    for i, k in enumerate(np.argsort(natural_freq_hz(poles)) if poles.size else [], start=1):
        c = clusters[k]
        print(f"{i:4d} {natural_freq_hz(c.pole):10.4f} {100 * damping_ratio(c.pole):9.3f} {c.n_orders:7d}")
    missed = _visible_without_pole(frf, stab.band, natural_freq_hz(poles) if poles.size else np.zeros(0))
    if missed:
        print(f"warning: resonance(s) the data show at {', '.join(f'{x:.4g}' for x in missed)} Hz have no stable "
              f"pole up to order {n}: raise --max-order, narrow --band around them (weak modes beside strong ones "
              "need it), or pick them on the report's diagram", file=sys.stderr)
    with errors_to_exit("analysis stabilization", (OSError, ValueError), prefix="cannot write the outputs: "):
        plot_stabilization(stab, frf, args.png, selected=poles, log_freq=args.log_freq)
        print(f"diagram written to {args.png}")
        if args.json:
            doc = stab.to_dict()
            doc["selected"] = [
                {"freq_hz": float(natural_freq_hz(c.pole)), "damping": float(damping_ratio(c.pole)),
                 "n_orders": int(c.n_orders)} for c in clusters
            ]
            doc["input"] = str(args.input)
            write_json(args.json, doc)
            print(f"poles written to {args.json}")
    return 0


def _visible_without_pole(frf: Any, band: Sequence[float], pole_hz: np.ndarray) -> list[float]:
    """Frequencies (Hz) of the resonances the data show (:func:`analysis.visibility.visible_peaks`, the
    fit's completeness rule) that no selected pole accounts for."""
    from .visibility import unaccounted_peaks, visible_peaks

    df = frf.line_spacing_hz
    missed, _ = unaccounted_peaks(visible_peaks(frf, band), pole_hz, df)
    return sorted(p.freq_hz for p in missed)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
