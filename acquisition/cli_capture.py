"""``python -m acquisition capture``: run an impact test and write a recording.

    python -m acquisition capture --device URL --out REC.h5 [--points P1,P2,...] [--reference POINT]
        [--mode roving-hammer|roving-accelerometer] [--hits N] [--auto] [--seed N] [--setup FILE]
        [--force-window WIDTH[,TAPER]|none] [--exp-window TAU|PCT%|none] [--timeout S] [--overwrite]
    python -m acquisition capture --resume REC.h5 [--device URL] [--auto] [--timeout S]

Without ``--points`` the plan is one measurement with the set-up's own points (the default set-up:
hammer at ``right:6:-X``, accelerometers at ``left:9:Y``, ``top:4:X``, ``right:4:-Z``). With
``--points`` and no ``--reference`` the hammer roves over the points; with ``--reference`` the
hammer stays there and the first accelerometer roves. ``--seed`` is added to a simulator URL.
``sim://?replay=REC.h5`` plays a recording back through the simulated analyser.

Windows: ``--force-window 10ms,2ms`` (rectangle 10 ms after the trigger, 2 ms cosine taper; s, ms
or samples); ``--exp-window 1%`` (decays to 1 % at the block end), ``--exp-window 0.3s`` (tau).
Exit status: 0 done, 1 device or session failure, 2 bad input.
"""
from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

from analysis.command_line import add_overwrite, cli_entry, exit_on, with_examples
from analysis.outputs import check_outputs

from .capture import capture_to_file, open_analyser
from .capture_options import (
    continue_stream,
    plan_from_options,
    recorded_auto,
    recorded_plan,
    recorded_test,
    with_levels,
    with_seed,
)
from .errors import ImpactlabError, InvalidDeviceURL, RecordingError, SetupError, UsageError
from .terminal import summary_text, terminal_decider
from .window_options import DEFAULT_EXP_WINDOW, DEFAULT_FORCE_WINDOW, parse_windows

__all__ = ["main", "build_parser", "run_capture", "run_resume", "EXIT_INCOMPLETE"]

log = logging.getLogger(__name__)




def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m acquisition capture", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    with_examples(p)
    p.add_argument("--device", help="device URL, e.g. sim://?seed=1, socket://HOST:PORT, usb://VID:PID "
                                    "(with --resume: default, the recording's device)")
    p.add_argument("--out", help="recording to write (HDF5)")
    p.add_argument("--resume", metavar="REC.h5",
                   help="continue an interrupted capture: same set-up, plan, windows and device, appending to "
                        "REC.h5; a capture made with --auto goes on with --auto")
    p.add_argument("--points", help="comma-separated measurement points (component:node:direction)")
    p.add_argument("--reference", help="hammer point of a roving-accelerometer test")
    p.add_argument("--mode", choices=("roving-hammer", "roving-accelerometer"),
                   help="default: roving-accelerometer with --reference, else roving-hammer")
    p.add_argument("--hits", type=int, help="accepted hits per point (default 5, or as recorded for a replay)")
    p.add_argument("--soft-hard", action="store_true",
                   help="strike each point --hits times softly, then --hits times hard (the prompts say which): "
                        "one recording for 'analysis linearity REC.h5'; a simulated device's operator does the same")
    p.add_argument("--auto", action="store_true",
                   help="accept every hit that passes the automatic checks (recorded: --resume goes on automatically)")
    p.add_argument("--seed", type=int, help="random seed of a simulated device (sim://, usbsim://)")
    p.add_argument("--setup", help="set-up file (JSON/TOML of AcquisitionSetup.to_dict()); default: default_setup()")
    p.add_argument("--print-setup", action="store_true",
                   help="print the set-up (--setup FILE, else the default) as TOML and exit: a template for --setup")
    p.add_argument("--force-window", default=DEFAULT_FORCE_WINDOW,
                   help=f"WIDTH[,TAPER] after the trigger, or none (default {DEFAULT_FORCE_WINDOW})")
    p.add_argument("--exp-window", default=DEFAULT_EXP_WINDOW,
                   help="exponential window: PCT%% at block end, TAU (s/ms/samples), or none "
                        f"(default {DEFAULT_EXP_WINDOW.replace('%', '%%')})")
    p.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for each trigger (default 10)")
    add_overwrite(p, "replace an existing --out file")
    p.add_argument("-q", "--quiet", action="store_true", help="print only the final summary")
    return p


def run_capture(args: argparse.Namespace, out_stream: TextIO | None = None) -> tuple[int, Any]:
    """The capture job behind :func:`main`. Returns (exit code, SessionResult or None).

    Everything the operator typed is checked before the analyser is opened.
    """
    out_stream = sys.stdout if out_stream is None else out_stream  # resolved at call time (pipes, tests)
    from analysis.geometry import GeometryError
    from analysis.recording import Recording
    from simulator.geometry import check_device_points  # a face wires the simulator in

    from .session import SessionError, auto_accept
    from .setup import AcquisitionSetup, default_setup, load_setup
    from .urls import SimURL, parse_device_url

    if args.resume:
        return run_resume(args, out_stream)
    if not args.device or not args.out:
        raise UsageError("give --device URL and --out REC.h5 (or --resume REC.h5 to continue a capture)")
    url = with_seed(args.device, args.seed)
    out = Path(args.out)
    parsed = parse_device_url(url)
    replay_path = parsed.options.get("replay") if isinstance(parsed, SimURL) else None
    check_outputs([out], [args.setup, replay_path])
    if out.exists() and not args.overwrite:
        raise UsageError(f"{out} exists: choose another --out file or add --overwrite")
    replay_plan = None
    if args.setup:
        setup = load_setup(args.setup)
    elif replay_path:
        with Recording(replay_path) as rec:
            try:
                setup = AcquisitionSetup.from_dict(rec.setup)
            except SetupError as exc:
                raise UsageError(f"{replay_path} holds no analyser set-up to replay ({exc}); give --setup") from None
            replay_plan = recorded_plan(rec)
    else:
        setup = default_setup()
    plan = plan_from_options(args, replay_plan)
    url = with_levels(url, plan)
    windows = parse_windows(args.force_window, args.exp_window, setup.sample_rate_hz)
    measurements = plan.measurements(setup)  # checks the set-up has a force channel and responses
    try:
        check_device_points(url, (ch.point for m in measurements for ch in m.setup.channels))
    except GeometryError as exc:  # bad input: a point the simulated frame does not have
        raise UsageError(str(exc)) from None
    say = (lambda text: None) if args.quiet else (lambda text: print(text, file=out_stream, flush=True))
    try:
        result = capture_to_file(url, out, setup, plan, windows, decide=auto_accept if args.auto else terminal_decider(),
                                 progress=say, timeout_s=args.timeout, overwrite=args.overwrite)
    except SessionError as exc:
        print(f"capture: {exc}", file=sys.stderr)
        return 1, None
    done = _finish(result, f"recording written: {out}", out_stream, quiet=args.quiet)
    if result is not None and not args.quiet:
        _print_quality(out, out_stream)
    return done


def _print_quality(path: Path, out_stream: TextIO) -> None:
    """The recording's quality checks (linearity when the hits span force levels, reciprocity, driving
    points), one line each; a check that cannot run is named, the recording stays as written."""
    from analysis.errors import ImpactlabError
    from analysis.quality import quality_lines, recording_quality

    try:
        lines = quality_lines(recording_quality(path))
    except (ImpactlabError, ValueError, OSError) as exc:
        lines = [f"not checked ({exc})"]
    for line in lines:
        print(f"quality: {line}", file=out_stream)


def run_resume(args: argparse.Namespace, out_stream: TextIO | None = None) -> tuple[int, Any]:
    """``capture --resume REC.h5``: continue an interrupted capture with the recording's set-up, plan,
    windows and device (``--device`` overrides it), appending to the same file. The accepted hits
    already recorded (complete, CRC-checked) count towards each point's average."""
    out_stream = sys.stdout if out_stream is None else out_stream  # resolved at call time (pipes, tests)
    from analysis.recording_writer import RecordingWriter

    from .session import CaptureSession, auto_accept, retry_on_link_fault

    path = Path(args.resume)
    setup, plan, windows, hits, device = recorded_test(args)
    url = args.device or device
    if not url:
        raise UsageError(f"{path} does not name its device: give --device URL")
    url = with_seed(url, args.seed) if args.seed is not None else url
    url = continue_stream(url, len(hits))
    analyser = open_analyser(url)
    say = (lambda text: None) if args.quiet else (lambda text: print(text, file=out_stream, flush=True))
    with analyser:
        identity = retry_on_link_fault(analyser.identify)
        n_acc = sum(1 for h in hits if h.accepted)
        say(f"analyser: {identity}; resuming {path}: {n_acc} accepted hit(s) recorded, "
            f"{len(plan.measurements(setup))} point(s) x {plan.hits_per_point} hits, {plan.mode}")
        auto = args.auto or recorded_auto(path)
        if auto and not args.auto:
            say("hits accepted automatically, as when the recording was made (--auto)")
        decide = auto_accept if auto else terminal_decider()
        with RecordingWriter.resume(path) as writer:
            writer.log("INFO", f"capture resumed on {url} with {n_acc} accepted hits recorded")
            session = CaptureSession(analyser, setup, plan, writer=writer, windows=windows, decide=decide,
                                     progress=say, timeout_s=args.timeout, resume_hits=hits)
            result = _run_session(session, writer)
    return _finish(result, f"recording completed: {path}", out_stream, quiet=args.quiet)


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        with exit_on("capture", ((UsageError, InvalidDeviceURL, SetupError, RecordingError), 2),
                     (ImpactlabError, 1, "device or session failure: "),
                     (ValueError, 2),  # bad values reaching the library (file contents, options)
                     (OSError, 1)):
            if args.print_setup:
                from .setup import default_setup, load_setup, setup_to_toml

                print(setup_to_toml(load_setup(args.setup) if args.setup else default_setup()), end="")
                return 0
            code, _ = run_capture(args)
            return code
    except KeyboardInterrupt:
        print(f"capture: interrupted; {args.out or args.resume} keeps every hit written so far "
              "(continue with 'python -m acquisition capture --resume FILE', or recompute its FRFs with "
              "'python -m acquisition replay')", file=sys.stderr)
        return 130


def _run_session(session, writer):
    """Run a capture session; a :class:`SessionError` is logged in the recording, shown, and gives None
    (every accepted hit is already on disk)."""
    from .session import SessionError

    try:
        return session.run()
    except SessionError as exc:
        writer.log("ERROR", str(exc))
        print(f"capture: {exc}", file=sys.stderr)
        return None


#: exit code of a test the operator ended before its plan was complete ('q'): the recording keeps
#: every hit and 'capture --resume' finishes it
EXIT_INCOMPLETE = 3


def _finish(result, done_line: str, out_stream, quiet: bool = False):
    """Exit code and result of a capture: the summary and ``done_line`` when the session completed;
    ``EXIT_INCOMPLETE`` when the operator ended it early."""
    if result is None:
        return 1, None
    print(summary_text(result, quiet=quiet), file=out_stream)
    print(done_line, file=out_stream)
    if result.aborted:
        print("capture: the test ended before every point had its hits; continue it with "
              "'impactlab capture --resume FILE'", file=sys.stderr)
        return EXIT_INCOMPLETE, result
    return 0, result
