"""``python -m acquisition demo --out DIR``: the ``make demo`` job.

Runs a roving-hammer session on the simulated frame (three points, five accepted hits each,
``--auto``, force window 20 ms + 5 ms taper, exponential window to 5 % at the block end) through
the real firmware, bulk-only protocol and driver. Two hits are spoiled on
purpose, deterministically: strike 2 is a double hit and strike 6 an overload (a hit far too
hard for the input range); the session rejects both with the reason. Then it prints a summary
(hits accepted/rejected with reasons, FRF peak table, coherence), writes the recording
``DIR/demo.h5`` and its UFF export ``DIR/demo.uff``.

The job is a list of steps (:data:`STEPS`), each ``step(ctx) -> None`` reading and filling the
:class:`DemoContext`; a fitting step appends to the list.
"""
from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from analysis.command_line import cli_entry, with_examples

__all__ = ["main", "DemoContext", "ScriptedStand", "STEPS", "DEMO_POINTS"]

#: roving-hammer points of the demo (the frame's test plan, first three)
DEMO_POINTS = ("right:6:-X", "top:4:Z", "left:9:Y")
#: the frame's lowest mode (12.9 Hz, 0.86 % damping) still rings at 3 % at the block end: an exponential
#: window down to 5 % at the block end stops the leakage (tau is stored; the fitter removes 1/tau)
DEMO_EXP_WINDOW = "5%"
#: 1600 Hz (625 Hz bandwidth) x 8192 samples: 5.12 s blocks, df 0.195 Hz, for the paper's 5-200 Hz band
DEMO_SAMPLE_RATE_HZ = 1600.0
#: the band the demo fits (the paper's frame band)
DEMO_FIT_BAND_HZ = (4.0, 215.0)
#: a soft tip (4 ms pulse) puts the force's energy in the band of interest; a hard tip's spectrum
#: reaches past fs/2 and the band-limited pulse rings (Gibbs), which the double-hit check flags
DEMO_HAMMER_TIP = "soft"
DOUBLE_HIT_STRIKE = 2
OVERLOAD_STRIKE = 6


class ScriptedStand:
    """The simulated stand with a script: chosen strikes (1-based) are spoiled through the stand's
    own one-shot options (``TestStand.next_strike``): a double hit, or a hit ``overload_scale`` times
    too hard (the analyser inputs clip). The hammer goes where the force channel's point says
    (the firmware aims the hammer at the force channel's point).
    """

    def __init__(self, stand: Any, double_hits: Sequence[int] = (), overloads: Sequence[int] = (),
                 overload_scale: float = 30.0) -> None:
        self.stand = stand
        self.double_hits = set(double_hits)
        self.overloads = set(overloads)
        self.overload_scale = overload_scale
        self.strikes = 0

    def set_channels(self, channels: Sequence[Any]) -> None:
        self.stand.set_channels(channels)

    def set_hammer_point(self, point: str) -> None:
        self.stand.set_hammer_point(point)

    def strike(self, fs_hz: float, n_samples: int, pretrigger: int) -> Any:
        self.strikes += 1
        if self.strikes in self.double_hits:
            self.stand.next_strike(double_hit=True)
        elif self.strikes in self.overloads:
            self.stand.next_strike(amplitude_scale=self.overload_scale, double_hit=False)
        return self.stand.strike(fs_hz, n_samples, pretrigger)


@dataclass
class DemoContext:
    out_dir: Path
    seed: int = 1
    hits: int = 5
    points: tuple = DEMO_POINTS
    recording: Path | None = None
    uff: Path | None = None
    result: Any = None
    frf: Any = None
    true_model: Any = None
    lines: list = field(default_factory=list)

    def say(self, text: str) -> None:
        self.lines.append(text)
        print(text, flush=True)


def capture_step(ctx: DemoContext) -> None:
    """The session on the simulated frame (loopback link to the simulated firmware)."""
    from analysis.recording_writer import RecordingWriter
    from simulator.analyser import create_analyser
    from simulator.config import FrameConfig
    from simulator.stand import TestStand

    from .driver import Analyser
    from .loopback import LoopbackTransport
    from .session import CaptureSession, TestPlan, auto_accept, channel_table
    from .setup import DEFAULT_SLOWEST_MODE, block_size_for_decay, default_setup
    from .window_options import DEFAULT_FORCE_WINDOW, parse_windows

    config = FrameConfig.load().with_overrides({"hammer": {"tip": DEMO_HAMMER_TIP, "double_hit_delay_s": [0.012, 0.02]}})
    stand = ScriptedStand(TestStand(config, seed=ctx.seed), double_hits=[DOUBLE_HIT_STRIKE], overloads=[OVERLOAD_STRIKE])
    ctx.true_model = stand.stand.model
    fw = create_analyser({"seed": ctx.seed}, stand=stand)
    base = default_setup()  # the demo's rate, the block that lets the slowest mode decay at that rate
    setup = replace(base, sample_rate_hz=DEMO_SAMPLE_RATE_HZ, block_size=block_size_for_decay(
        DEMO_SAMPLE_RATE_HZ, *DEFAULT_SLOWEST_MODE, pretrigger_samples=base.trigger.pretrigger_samples))
    plan = TestPlan(mode="roving_hammer", points=ctx.points, hits_per_point=ctx.hits)
    windows = parse_windows(DEFAULT_FORCE_WINDOW, DEMO_EXP_WINDOW, setup.sample_rate_hz).resolved(
        setup.block_size, setup.sample_rate_hz, setup.trigger.pretrigger_samples)
    ctx.recording = ctx.out_dir / "demo.h5"  # the demo's own: replaced, unless a live writer has it open
    with Analyser(LoopbackTransport(fw, url=f"sim://?seed={ctx.seed}")) as analyser:
        identity = analyser.identify()
        ctx.say(f"analyser: {identity}  (simulated frame, seed {ctx.seed}; strike {DOUBLE_HIT_STRIKE} is a double "
                f"hit and strike {OVERLOAD_STRIKE} an overload, on purpose)")
        with RecordingWriter(ctx.recording, instrument=identity.as_dict(), setup=setup.to_dict(),
                             channels=channel_table(setup), windows=windows,
                             plan={**plan.to_dict(), "device": "sim:// (demo, scripted stand)"}, overwrite=True) as writer:
            session = CaptureSession(analyser, setup, plan, writer=writer, windows=windows, decide=auto_accept,
                                     progress=ctx.say)
            ctx.result = session.run()
    ctx.frf = ctx.result.frfset("H1")


def summary_step(ctx: DemoContext) -> None:
    from .terminal import summary_text

    ctx.say("")
    ctx.say(summary_text(ctx.result))


def export_step(ctx: DemoContext) -> None:
    from .cli_export import export

    assert ctx.recording is not None, "the capture step comes first"
    ctx.uff = ctx.out_dir / "demo.uff"
    n = export(ctx.recording, ctx.uff, overwrite=True)
    ctx.say(f"recording: {ctx.recording}   UFF 58 export: {ctx.uff} ({n} datasets)")


def fit_step(ctx: DemoContext) -> None:
    """Multi-reference LSFD fit of the recorded FRFs (global poles), against the frame's true modes."""
    import numpy as np

    from analysis.pipeline import fit_auto
    from analysis.plots import plot_fit, plot_stabilization
    from analysis.report import format_table, result_to_dict, write_json
    frf = ctx.frf
    fit = fit_auto(frf, band=DEMO_FIT_BAND_HZ, method="lm")
    result, stab = fit.lsfd, fit.stabilization
    live = [(i, j) for i in range(frf.n_outputs) for j in range(frf.n_references)
            if np.all(np.isfinite(frf.H[i, j])) and np.any(frf.H[i, j] != 0)]
    oi, rj = max(live, key=lambda ij: float(np.max(np.abs(frf.band(*DEMO_FIT_BAND_HZ).H[ij[0], ij[1]]))))
    ctx.say("")
    ctx.say(format_table(result, frf, output=oi, reference=rj,
                         initial=None if stab is None else fit.selected_poles))
    f_true, z_true, _ = ctx.true_model.modes()  # the frame with the accelerometers' mass on it
    f_true, z_true = np.asarray(f_true), np.asarray(z_true)
    lo, hi = DEMO_FIT_BAND_HZ
    in_band = np.flatnonzero((f_true >= lo) & (f_true <= hi))
    ctx.say("")
    ctx.say("the simulated frame's true modes in the band vs the fitted poles (exponential window removed):")
    ctx.say(f"  {'f true [Hz]':>11} {'f fit':>9} {'df [%]':>8} {'zeta true [%]':>14} {'zeta fit':>9}")
    used: set = set()
    matched = 0
    for k in in_band:
        # a true mode is matched by the nearest unused fitted pole within a quarter of the gap to
        # its neighbours (and 1 %)
        gaps = np.abs(np.delete(f_true, k) - f_true[k])
        tol = min(0.01 * f_true[k], 0.25 * float(gaps.min()) if gaps.size else np.inf)
        cand = [i for i in np.argsort(np.abs(result.freq_hz - f_true[k]))
                if i not in used and abs(result.freq_hz[i] - f_true[k]) <= tol]
        if cand:
            i = int(cand[0])
            used.add(i)
            matched += 1
            f, z = result.freq_hz[i], result.damping[i]
            ctx.say(f"  {f_true[k]:11.3f} {f:9.3f} {100 * (f - f_true[k]) / f_true[k]:8.3f} "
                    f"{100 * z_true[k]:14.3f} {100 * z:9.3f}")
        else:
            ctx.say(f"  {f_true[k]:11.3f} {'missed':>9}")
    extra = [f"{result.freq_hz[i]:.3f}" for i in range(result.freq_hz.size) if i not in used]
    ctx.say(f"{matched} of {in_band.size} true modes matched"
            + (f"; unmatched fitted poles at {', '.join(extra)} Hz" if extra else ""))
    write_json(ctx.out_dir / "fit.json", result_to_dict(fit, frf))
    plot_fit(frf, result, ctx.out_dir / "fit.png", pairs=[(oi, rj)], band=DEMO_FIT_BAND_HZ)
    if stab is not None:
        plot_stabilization(stab, frf, ctx.out_dir / "stabilization.png", selected=result.poles)
    ctx.say(f"fit: {ctx.out_dir / 'fit.json'}, plots: fit.png, stabilization.png")


def report_step(ctx: DemoContext) -> None:
    """The HTML test report of the demo, with the fit above and the frame's wireframe."""
    from analysis.report_html import make_report
    from simulator.geometry import frame_geometry

    assert ctx.recording is not None, "the capture step comes first"
    index = make_report(ctx.recording, ctx.out_dir / "report", fit_json=ctx.out_dir / "fit.json", geometry=frame_geometry(),
                        overwrite=True)  # the demo's own report folder
    ctx.say(f"report: {index} (open {index.resolve().as_uri()} in a browser)")


STEPS: list[Callable[[DemoContext], None]] = [capture_step, summary_step, export_step, fit_step, report_step]


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m acquisition demo", description=__doc__.split("\n\n")[0])
    with_examples(p)
    p.add_argument("--out", default="demo-output", help="output folder (created)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--hits", type=int, default=5, help="accepted hits per point")
    args = p.parse_args(argv)
    if args.hits < 1:
        print("demo: --hits must be >= 1", file=sys.stderr)
        return 2
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f"demo: cannot create {out}: {exc.strerror}", file=sys.stderr)
        return 2
    ctx = DemoContext(out, seed=args.seed, hits=args.hits)
    t0 = time.perf_counter()
    for step in STEPS:
        step(ctx)
    ctx.say(f"demo done in {time.perf_counter() - t0:.1f} s")
    return 0
