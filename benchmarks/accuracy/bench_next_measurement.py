"""The next measurement at work: a test plan that cannot separate two candidates, the proposed point
added to the plan and captured, and the diagnosis again.

Each case fixes a steel block (1.5-4 kg, a cube of two beam elements on joint springs) at a random inner
node of the beam other than its middle, and captures through ``sim://?config=...`` with the beam
hammered at its middle only (``top:4:Z``) and the default three sensors: a plan under which a mass and
its mirror image about the middle give nearly the same measured modes. The recording is diagnosed
against the unchanged frame (the whole catalogue). When the diagnosis proposes a next measurement, the
proposed point is added to the hammer points, the frame is captured again (same seed) and diagnosed
again. Reported per case: the verdict and mass node before, the proposal and its two candidates, and
after: named right (node within one element, mass within 25 %) and whether a proposal remains.
``--plan default2`` draws two hammer points of the default plan instead (the plan is not chosen to be
ambiguous: proposals are rarer there).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/accuracy/bench_next_measurement.py [--cases 4] \
        [--plan middle|default2] [--json out.json]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_diagnosis_large import _block, _param_ok  # noqa: E402
from bench_diagnosis_physical import POINTS, steel_block  # noqa: E402


def _diagnose(tmp: Path, device: str, points: list[str], tag: str):
    from acquisition.cli_capture import main as capture
    from analysis.diagnosis import diagnose
    from analysis.inputs import load_input
    from simulator.physical import FrameVariants

    rec = tmp / f"{tag}.h5"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        rc = capture(["--device", device, "--out", str(rec), "--points", ",".join(points), "--hits", "3", "--auto", "-q"])
    if rc != 0:
        raise RuntimeError(f"capture failed ({rc}) at {points}")
    m = load_input(rec)
    return diagnose(m, FrameVariants(None, m.outputs, m.references), band="data", recording=rec)


def _named(d) -> dict:
    return next((c["parameters"] for c in d.named if c["effect"] == "added_mass"), {})


def run_case(spec: dict) -> dict:
    from simulator.config import overrides_to_toml

    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        cfg = tmp / "frame.toml"
        cfg.write_text(overrides_to_toml(spec["overrides"]))
        device = f"sim://?seed={spec['seed']}&config={cfg}"
        t0 = time.perf_counter()
        first = _diagnose(tmp, device, spec["points"], "first")
        out = {"truth": spec["truth"], "points": spec["points"], "verdict_before": first.verdict,
               "named_before": _named(first), "next": first.next_measurement,
               "right_before": bool(_named(first)) and _param_ok(spec["truth"], _named(first))}
        if first.next_measurement:
            second = _diagnose(tmp, device, [*spec["points"], first.next_measurement["point"]], "second")
            out.update({"verdict_after": second.verdict, "named_after": _named(second), "next_after": second.next_measurement,
                        "right_after": bool(_named(second)) and _param_ok(spec["truth"], _named(second))})
        out["time_s"] = time.perf_counter() - t0
    return out


def main() -> None:
    from simulator.config import FrameConfig

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=4)
    ap.add_argument("--plan", choices=("middle", "default2"), default="middle")
    ap.add_argument("--seed", type=int, default=2028)
    ap.add_argument("--json")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    cfg = FrameConfig.load()
    rows = []
    for _ in range(args.cases):
        if args.plan == "middle":
            node = f"top:{int(rng.choice([1, 2, 3, 5, 6, 7]))}"
            mass = float(rng.uniform(1.5, 4.0))
            over, truth = steel_block(cfg, node, mass), {"cause": "added_mass", "point": node, "mass_kg": mass}
            points = ["top:4:Z"]
        else:
            over, truth = _block(cfg, rng, 1.0, 4.0)
            points = [str(p) for p in rng.choice(POINTS, size=2, replace=False)]
        r = run_case({"overrides": over, "truth": truth, "points": points, "seed": int(rng.integers(1, 10**6))})
        rows.append(r)
        nxt = r["next"]
        pair = nxt and [c["parameters"].get("point", c["effect"]) for c in nxt["candidates"]]
        print(f"truth {truth['point']} {truth['mass_kg']:.2f} kg, hammer {points}: {r['verdict_before']} "
              f"{r['named_before']} right={r['right_before']}; next {nxt and (nxt['point'], round(nxt['separation_db'], 1))}"
              f" between {pair}"
              + (f" -> {r['verdict_after']} {r['named_after']} right={r['right_after']}, next after "
                 f"{r['next_after'] and r['next_after']['point']}" if nxt else "") + f" ({r['time_s']:.0f} s)", flush=True)
    asked = [r for r in rows if r["next"]]
    print(f"\n{len(asked)} of {len(rows)} cases asked for a next measurement; right before {sum(r['right_before'] for r in asked)}"
          f", after {sum(r.get('right_after', False) for r in asked)}; still asking after: "
          f"{sum(bool(r.get('next_after')) for r in asked)}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=str))


if __name__ == "__main__":
    main()
