"""Linearity, reciprocity and the joint_nonlinearity cause on simulated tests made by the time-domain
frame (not by the models the checks fit).

Rows of the table:

* ``linear frame``: the default frame struck at 20 and 400 N (8 hits at right:6:-X, sensor noise),
  ``analysis.linearity.compare_levels``; a "nonlinear" verdict is a false alarm.
* ``friction joint``: the right column-beam joint as an Iwan micro-slip spring (2e4 N m/rad, slip
  moment 1.5 N m); verdict, and whether the mode that softens most is one whose shape loads the joint
  (its strain-energy share at least half the largest of the judged modes).
* ``diagnosis``: frames with semi-rigid corners and base rotations; one of the four rotational springs
  (left/right joint, left/right support, about Y) is an Iwan joint with a random slip moment
  (1-3 N m); three points struck at 20 and 400 N; :func:`analysis.diagnosis.joint_nonlinearity.joint_nonlinearity`
  with :class:`simulator.nonlinear_simulation.JointHitSimulation` on the nominal (linear) frame. Right
  when the named spring is the one simulated.
* ``linear changes``: the same frames with a steel block (2 kg), a loose support (x 0.4) or a soft
  joint (x 0.3) and no nonlinear spring: the linearity verdict must stay "linear" and the cause absent.
* ``reciprocity``: three struck sensor points (4 hits each): within the noise; the same with one
  sensor's data 10 % high: flagged at that sensor.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/accuracy/bench_linearity.py [--seeds 20] [--cases 20] \
        [--only linear,friction,diagnosis,changes,reciprocity]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks" / "accuracy"))

from quality_support import FRICTION_JOINT, level_hits, roving_test  # noqa: E402

from analysis.diagnosis.joint_nonlinearity import joint_nonlinearity  # noqa: E402
from analysis.linearity import compare_levels, level_frfsets  # noqa: E402
from analysis.reciprocity import reciprocity  # noqa: E402
from simulator.config import FrameConfig  # noqa: E402
from simulator.fem import FrameModel  # noqa: E402
from simulator.nonlinear_joint import joint_dof_vector, joint_law  # noqa: E402
from simulator.nonlinear_simulation import JointHitSimulation  # noqa: E402
from simulator.stand import TestStand  # noqa: E402

SEMI_RIGID = {"joints": {"stiffness": [1e9, 1e9, 1e9, 1e8, 2e4, 1e8]},
              "supports": {"stiffness": [1e9, 1e9, 1e9, 1.6e7, 5e4, 1.6e7]}}
PLACES = ("right:10", "left:10", "left:0", "right:0")
POINTS = ("right:6:-X", "left:6:X", "top:4:Z")
BAND = (5.0, 400.0)


def linear_frame(seeds: int) -> dict:
    alarms, worst = 0, 0.0
    for seed in range(seeds):
        lv, sets = level_frfsets(level_hits(None, 100 + seed))
        res = compare_levels(sets, lv, band=(5.0, 220.0))
        alarms += res.verdict != "linear"
        worst = max([worst] + [abs(m.df_percent) for m in res.modes if m.determined])
    return {"cases": seeds, "right": seeds - alarms, "note": f"{alarms} false alarm(s); largest |df| {worst:.3f} %"}


def friction_joint(seeds: int) -> dict:
    cfg = FrameConfig.from_dict({"nonlinear": FRICTION_JOINT})
    model = FrameModel.from_config(cfg)
    ms = model.modes()
    share = joint_law(cfg).k0 * (joint_dof_vector(model, cfg) @ ms.shapes) ** 2 / ms.omega ** 2
    right, shifts = 0, []
    for seed in range(seeds):
        lv, sets = level_frfsets(level_hits(cfg, 200 + seed))
        res = compare_levels(sets, lv, band=(5.0, 220.0))
        judged = [m for m in res.modes if m.determined]
        at = np.array([share[int(np.argmin(np.abs(ms.freq_hz - m.freq_hz)))] for m in judged])
        most = int(np.argmin([m.df_percent for m in judged]))
        ok = res.verdict == "nonlinear" and at[most] >= 0.5 * at.max()
        right += ok
        shifts.append(judged[most].df_percent)
    return {"cases": seeds, "right": right,
            "note": f"nonlinear and the most softened mode loads the joint; its df {np.mean(shifts):+.2f} % "
                    f"(mean), per decade {np.mean(shifts) / np.log10(20):+.2f} %"}


def _diagnose(cfg_over: dict, seed: int) -> tuple[dict, dict, float]:
    cfg = FrameConfig.from_dict(cfg_over)
    hits = level_hits(cfg, seed, n_hits=6, points=POINTS)
    lv, sets = level_frfsets(hits)
    res = compare_levels(sets, lv, band=BAND)
    t = time.perf_counter()
    nominal = {k: v for k, v in cfg_over.items() if k != "nonlinear"}
    sim = JointHitSimulation(FrameConfig.from_dict(nominal), POINTS, hits[0].outputs, lv, hits[0].fs_hz,
                             hits[0].force.size, hits[0].trigger_index)
    return res.to_dict(), joint_nonlinearity(res, sim), time.perf_counter() - t


def diagnosis(cases: int) -> tuple[dict, list]:
    rng = np.random.default_rng(25)
    right, times, slips, rows = 0, [], [], []
    for i in range(cases):
        place = PLACES[i % len(PLACES)]
        slip = float(rng.uniform(1.0, 3.0))
        _, cause, dt = _diagnose({**SEMI_RIGID, "nonlinear": {"law": "iwan", "joint": place, "axis": "ry",
                                                             "slip_moment_nm": slip}}, 300 + i)
        named = cause.get("joint", {}) if cause["present"] else {}
        ok = place in named.get("nodes", []) and named.get("axis") == "ry"
        right += ok
        times.append(dt)
        if ok and cause["law"].get("slip_moment_nm"):
            slips.append(cause["law"]["slip_moment_nm"] / slip - 1.0)
        rows.append(f"  {place:9s} slip {slip:4.2f} N m -> {named.get('name', 'none'):26s} "
                    f"slip {cause.get('law', {}).get('slip_moment_nm') or float('nan'):5.2f} N m  {dt:5.1f} s")
    note = (f"slip moment within {100 * np.median(np.abs(slips)):.0f} % (median) of the truth; "
            f"{np.median(times):.1f} s per case (median)")
    return {"cases": cases, "right": right, "note": note}, rows


def linear_changes() -> dict:
    from bench_diagnosis_physical import steel_block

    base = FrameConfig.from_dict(SEMI_RIGID)
    changes = [steel_block(base, "top:4", 2.0), steel_block(base, "left:6", 2.0),
               {"damage": {"loose_supports": ["left:0"], "loose_support_factor": [0.4]}},
               {"damage": {"loose_supports": ["right:0"], "loose_support_factor": [0.4]}},
               {"damage": {"soft_joints": ["right:10"], "soft_joint_factor": [0.3]}},
               {"damage": {"soft_joints": ["left:10"], "soft_joint_factor": [0.3]}}]
    right = 0
    for i, ch in enumerate(changes):
        over = {**SEMI_RIGID, **{k: v for k, v in ch.items() if k != "joints"}}
        if "joints" in ch:
            over["joints"] = {**SEMI_RIGID["joints"], **ch["joints"]}
        lin, cause, _ = _diagnose(over, 400 + i)
        right += lin["verdict"] == "linear" and not cause["present"]
    return {"cases": len(changes), "right": right, "note": "block 2 kg (beam, column), loose support x0.4, "
                                                          "soft joint x0.3: linear, no joint named"}


def reciprocity_rows(seeds: int) -> list[dict]:
    ok_clean, ok_off = 0, 0
    for seed in range(seeds):
        r = reciprocity(roving_test(TestStand(seed=500 + seed), seed=seed))
        ok_clean += r.verdict == "reciprocal"
        off = reciprocity(roving_test(TestStand(seed=600 + seed), gain={"top:2:Z": 1.1}, seed=seed))
        ok_off += off.suspects == ("top:2:Z",)
    return [{"name": "reciprocity, struck sensor points", "cases": seeds, "right": ok_clean,
             "note": "within the noise"},
            {"name": "reciprocity, one sensor 10 % off", "cases": seeds, "right": ok_off,
             "note": "flagged at that sensor (and only there)"}]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=20, help="seeds of the linear-frame and reciprocity rows")
    ap.add_argument("--cases", type=int, default=20, help="diagnosis cases")
    ap.add_argument("--friction-seeds", type=int, default=5)
    ap.add_argument("--only", default="linear,friction,diagnosis,changes,reciprocity",
                    help="rows to run, comma separated (default: all)")
    args = ap.parse_args()
    only = set(args.only.split(","))
    t0 = time.perf_counter()
    rows, detail = [], []
    if "linear" in only:
        rows.append({"name": "linear frame, 20 and 400 N", **linear_frame(args.seeds)})
    if "friction" in only:
        rows.append({"name": "friction joint (right corner)", **friction_joint(args.friction_seeds)})
    if "diagnosis" in only:
        diag, detail = diagnosis(args.cases)
        rows.append({"name": "diagnosis: joint_nonlinearity at the right spring", **diag})
    if "changes" in only:
        rows.append({"name": "linear changes not called nonlinear", **linear_changes()})
    if "reciprocity" in only:
        rows += reciprocity_rows(args.seeds)
    print(f"{'check':52s} {'right':>9s}  note")
    for r in rows:
        print(f"{r['name']:52s} {r['right']:3d} / {r['cases']:3d}  {r['note']}")
    if detail:
        print("\ndiagnosis cases:")
        print("\n".join(detail))
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
