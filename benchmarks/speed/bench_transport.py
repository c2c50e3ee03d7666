"""Sustained block throughput through each door, as a multiple of real time.

    .venv/bin/python benchmarks/speed/bench_transport.py [--block 65536] [--seconds 3] [--doors sim,socket,...]
                                                   [--profile DOOR]

Set-up: 4 channels at 51.2 kS/s (the default test plan's channels, rate raised to 51 200 Hz),
blocks of ``--block`` samples per channel. The structure's responses are precomputed once
(``simulator.firmware.PrecomputedStand`` holding one strike of the simulated frame), and the
firmware is told to strike at ARM (``polls=0``), so the figure measures the driver (bulk-only
envelope, READ BLOCK chunks of 64 KiB, decoding and scaling) and the transport, not the physics.

For each door the driver is configured once, then ``Analyser.capture()`` (ARM, GET STATUS,
READ BLOCK x k) is repeated for ``--seconds``. Reported: blocks, MB/s of block images, and
x real time = (blocks x block duration) / wall time. ``loopback`` (``LoopbackTransport``, no
link at all) is the ceiling set by driver + firmware.

``--profile DOOR`` runs cProfile on that door (in-process doors) and prints the top functions.
"""
from __future__ import annotations

import argparse
import cProfile
import dataclasses
import io
import pstats
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from acquisition import protocol as P  # noqa: E402
from acquisition.driver import Analyser  # noqa: E402
from acquisition.loopback import LoopbackTransport  # noqa: E402
from acquisition.setup import AcquisitionSetup, default_setup  # noqa: E402
from acquisition.stream_transport import StreamTransport  # noqa: E402
from acquisition.urls import open_transport  # noqa: E402
from acquisition.usb_transport import UsbTransport  # noqa: E402
from simulator.analyser import create_analyser  # noqa: E402
from simulator.firmware import PrecomputedStand  # noqa: E402
from simulator.urlhandlers.protocol_sim import Serial as SimSerial  # noqa: E402
from simulator.usb_backend import SimUsbBackend  # noqa: E402

FS = 51200.0
DOORS = ("loopback", "sim", "usbsim", "socket", "pty")
OPTIONS = {"polls": "0"}  # strike at ARM: no GET STATUS round trips waiting for the operator


def bench_setup(block: int) -> AcquisitionSetup:
    """The default plan's 4 channels at 51.2 kS/s with ``block`` samples per channel."""
    base = default_setup()
    return dataclasses.replace(base, sample_rate_hz=FS, block_size=block)


def precompute(setup: AcquisitionSetup, seed: int) -> tuple[np.ndarray, float]:
    """One strike of the simulated frame for this set-up: input volts[n_ch, n + margin]."""
    fw = create_analyser({"seed": seed})
    with Analyser(LoopbackTransport(fw)) as a:
        a.configure(setup)  # gives the stand its channels
    event = fw.stand.strike(FS, setup.block_size + fw.margin, setup.trigger.pretrigger_samples)
    return np.asarray(event.volts, dtype=float), FS


def _server(kind: str, npz: Path) -> tuple[subprocess.Popen, str]:
    door = ["--tcp", "127.0.0.1:0"] if kind == "socket" else ["--pty"]
    args = [sys.executable, "-m", "simulator", "serve", *door, "--precomputed", str(npz)]
    for k, v in OPTIONS.items():
        args += ["--option", f"{k}={v}"]
    proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    url = proc.stdout.readline().strip()
    if not url:
        proc.kill()
        raise RuntimeError(f"the {kind} server did not start")
    return proc, url


def open_door(door: str, stand: PrecomputedStand, npz: Path) -> tuple[Analyser, Callable[[], None]]:
    """An Analyser through ``door`` and a clean-up function."""
    nothing: Callable[[], None] = lambda: None  # noqa: E731
    if door == "loopback":
        return Analyser(LoopbackTransport(create_analyser(OPTIONS, stand=stand))), nothing
    if door == "sim":
        port = SimSerial.from_firmware(create_analyser(OPTIONS, stand=stand))
        return Analyser(StreamTransport(port, url="sim://")), nothing
    if door == "usbsim":
        backend = SimUsbBackend(create_analyser(dict(OPTIONS, packetized=True), stand=stand))
        return Analyser(UsbTransport.find(backend.vid, backend.pid, backend=backend, url="usbsim://")), nothing
    if door in ("socket", "pty"):
        proc, url = _server(door, npz)

        def stop() -> None:
            proc.send_signal(signal.SIGTERM)
            proc.wait(timeout=5)
            proc.stdout.close()

        return Analyser(open_transport(url), timeout_s=10.0), stop
    raise SystemExit(f"unknown door {door!r}; choose from {', '.join(DOORS)}")


def run_door(door: str, setup: AcquisitionSetup, stand: PrecomputedStand, npz: Path, seconds: float,
             profile: bool = False) -> dict:
    analyser, cleanup = open_door(door, stand, npz)
    try:
        analyser.configure(setup)
        analyser.capture(timeout_s=10.0)  # warm-up: the firmware digitises the cached record once
        prof = cProfile.Profile() if profile else None
        blocks = 0
        t0 = time.perf_counter()
        if prof:
            prof.enable()
        while True:
            analyser.capture(timeout_s=10.0)
            blocks += 1
            elapsed = time.perf_counter() - t0
            if elapsed >= seconds and blocks >= 3:
                break
        if prof:
            prof.disable()
    finally:
        analyser.close()
        cleanup()
    image = P.block_image_size(len(setup.channels), setup.block_size)
    result = {"door": door, "blocks": blocks, "seconds": elapsed,
              "mb_per_s": blocks * image / elapsed / 1e6,
              "x_real_time": blocks * setup.block_size / setup.sample_rate_hz / elapsed,
              "ms_per_block": 1e3 * elapsed / blocks}
    if prof:
        out = io.StringIO()
        pstats.Stats(prof, stream=out).sort_stats("cumulative").print_stats(25)
        out.write("\n")
        pstats.Stats(prof, stream=out).sort_stats("tottime").print_stats(15)
        result["profile"] = out.getvalue()
    return result


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--block", type=int, default=65536, help="samples per channel (256..65536)")
    ap.add_argument("--seconds", type=float, default=3.0, help="measuring time per door")
    ap.add_argument("--doors", default=",".join(DOORS), help="comma-separated subset of " + ", ".join(DOORS))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--profile", default=None, metavar="DOOR", help="cProfile this door (in-process doors)")
    args = ap.parse_args(argv)

    setup = bench_setup(args.block)
    t0 = time.perf_counter()
    volts, fs = precompute(setup, args.seed)
    stand = PrecomputedStand(volts, fs)
    print(f"precomputed one strike ({volts.shape[0]} ch x {volts.shape[1]} samples) in "
          f"{time.perf_counter() - t0:.1f} s")
    image = P.block_image_size(len(setup.channels), setup.block_size)
    print(f"4 channels at {FS:.0f} S/s, block {setup.block_size} samples ({setup.duration_s * 1e3:.0f} ms, "
          f"{image / 1e6:.3f} MB image), {args.seconds:g} s per door\n")
    doors = [d.strip() for d in args.doors.split(",") if d.strip()]
    if args.profile and args.profile not in doors:
        doors.append(args.profile)
    with tempfile.TemporaryDirectory() as tmp:
        npz = Path(tmp) / "stand.npz"
        np.savez(npz, volts=volts, fs_hz=fs)
        print(f"{'door':10s} {'blocks':>7s} {'ms/block':>9s} {'MB/s':>8s} {'x real time':>12s}")
        profiles = []
        for door in doors:
            r = run_door(door, setup, stand, npz, args.seconds, profile=(door == args.profile))
            print(f"{r['door']:10s} {r['blocks']:7d} {r['ms_per_block']:9.2f} {r['mb_per_s']:8.1f} "
                  f"{r['x_real_time']:12.1f}", flush=True)
            if "profile" in r:
                profiles.append((door, r["profile"]))
        for door, text in profiles:
            print(f"\n--- profile of {door} ---\n{text}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
