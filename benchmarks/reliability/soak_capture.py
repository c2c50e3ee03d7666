"""Soak test: a long capture with faults injected at random loses no accepted hit.

    .venv/bin/python benchmarks/reliability/soak_capture.py [--hits 1000] [--door sim|usbsim|loopback]
        [--faults KIND:P,...] [--seed N] [--out DIR] [--json]

The capture session runs in this process against a :class:`simulator.faults.FaultyFirmware`
reached through a real door (``sim``: the pyserial ``sim://`` handler and ``StreamTransport``;
``usbsim``: pyusb's core over ``SimUsbBackend`` and ``UsbTransport``; ``loopback``: the
cheapest in-process transport), so the firmware's ground truth is at hand:

* every accepted hit of the session is in the recording, complete, with a CRC-32 that matches
  its counts (``Recording.hit`` recomputes it) and equals the CRC-32 of the block the firmware
  digitised for that sequence number (nothing corrupted on the way);
* no accepted hit twice, none missing (recording accepted hits == session accepted == plan);
* no hang: every hit's wall time is recorded, the run is bounded by a watchdog
  (``faulthandler.dump_traceback_later`` aborts a hung run with a traceback).

Prints a table of faults injected by kind, link faults the session recovered from, hits
accepted/rejected/lost, and the wall time.
"""
from __future__ import annotations

import argparse
import collections
import faulthandler
import json
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

DEFAULT_FAULTS = ("no_trigger:0.02,double_hit:0.02,overload:0.01,short_transfer:0.01,check_condition:0.01,"
                  "phase_error:0.01,stall:0.01,garbage:0.005,disconnect:0.002,slow:0.01")
#: points of the soak's roving-hammer plan (hits are spread over them)
SOAK_POINTS = ("right:6:-X", "right:5:-X", "right:4:-X", "top:4:X", "top:3:X")


@dataclass
class SoakReport:
    """What a soak run measured."""

    door: str
    hits_target: int
    accepted: int = 0
    rejected: int = 0
    recorded_accepted: int = 0
    lost: int = 0
    corrupted: int = 0
    duplicated: int = 0
    link_faults_recovered: int = 0
    bot_recoveries: int = 0
    injected: dict = field(default_factory=dict)
    wall_s: float = 0.0
    max_hit_s: float = 0.0
    problems: list = field(default_factory=list)

    def table(self) -> str:
        lines = [f"door {self.door}: {self.accepted} accepted / {self.hits_target} planned, {self.rejected} rejected "
                 f"(automatic checks), {self.recorded_accepted} accepted hits in the recording",
                 f"lost {self.lost}, corrupted {self.corrupted}, duplicated {self.duplicated}; "
                 f"link faults recovered by the session {self.link_faults_recovered}, "
                 f"reset recoveries by the bulk-only layer {self.bot_recoveries}",
                 f"wall {self.wall_s:.1f} s, slowest hit {self.max_hit_s:.2f} s",
                 "| fault | injected |", "|---|---:|"]
        lines += [f"| {k} | {v} |" for k, v in sorted(self.injected.items())]
        lines += [f"| total | {sum(self.injected.values())} |"]
        if self.problems:
            lines.append("PROBLEMS: " + "; ".join(self.problems[:10]))
        return "\n".join(lines)


def _transport(door: str, fw: Any, timeout_s: float) -> Any:
    if door == "loopback":
        from acquisition.loopback import LoopbackTransport

        return LoopbackTransport(fw)
    if door == "sim":
        from acquisition.stream_transport import StreamTransport
        from acquisition.urlhandlers.protocol_sim import Serial

        return StreamTransport(Serial.from_firmware(fw, timeout=timeout_s), url="sim://")
    if door == "usbsim":
        from acquisition.usb_transport import UsbTransport
        from simulator.usb_backend import SimUsbBackend

        backend = SimUsbBackend(fw)
        return UsbTransport.find(backend.vid, backend.pid, backend=backend, url="usbsim://")
    raise ValueError(f"door {door!r}: use sim, usbsim or loopback")


def run_soak(hits: int, out: str | Path, *, door: str = "sim", faults: str = DEFAULT_FAULTS, seed: int = 1,
             points: tuple = SOAK_POINTS, command_timeout_s: float = 0.5, trigger_timeout_s: float = 2.0,
             hang_limit_s: float | None = None) -> SoakReport:
    """Capture ``hits`` accepted hits (spread over ``points``) through ``door`` with ``faults``
    injected, write the recording ``out``, and check it against the firmware's ground truth."""
    from acquisition.driver import Analyser
    from acquisition.session import CaptureSession, TestPlan, channel_table, retry_on_link_fault
    from acquisition.setup import default_setup
    from analysis.recording import Recording
    from analysis.recording_writer import RecordingWriter
    from analysis.spectra import WindowSettings
    from simulator.analyser import create_analyser

    n_points = max(1, min(len(points), hits))
    per_point = max(1, hits // n_points)
    plan = TestPlan(mode="roving_hammer", points=tuple(points[:n_points]), hits_per_point=per_point)
    target = per_point * n_points
    report = SoakReport(door, target)
    fw = create_analyser({"seed": seed, "faults": faults, "fault_seed": seed + 1000,
                          "packetized": door == "usbsim"})
    setup = default_setup()
    windows = WindowSettings()
    hit_times: list = []
    last = [time.monotonic()]

    def progress(text: str) -> None:
        if text.lstrip().startswith("progress:"):
            now = time.monotonic()
            hit_times.append(now - last[0])
            last[0] = now

    if hang_limit_s:
        faulthandler.dump_traceback_later(hang_limit_s, exit=True)
    t0 = time.monotonic()
    try:
        with Analyser(_transport(door, fw, command_timeout_s), timeout_s=command_timeout_s) as analyser:
            identity = retry_on_link_fault(analyser.identify)
            with RecordingWriter(out, instrument=identity.as_dict(), setup=setup.to_dict(),
                                 channels=channel_table(setup),
                                 windows=windows.resolved(setup.block_size, setup.sample_rate_hz,
                                                          setup.trigger.pretrigger_samples),
                                 plan={**plan.to_dict(), "device": f"{door}+faults"}, overwrite=True) as writer:
                session = CaptureSession(analyser, setup, plan, writer=writer, windows=windows, progress=progress,
                                         timeout_s=trigger_timeout_s, max_attempts_factor=20, max_timeouts=10)
                result = session.run()
            report.bot_recoveries = analyser.bot.recoveries
    finally:
        if hang_limit_s:
            faulthandler.cancel_dump_traceback_later()
    report.wall_s = time.monotonic() - t0
    report.max_hit_s = max(hit_times, default=0.0)
    report.accepted = result.accepted
    report.rejected = len(result.rejected)
    report.link_faults_recovered = session.link_faults
    report.injected = dict(fw.injected)
    seen: collections.Counter = collections.Counter()
    with Recording(out) as rec:
        for h in rec.hits():  # raises RecordingError on an incomplete hit or a CRC mismatch
            if not h.accepted:
                continue
            report.recorded_accepted += 1
            seen[h.sequence] += 1
            truth = fw.block_crc.get(h.sequence)
            from analysis.recording import counts_crc32

            if truth is None or counts_crc32(h.counts) != truth:
                report.corrupted += 1
                report.problems.append(f"hit {h.index} (sequence {h.sequence}) differs from the block the "
                                       "analyser digitised")
        frf_hits = sum(len(rec.frf_group(name)["hits"]) for name in rec.measurement_names())
    report.duplicated = sum(c - 1 for c in seen.values() if c > 1)
    report.lost = max(0, report.accepted - report.recorded_accepted) + max(0, target - report.accepted)
    if frf_hits != report.accepted:
        report.problems.append(f"FRF groups list {frf_hits} hits, the session accepted {report.accepted}")
    return report


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--hits", type=int, default=1000)
    p.add_argument("--door", choices=("sim", "usbsim", "loopback"), default="sim")
    p.add_argument("--faults", default=DEFAULT_FAULTS)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", default=None, help="directory for the recording (default: a temporary one)")
    p.add_argument("--hang-limit", type=float, default=3600.0, help="abort with a traceback after this many s")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    import logging

    logging.basicConfig(level=logging.ERROR)  # the session logs every recovered fault as a warning
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.out or tmp) / f"soak-{args.door}-{args.seed}.h5"
        rep = run_soak(args.hits, out, door=args.door, faults=args.faults, seed=args.seed,
                       hang_limit_s=args.hang_limit)
    print(json.dumps(rep.__dict__, indent=1) if args.json else rep.table())
    ok = rep.lost == 0 and rep.corrupted == 0 and rep.duplicated == 0 and not rep.problems
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
