"""``python -m acquisition station``: the operator's capture station in the browser.

    python -m acquisition station --device URL --out REC.h5 [--points P1,P2,...] [--reference R] [--hits N]
        [--setup FILE] [--host 127.0.0.1] [--port 0] [--auto] [--seed N] [--force-window W] [--exp-window E]
    python -m acquisition station --resume REC.h5 [--device URL] [--host H] [--port P]

Serves the operator page and prints its URL first (with a random token: every request without it
is refused). Bound to 127.0.0.1 unless ``--host`` says otherwise. The page drives the same capture
session as ``capture`` and writes the same crash-safe recording: ``capture --resume`` continues a
station's recording and ``station --resume`` a capture's. Ctrl-C stops the station; the recording
keeps every hit written so far.
Exit status: 0 stopped after the test finished, 1 device or session failure, 2 bad input, 130 stopped early.
"""
from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

from analysis.command_line import with_examples
from analysis.errors import OutputBusy
from analysis.outputs import check_outputs

from .capture import open_analyser
from .capture_options import plan_from_options, recorded_test, with_seed
from .errors import ImpactlabError, InvalidDeviceURL, RecordingError, SetupError, UsageError
from .window_options import DEFAULT_EXP_WINDOW, DEFAULT_FORCE_WINDOW, parse_windows

__all__ = ["build_parser", "main"]

log = logging.getLogger(__name__)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m acquisition station", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    with_examples(p)
    p.add_argument("--device", help="device URL, e.g. sim://?seed=1, socket://HOST:PORT, usb://VID:PID")
    p.add_argument("--out", help="recording to write (HDF5)")
    p.add_argument("--resume", metavar="REC.h5", help="continue an interrupted capture or station recording")
    p.add_argument("--points", help="comma-separated measurement points (component:node:direction)")
    p.add_argument("--reference", help="hammer point of a roving-accelerometer test")
    p.add_argument("--mode", choices=("roving-hammer", "roving-accelerometer"),
                   help="default: roving-accelerometer with --reference, else roving-hammer")
    p.add_argument("--hits", type=int, help="accepted hits per point (default 5)")
    p.add_argument("--setup", help="set-up file (JSON/TOML of AcquisitionSetup.to_dict()); default: default_setup()")
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=int, default=0, help="port (default 0: any free port)")
    p.add_argument("--auto", action="store_true", help="start in auto mode (arm, accept and move on by itself)")
    p.add_argument("--seed", type=int, help="random seed of a simulated device (sim://, usbsim://)")
    p.add_argument("--force-window", default=DEFAULT_FORCE_WINDOW, help="WIDTH[,TAPER] or none (as capture)")
    p.add_argument("--exp-window", default=DEFAULT_EXP_WINDOW, help="PCT%%, TAU or none (as capture)")
    p.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for each trigger (default 10)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    return p


def _geometry(url: str) -> dict:
    """The test-plan view's wireframe: the simulated frame's for a simulated device, none otherwise."""
    from simulator.geometry import device_geometry  # a face wires the simulator in

    from .station.payloads import geometry_payload

    try:
        return geometry_payload(device_geometry(url))
    except (ImpactlabError, OSError, ValueError) as exc:
        log.warning("no frame geometry for the test-plan view: %s", exc)
        return geometry_payload(None)


def _prepare(args: argparse.Namespace) -> dict:
    """Everything checked and loaded before the analyser is opened."""
    from analysis.recording_writer import RecordingWriter

    from .session import channel_table
    from .setup import default_setup, load_setup

    if args.resume:
        path = Path(args.resume)
        setup, plan, windows, hits, device = recorded_test(args)
        url = args.device or device
        if not url:
            raise UsageError(f"{path} does not name its device: give --device URL")

        def reopen(setup: Any, win: Any) -> Any:
            w = RecordingWriter.resume(path)
            w.log("INFO", f"station resumed on {url} with {sum(1 for h in hits if h.accepted)} accepted hits recorded")
            return w

        return dict(url=with_seed(url, args.seed), setup=setup, plan=plan, windows=windows, resume_hits=hits,
                    open_writer=reopen, editable=False, out=path)
    if not args.device or not args.out:
        raise UsageError("give --device URL and --out REC.h5 (or --resume REC.h5 to continue a recording)")
    url = with_seed(args.device, args.seed)
    out = Path(args.out)
    check_outputs([out], [args.setup])
    if out.exists() and not args.overwrite:
        raise UsageError(f"{out} exists: choose another --out file or add --overwrite")
    setup = load_setup(args.setup) if args.setup else default_setup()
    plan = plan_from_options(args)
    windows = parse_windows(args.force_window, args.exp_window, setup.sample_rate_hz)
    from analysis.geometry import GeometryError
    from simulator.geometry import check_device_points  # a face wires the simulator in

    measurements = plan.measurements(setup)  # a force channel and responses
    try:
        check_device_points(url, (ch.point for m in measurements for ch in m.setup.channels))
    except GeometryError as exc:  # bad input: a point the simulated frame does not have
        raise UsageError(str(exc)) from None

    def open_writer(setup: Any, win: Any) -> Any:
        return RecordingWriter(out, instrument=identity_box["instrument"], setup=setup.to_dict(),
                               channels=channel_table(setup),
                               windows=win,
                               plan={**plan.to_dict(), "device": url, "front_end": "station"},
                               overwrite=args.overwrite)

    identity_box: dict = {"instrument": {}}
    return dict(url=url, setup=setup, plan=plan, windows=windows, resume_hits=(), open_writer=open_writer,
                editable=True, out=out, identity_box=identity_box)


def run_station(args: argparse.Namespace, out_stream: TextIO | None = None, ready: threading.Event | None = None) -> int:
    """Serve the station until it is stopped (Ctrl-C / SIGTERM). Returns the exit code."""
    out_stream = sys.stdout if out_stream is None else out_stream  # resolved at call time (pipes, tests)
    from analysis.web_assets import plotly_js_path

    from .session import retry_on_link_fault
    from .station.engine import StationEngine
    from .station.server import StationServer, new_token

    job = _prepare(args)
    geometry = _geometry(job["url"])
    analyser = open_analyser(job["url"], timeout_s=max(2.0, args.timeout))
    with analyser:
        identity = retry_on_link_fault(analyser.identify)
        caps = retry_on_link_fault(analyser.capabilities)
        if "identity_box" in job:
            job["identity_box"]["instrument"] = identity.as_dict() if hasattr(identity, "as_dict") else {}
        engine = StationEngine(analyser, job["setup"], job["plan"], capabilities=caps, windows=job["windows"],
                               open_writer=job["open_writer"], resume_hits=job["resume_hits"],
                               setup_editable=job["editable"], timeout_s=args.timeout, geometry=geometry,
                               auto=args.auto)
        engine.state.update(device=str(identity), recording=str(job["out"]))
        try:
            server = StationServer((args.host, args.port), engine, new_token(), plotly_js_path)
        except OSError as exc:
            raise UsageError(f"cannot serve on {args.host}:{args.port}: {exc}") from None
        print(server.url, file=out_stream, flush=True)
        try:
            plotly_js_path()
        except (ImportError, OSError) as exc:  # analysis.web_assets.MissingAssetError: plotly is not installed
            print(f"station: {exc}; the page works without plots until then", file=sys.stderr, flush=True)
        print(f"station: {identity}; recording {job['out']}; open the URL above in a browser (Ctrl-C stops)",
              file=out_stream, flush=True)
        if args.host not in ("127.0.0.1", "localhost", "::1"):
            print(f"station: serving on {args.host}: anyone who can reach this address and has the URL (token) can "
                  "steer the test; the link is plain HTTP", file=sys.stderr, flush=True)
        stop = threading.Event()

        def _term(signum: int, frame: Any) -> None:
            raise KeyboardInterrupt

        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGTERM, _term)
            # Ctrl-C stops the station even where the parent started it with SIGINT ignored (a job started
            # in the background by a script, a test runner's worker): Python then installs no handler of its own
            signal.signal(signal.SIGINT, _term)
        finished = False
        serving: threading.Thread | None = None
        try:  # from the engine's start on, a Ctrl-C (or SIGTERM) at any moment stops the threads it started
            engine.start()
            serving = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.5}, daemon=True)
            serving.start()
            if ready is not None:
                ready.set()
            while not stop.wait(1.0):
                pass
        except KeyboardInterrupt:
            pass
        finally:
            finished = engine.state.get("phase") == "finished"  # ended on the page before the stop (else: early)
            if serving is not None:  # shutdown() waits for serve_forever: only once it was started
                server.shutdown()
            server.server_close()
            engine.stop()
        if not Path(job["out"]).exists():
            print("station stopped before the first hit: nothing was recorded", file=out_stream, flush=True)
            return 0 if finished else 130  # stopped (Ctrl-C, SIGTERM) before the test ended: early, as documented
        print(f"station stopped; {job['out']} keeps every hit written"
              + ("" if finished else " (continue with 'python -m acquisition station --resume FILE' or "
                                     "'python -m acquisition capture --resume FILE')"), file=out_stream, flush=True)
        if engine.state.get("phase") == "error":
            print(f"station: {engine.state.get('error')}", file=sys.stderr, flush=True)
            return 1
        return 0 if finished else 130


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return run_station(args)
    except KeyboardInterrupt:  # Ctrl-C while the station was starting (the analyser opening)
        print("station: stopped while starting; nothing was recorded", file=sys.stderr)
        return 130
    except OutputBusy as exc:
        print(f"station: {exc}", file=sys.stderr)
        return 1
    except (UsageError, InvalidDeviceURL, SetupError, RecordingError) as exc:
        print(f"station: {exc}", file=sys.stderr)
        return 2
    except ImpactlabError as exc:
        print(f"station: device failure: {exc}", file=sys.stderr)
        return 1
    except ValueError as exc:
        print(f"station: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"station: {exc}", file=sys.stderr)
        return 1
