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
from typing import Any, Callable, Optional, Sequence, TextIO

import numpy as np

from analysis.command_line import with_examples
from analysis.command_line import add_overwrite, cli_entry, exit_on
from analysis.spectra import WindowSettings, excitation_band, parse_duration

from .errors import ImpactlabError, InvalidDeviceURL, RecordingError, SetupError, UsageError
from .operator import HitSummary
from .session_errors import OperatorQuit

__all__ = ["main", "build_parser", "parse_windows", "open_analyser", "summary_text", "DEFAULT_FORCE_WINDOW",
           "DEFAULT_EXP_WINDOW"]

log = logging.getLogger(__name__)

DEFAULT_FORCE_WINDOW = "20ms,5ms"
DEFAULT_EXP_WINDOW = "none"



def parse_windows(force: Optional[str], exp: Optional[str], fs_hz: Optional[float],
                  base: Optional[WindowSettings] = None) -> WindowSettings:
    """Window settings from the ``--force-window`` and ``--exp-window`` texts (None: keep ``base``)."""
    b = base or WindowSettings()
    fw, ft = b.force_width_s, b.force_taper_s
    tau, decay = b.exp_tau_s, b.exp_decay
    try:
        if force is not None:
            t = force.strip().lower()
            if t in ("none", "off", ""):
                fw, ft = None, 0.0
            else:
                parts = [x for x in t.split(",")]
                if len(parts) > 2:
                    raise UsageError(f"--force-window {force!r}: give WIDTH or WIDTH,TAPER (e.g. 10ms,2ms)")
                fw = parse_duration(parts[0], fs_hz)
                ft = parse_duration(parts[1], fs_hz) if len(parts) == 2 else 0.0
                if fw <= 0:
                    raise UsageError(f"--force-window {force!r}: the width must be positive")
        if exp is not None:
            t = exp.strip().lower()
            if t in ("none", "off", ""):
                tau, decay = None, None
            elif t.endswith("%"):
                decay = float(t[:-1]) / 100.0
                tau = None
                if not 0 < decay < 1:
                    raise UsageError(f"--exp-window {exp!r}: the end value must lie between 0 and 100 %")
            else:
                tau = parse_duration(t[4:] if t.startswith("tau=") else t, fs_hz)
                decay = None
                if tau <= 0:
                    raise UsageError(f"--exp-window {exp!r}: tau must be positive")
        return WindowSettings(fw, ft, tau, decay, b.exp_on_force)
    except UsageError:
        raise
    except ValueError as exc:
        raise UsageError(f"bad window option: {exc}") from None


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
    p.add_argument("--print-setup", action="store_true",
                   help="print the set-up (--setup FILE, else the default) as TOML and exit: a template for --setup")
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


def open_analyser(url: str, timeout_s: float = 10.0) -> Any:
    """An ``Analyser`` on ``url`` (``sim://?replay=REC.h5``: the simulated analyser plays a recording back
    through :class:`simulator.replay_stand.ReplayStand`). ``timeout_s`` bounds each command."""
    from .driver import Analyser

    return Analyser(url, timeout_s=timeout_s)


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


def summary_text(result: Any, estimator: str = "H1", n_peaks: int = 8, quiet: bool = False) -> str:
    """Hits accepted/rejected with reasons (``quiet``: counted by reason), an FRF peak table and the
    mean coherence per FRF."""
    from collections import Counter

    from scipy.signal import find_peaks

    lines = [f"hits accepted: {result.accepted}, rejected: {len(result.rejected)}"]
    if quiet and result.rejected:
        why = Counter(r.split(":")[0] for *_, reasons in result.rejected for r in reasons[:1])
        lines.append("  rejected: " + ", ".join(f"{n} x {reason}" for reason, n in why.most_common()))
    for m, point, idx, reasons in ([] if quiet else sorted(result.rejected, key=lambda r: r[2])):
        lines.append(f"  rejected hit #{idx + 1} at point {m + 1} ({point}): {'; '.join(reasons)}")
    avgs = [a for a in result.averages if a.n_averages > 0]
    if not avgs:
        lines.append("no FRF: no point has an accepted hit")
        return "\n".join(lines)
    for a in avgs:
        s = a.frfset(estimator)
        f = s.freq_hz
        hi = a.sample_rate_hz / 2.56  # alias-free band, from the acquisition's sample rate
        band = (f > 2.0) & (f <= hi)
        mag = np.abs(s.H[:, 0, :])
        live = [i for i in range(s.n_outputs) if np.any(a.acc.spectra()[1][i] > 0)]  # outputs with any signal
        # peaks of the sum of the live outputs' magnitudes, each normalised to its own maximum
        total = sum((np.where(band, mag[i], 0.0) / max(float(np.nanmax(np.where(band, mag[i], 0.0))), 1e-300)
                     for i in live), np.zeros(f.size))
        pk, prop = find_peaks(np.nan_to_num(total), prominence=0.02 * max(float(np.nanmax(total)), 1e-300))
        top = np.sort(pk[np.argsort(prop["prominences"])[::-1][:n_peaks]])
        tau = f"{s.exp_window_tau_s:.4g} s" if s.exp_window_tau_s else "none"
        lines.append(f"point {a.index + 1}: reference {a.reference}, {a.n_averages} averages, {estimator} "
                     f"[{s.unit}], exponential window tau {tau}")
        lines.append("  peak Hz " + "".join(f"{o:>24s}" for o in s.outputs))
        for k in top:
            cells = "".join(f"{mag[i, k]:12.4g} (coh {s.coherence[i, 0, k]:.3f})" if i in live else f"{'-':>24s}"
                            for i in range(s.n_outputs))
            lines.append(f"  {f[k]:7.2f} {cells}")
        coh = ", ".join(f"{o} {np.mean(s.coherence[i, 0, band]):.3f}" if i in live else f"{o} no signal (below 1 LSB)"
                        for i, o in enumerate(s.outputs))
        lines.append(f"  mean coherence 2..{hi:.0f} Hz: {coh}")
        gff = a.acc.spectra()[0]
        edges = excitation_band(f, 10 * np.log10(np.maximum(gff, max(float(np.max(gff)), 1e-300) * 1e-30)))
        e10, e20 = edges[10.0], edges[20.0]
        lines.append("  excitation band (force spectrum): "
                     + ", ".join(f"-{d:g} dB at {'beyond ' + format(hi, '.0f') if e is None or e > hi else format(e, '.0f')} Hz"
                                 for d, e in ((10, e10), (20, e20))))
        if e20 is not None and e20 < hi:
            lines.append(f"  warning: the hammer excites this point only up to {e20:.0f} Hz of the analyser's "
                         f"0..{hi:.0f} Hz band: modes above it are not measured well (fit below {e20:.0f} Hz, "
                         "or use a harder tip)")
    return "\n".join(lines)


def run_capture(args: argparse.Namespace, out_stream: Optional[TextIO] = None) -> tuple[int, Any]:
    """The capture job behind :func:`main`. Returns (exit code, SessionResult or None).

    Everything the operator typed is checked before the analyser is opened.
    """
    out_stream = sys.stdout if out_stream is None else out_stream  # resolved at call time (pipes, tests)
    from analysis.recording import Recording, RecordingWriter
    from .session import CaptureSession, auto_accept, channel_table, retry_on_link_fault
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
    analyser = open_analyser(url)
    with analyser:
        identity = retry_on_link_fault(analyser.identify)
        instrument = identity.as_dict() if hasattr(identity, "as_dict") else dict(vars(identity))
        say = (lambda text: None) if args.quiet else (lambda text: print(text, file=out_stream, flush=True))
        say(f"analyser: {identity}; {len(measurements)} point(s) x {plan.hits_per_point} hits, {plan.mode}")
        decide = auto_accept if args.auto else terminal_decider()
        with RecordingWriter(out, instrument=instrument, setup=setup.to_dict(), channels=channel_table(setup),
                             windows=windows.resolved(setup.block_size, setup.sample_rate_hz,
                                                      setup.trigger.pretrigger_samples),
                             plan={**plan.to_dict(), "device": url}, overwrite=args.overwrite) as writer:
            session = CaptureSession(analyser, setup, plan, writer=writer, windows=windows, decide=decide,
                                     progress=say, timeout_s=args.timeout)
            result = _run_session(session, writer)
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
    from analysis.recording import RecordingWriter

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


# -- the operator at a terminal -------------------------------------------------------------------
def read_key(prompt: str) -> str:
    """One key press at a terminal (no Enter needed); a whole line when stdin is not a terminal."""
    if not sys.stdin.isatty():
        return input(prompt)
    import termios
    import tty

    print(prompt, end="", flush=True)
    fd = sys.stdin.fileno()
    old = termios.tcgetattr(fd)
    try:
        tty.setcbreak(fd)
        key = sys.stdin.read(1)
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, old)
    print(key)
    if key in ("\x03", "\x04"):  # Ctrl-C, Ctrl-D
        raise EOFError
    return key


def terminal_decider(input_fn: Callable[[str], str] = read_key, out: TextIO = sys.stdout) -> Callable[[HitSummary], bool]:
    """An operator at a terminal (the capture CLI's ``decide``): key ``a`` (or Enter) accept, ``r`` reject, ``q`` quit (raises
    :class:`OperatorQuit`). ``input_fn(prompt) -> str`` reads the answer (default :func:`read_key`)."""

    def decide(summary: HitSummary) -> bool:
        while True:
            try:
                key = input_fn("accept (a), reject (r), quit (q)? ").strip().lower()
            except EOFError:
                raise OperatorQuit("input closed: ending the test") from None
            if key in ("a", "", "\n", "\r"):
                return True
            if key == "r":
                return False
            if key == "q":
                raise OperatorQuit("operator pressed q")
            print("please press a, r or q", file=out)

    return decide
