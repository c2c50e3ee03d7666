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
from pathlib import Path
from typing import Any, Optional, Sequence, TextIO


from analysis.command_line import add_overwrite, cli_entry, exit_on, with_examples

from .capture import capture_to_file, open_analyser
from .errors import ImpactlabError, InvalidDeviceURL, RecordingError, SetupError, UsageError
from .terminal import summary_text, terminal_decider
from .window_options import DEFAULT_EXP_WINDOW, DEFAULT_FORCE_WINDOW, parse_windows

__all__ = ["main", "build_parser", "run_capture", "run_resume", "recorded_test", "check_points_on_device",
           "EXIT_INCOMPLETE"]

log = logging.getLogger(__name__)




def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m acquisition capture", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    with_examples(p)
    p.add_argument("--device", help="device URL, e.g. sim://?seed=1, socket://HOST:PORT, usb://VID:PID "
                                    "(with --resume: default, the recording's device)")
    p.add_argument("--out", help="recording to write (HDF5)")
    p.add_argument("--resume", metavar="REC.h5",
                   help="continue an interrupted capture: same set-up, plan and windows, appending to REC.h5")
    p.add_argument("--points", help="comma-separated measurement points (component:node:direction)")
    p.add_argument("--reference", help="hammer point of a roving-accelerometer test")
    p.add_argument("--mode", choices=("roving-hammer", "roving-accelerometer"),
                   help="default: roving-accelerometer with --reference, else roving-hammer")
    p.add_argument("--hits", type=int, help="accepted hits per point (default 5, or as recorded for a replay)")
    p.add_argument("--auto", action="store_true", help="accept every hit that passes the automatic checks")
    p.add_argument("--seed", type=int, help="random seed of a simulated device (sim://, usbsim://)")
    p.add_argument("--setup", help="set-up file (JSON/TOML of AcquisitionSetup.to_dict()); default: default_setup()")
    p.add_argument("--force-window", default=DEFAULT_FORCE_WINDOW,
                   help=f"WIDTH[,TAPER] after the trigger, or none (default {DEFAULT_FORCE_WINDOW})")
    p.add_argument("--exp-window", default=DEFAULT_EXP_WINDOW,
                   help="exponential window: PCT%% at block end, TAU (s/ms/samples), or none (default none)")
    p.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for each trigger (default 10)")
    add_overwrite(p, "replace an existing --out file")
    p.add_argument("-q", "--quiet", action="store_true", help="print only the final summary")
    return p


def _with_seed(url: str, seed: Optional[int]) -> str:
    if seed is None:
        return url
    if not url.startswith(("sim://", "usbsim://")):
        raise UsageError(f"--seed applies to simulated devices (sim://, usbsim://), not {url!r}")
    if "seed=" in url:
        raise UsageError(f"the URL {url!r} already has a seed; drop --seed or the URL's seed")
    return url + ("&" if "?" in url else "?") + f"seed={seed}"


def _continue_stream(url: str, n_recorded: int) -> str:
    """A simulated device resumed after ``n_recorded`` hits continues its random stream instead of
    playing the same strikes again: its seed moves on by the number of hits already recorded."""
    if not url.startswith(("sim://", "usbsim://")) or n_recorded <= 0 or "replay=" in url:
        return url
    import re

    m = re.search(r"([?&])seed=(-?\d+)", url)
    if m is None:
        return url + ("&" if "?" in url else "?") + f"seed={n_recorded}"
    return url[:m.start()] + f"{m.group(1)}seed={int(m.group(2)) + n_recorded}" + url[m.end():]


def check_points_on_device(parsed_url: Any, measurements: Sequence[Any]) -> None:
    """Before anything is opened or written: every point of the plan must lie on the structure a
    simulated device holds (the simulated frame of its ``config``); :class:`UsageError` names the
    point and the frame's nodes. Real devices measure whatever they are attached to."""
    from analysis.geometry import GeometryError

    from .urls import SimURL, UsbSimURL

    if not isinstance(parsed_url, (SimURL, UsbSimURL)) or parsed_url.options.get("replay"):
        return
    from simulator.config import FrameConfig  # a face wires the simulator in
    from simulator.geometry import frame_geometry

    try:
        geometry = frame_geometry(FrameConfig.load(parsed_url.options.get("config")))
        geometry.check_points(ch.point for m in measurements for ch in m.setup.channels)
    except GeometryError as exc:
        raise UsageError(f"{exc}: choose points on the frame (e.g. top:4:Z)") from None


def _plan(args: argparse.Namespace, replay_plan: Optional[dict]):
    from .session import TestPlan

    points: tuple = ()
    if args.points:
        points = tuple(p.strip() for p in args.points.split(",") if p.strip())
    mode = args.mode.replace("-", "_") if args.mode else ("roving_accelerometer" if args.reference else "roving_hammer")
    hits = args.hits if args.hits is not None else 5
    reference = args.reference
    if replay_plan and not args.points and not args.mode and not args.reference:
        mode = replay_plan.get("mode", mode)
        points = tuple(replay_plan.get("points", ()))
        if args.hits is None:
            hits = int(replay_plan.get("hits_per_point", hits))
        if mode == "roving_accelerometer":
            reference = replay_plan.get("reference")
    if hits < 1:
        raise UsageError(f"--hits {hits}: need at least one hit per point")
    try:
        return TestPlan(mode=mode, points=points, hits_per_point=hits, reference=reference)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _recorded_plan(rec: Any) -> dict:
    """The plan of a recording to replay: as stored, completed from its accepted hits."""
    plan = dict(rec.plan)
    hits = list(rec.hits(accepted_only=True, skip_damaged=True))
    order: list = []
    for h in hits:
        if h.measurement not in [m for m, _, _ in order]:
            order.append((h.measurement, h.point, h.reference))
    if plan.get("mode") not in ("roving_hammer", "roving_accelerometer"):
        refs = {r for _, _, r in order}
        plan["mode"] = "roving_hammer" if len(refs) > 1 or len(order) == 1 else "roving_accelerometer"
        plan.pop("reference", None)
        if plan["mode"] == "roving_accelerometer":
            plan["reference"] = order[0][2]
    if not plan.get("points"):
        plan["points"] = [p for _, p, _ in order]
    if "hits_per_point" not in plan and order:
        plan["hits_per_point"] = min(sum(1 for h in hits if h.measurement == m) for m, _, _ in order)
    return plan


def run_capture(args: argparse.Namespace, out_stream: Optional[TextIO] = None) -> tuple[int, Any]:
    """The capture job behind :func:`main`. Returns (exit code, SessionResult or None).

    Everything the operator typed is checked before the analyser is opened.
    """
    out_stream = sys.stdout if out_stream is None else out_stream  # resolved at call time (pipes, tests)
    from analysis.recording import Recording

    from .session import SessionError, auto_accept
    from .setup import AcquisitionSetup, default_setup, load_setup
    from .urls import SimURL, parse_device_url

    if args.resume:
        return run_resume(args, out_stream)
    if not args.device or not args.out:
        raise UsageError("give --device URL and --out REC.h5 (or --resume REC.h5 to continue a capture)")
    url = _with_seed(args.device, args.seed)
    out = Path(args.out)
    if out.exists() and not args.overwrite:
        raise UsageError(f"{out} exists: choose another --out file or add --overwrite")
    parsed = parse_device_url(url)
    replay_path = parsed.options.get("replay") if isinstance(parsed, SimURL) else None
    replay_plan = None
    if args.setup:
        setup = load_setup(args.setup)
    elif replay_path:
        with Recording(replay_path) as rec:
            try:
                setup = AcquisitionSetup.from_dict(rec.setup)
            except SetupError as exc:
                raise UsageError(f"{replay_path} holds no analyser set-up to replay ({exc}); give --setup") from None
            replay_plan = _recorded_plan(rec)
    else:
        setup = default_setup()
    plan = _plan(args, replay_plan)
    windows = parse_windows(args.force_window, args.exp_window, setup.sample_rate_hz)
    measurements = plan.measurements(setup)  # checks the set-up has a force channel and responses
    check_points_on_device(parsed, measurements)
    say = (lambda text: None) if args.quiet else (lambda text: print(text, file=out_stream, flush=True))
    try:
        result = capture_to_file(url, out, setup, plan, windows, decide=auto_accept if args.auto else terminal_decider(),
                                 progress=say, timeout_s=args.timeout, overwrite=args.overwrite)
    except SessionError as exc:
        print(f"capture: {exc}", file=sys.stderr)
        return 1, None
    return _finish(result, f"recording written: {out}", out_stream, quiet=args.quiet)


def recorded_test(args: argparse.Namespace) -> tuple:
    """What ``--resume REC.h5`` continues: (set-up, plan, windows, recorded hits, device URL or None),
    after checking that no option tries to change the recorded plan (capture and station alike)."""
    from analysis.recording import Recording

    from .session import TestPlan
    from .setup import AcquisitionSetup

    if args.out or args.points or args.reference or args.mode or args.setup or args.hits is not None:
        raise UsageError("--resume continues the recorded test as it was planned: drop --out, --points, --reference, "
                         "--mode, --hits and --setup")
    path = Path(args.resume)
    with Recording(path) as rec:
        try:
            setup = AcquisitionSetup.from_dict(rec.setup)
            planned = dict(rec.plan)
            device = planned.pop("device", None)
            fields: dict[str, Any] = {k: (tuple(v) if k == "points" else v) for k, v in planned.items()
                                      if k in ("mode", "points", "hits_per_point", "reference")}
            plan = TestPlan(**fields)
        except (SetupError, TypeError, ValueError) as exc:
            raise UsageError(f"{path} does not hold a capture plan and set-up to resume ({exc})") from None
        windows = rec.windows
        hits = list(rec.hits(skip_damaged=True))
    return setup, plan, windows, hits, device


def run_resume(args: argparse.Namespace, out_stream: Optional[TextIO] = None) -> tuple[int, Any]:
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
    url = _with_seed(url, args.seed) if args.seed is not None else url
    url = _continue_stream(url, len(hits))
    analyser = open_analyser(url)
    say = (lambda text: None) if args.quiet else (lambda text: print(text, file=out_stream, flush=True))
    with analyser:
        identity = retry_on_link_fault(analyser.identify)
        n_acc = sum(1 for h in hits if h.accepted)
        say(f"analyser: {identity}; resuming {path}: {n_acc} accepted hit(s) recorded, "
            f"{len(plan.measurements(setup))} point(s) x {plan.hits_per_point} hits, {plan.mode}")
        decide = auto_accept if args.auto else terminal_decider()
        with RecordingWriter.resume(path) as writer:
            writer.log("INFO", f"capture resumed on {url} with {n_acc} accepted hits recorded")
            session = CaptureSession(analyser, setup, plan, writer=writer, windows=windows, decide=decide,
                                     progress=say, timeout_s=args.timeout, resume_hits=hits)
            result = _run_session(session, writer)
    return _finish(result, f"recording completed: {path}", out_stream, quiet=args.quiet)


@cli_entry
def main(argv: Optional[Sequence[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        with exit_on("capture", ((UsageError, InvalidDeviceURL, SetupError, RecordingError), 2),
                     (ImpactlabError, 1, "device or session failure: "),
                     (ValueError, 2),  # bad values reaching the library (file contents, options)
                     (OSError, 1)):
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
