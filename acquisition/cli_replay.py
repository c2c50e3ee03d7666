"""``python -m acquisition replay``: recompute FRFs from a recording's raw data with other settings.

    python -m acquisition replay REC.h5 --out NEW.h5 [--force-window WIDTH[,TAPER]|none]
        [--exp-window TAU|PCT%|none] [--window ...] [--exclude-hits 3,7-9] [--estimator H1|H2] [--overwrite]

The original is never modified: NEW.h5 receives a copy of the set-up, instrument, every hit
(accepted or rejected, counts and scaling untouched), the event log plus a replay event, and new
FRF results from the accepted hits that are not excluded. Windows not given keep the recording's.
``--window`` is shorthand: ``--window force=10ms,2ms;exp=1%``. With the original windows and no
exclusions the FRFs equal the original ones bit for bit.
"""
from __future__ import annotations

from collections.abc import Sequence

from analysis.command_line import cli_entry, errors_to_exit, recording_in_out

from .errors import RecordingError, UsageError
from .replay import replay
from .window_options import parse_windows

__all__ = ["main", "parse_hit_list"]


def parse_hit_list(text: str | None) -> set[int]:
    """``"3,7-9"`` -> {3, 7, 8, 9} (hit indices as stored)."""
    out: set[int] = set()
    if not text:
        return out
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        try:
            if "-" in part:
                a, b = part.split("-", 1)
                lo, hi = int(a), int(b)
                if hi < lo:
                    raise ValueError
                out.update(range(lo, hi + 1))
            else:
                out.add(int(part))
        except ValueError:
            raise UsageError(f"--exclude-hits {text!r}: write hit indices and ranges like 3,7-9") from None
    return out


def _split_window(text: str) -> tuple[str | None, str | None]:
    force = exp = None
    for item in text.split(";"):
        key, _, val = item.partition("=")
        key = key.strip().lower()
        if key == "force":
            force = val
        elif key == "exp":
            exp = val
        else:
            raise UsageError(f"--window {text!r}: use force=WIDTH[,TAPER] and/or exp=TAU|PCT%, joined by ';'")
    return force, exp


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    p = recording_in_out("python -m acquisition replay", __doc__, "the new recording to write")
    p.add_argument("--force-window", help="WIDTH[,TAPER] or none (default: the recording's)")
    p.add_argument("--exp-window", help="PCT%%, TAU or none (default: the recording's)")
    p.add_argument("--window", help="shorthand 'force=10ms,2ms;exp=1%%'")
    p.add_argument("--exclude-hits", help="hit indices to leave out, e.g. 3,7-9")
    p.add_argument("--estimator", choices=("H1", "H2", "h1", "h2"), default="H1",
                   help="the FRF estimate the new recording prefers: H1 (noise on the response, the default) or H2 "
                        "(noise on the force, e.g. a light hammer tip); fit, report, linearity and diagnose then use it")
    args = p.parse_args(argv)
    with errors_to_exit("replay", (UsageError, RecordingError, ValueError)):
        from analysis.recording import Recording

        force, exp = args.force_window, args.exp_window
        if args.window:
            f2, e2 = _split_window(args.window)
            force = f2 if f2 is not None else force
            exp = e2 if e2 is not None else exp
        with Recording(args.recording) as rec:
            base = rec.windows
            first = next(rec.hits(), None)
            fs = first.sample_rate_hz if first is not None else None
        windows = parse_windows(force, exp, fs, base) if (force is not None or exp is not None) else None
        averages = replay(args.recording, args.out, windows=windows, exclude=parse_hit_list(args.exclude_hits),
                          estimator=args.estimator, overwrite=args.overwrite)
    for a in averages:
        print(f"point {a.index + 1} ({a.point}): {a.n_averages} averages, windows {a.windows.describe()}")
    print(f"recording written: {args.out}")
    return 0
