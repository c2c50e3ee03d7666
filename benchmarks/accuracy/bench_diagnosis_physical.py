"""Physical diagnosis on data it was not made from: changed frames captured through the analyser.

Every case writes a frame configuration that differs from ``simulator/frame.toml`` in ONE physical way,
built the way a user would build it (a steel block as an extra member on joint springs, explicit
sections, changed springs), captures the default test plan through ``sim://?config=...`` (hammer,
sensors, anti-alias filter, ADC, H1 averaging: the time-domain chain), and diagnoses the recording
against the unchanged ``frame.toml`` (:func:`analysis.diagnosis.diagnose` with
:class:`simulator.physical.FrameVariants`). The diagnosis fits lumped masses and scaled matrices, so
the data come from a different model than the one it fits.

Families (``--per-family`` cases each, parameters drawn from a seeded generator):

* ``added_mass``: a steel block (1-5 kg, a cube of two beam elements with consistent mass, its middle
  on joint springs) on a random node of the beam or a column; right if the node is within one element and the mass within 25 %;
* ``support_stiffness``: rotational springs x 0.2-0.6; ``joint_stiffness``: x 0.02-0.1 (the joints are
  stiff: at x 0.16 no mode moves by more than 0.1 %, below the 0.2 % model-form floor, and such a
  change is rightly ``none``); right within 10 %;
* ``member_mass``: one member's area x 1.15-1.4 (explicit section: its axial stiffness changes too);
  right member, factor within 10 %;
* ``member_stiffness``: one member's second moments x 0.65-0.9; right member, factor within 10 %;
* ``mass_loading``: accelerometers of 50-300 g; within 25 %;
* ``stiffness_shift``: Young's modulus x 0.88-0.95 or 1.05-1.12; within 10 %.

Nulls (no change to find): other seeds, a finer mesh (every member's elements doubled, point labels
mapped to the same places), captures with an exponential window (5 % at the block end). Out of the
catalogue: the span 6 % longer, the right column's roll 20 -> 40 deg: ``unexplained`` is right.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/accuracy/bench_diagnosis_physical.py [--per-family 15] \
        [--nulls 10] [--workers 2] [--json out.json]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import sys  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository, for benchmarks.results
from benchmarks.results import add_write_option, recorded  # noqa: E402

#: this benchmark's results file (``--write`` replaces it with the run's figures)
RESULTS = Path(__file__).with_name("bench_diagnosis_physical.md")

POINTS = ("right:6:-X", "right:4:-X", "left:6:X", "top:4:Z", "top:2:Z", "left:9:Y")
FAMILIES = ("added_mass", "support_stiffness", "joint_stiffness", "member_mass", "member_stiffness",
            "mass_loading", "stiffness_shift")


def _explicit(sec, area=1.0, inertia=1.0) -> dict:
    from simulator.fem import section_properties

    sp = section_properties(sec)
    return {"shape": "explicit", "area_m2": sp.A * area, "iy_m4": sp.Iy * inertia, "iz_m4": sp.Iz * inertia, "j_m4": sp.J}


def steel_block(cfg, node: str, mass_kg: float) -> dict:
    """Config overrides that fix a steel cube of ``mass_kg`` on the frame at ``node`` (``component:node``):
    two beam elements across the member (along Y) with their consistent mass and rotary inertia, the
    cube's middle node joined to ``node`` by the frame's joint springs (not a lumped mass)."""
    from simulator.fem import member_nodes_xyz

    comp, i = node.split(":")
    xyz = member_nodes_xyz(cfg.components[comp])[int(i)]
    a = (mass_kg / 7850.0) ** (1 / 3)                       # the cube's side (m)
    half = np.array([0.0, a / 2, 0.0])
    return {"sections": {"block": {"shape": "explicit", "area_m2": a * a, "iy_m4": a ** 4 / 12, "iz_m4": a ** 4 / 12,
                                   "j_m4": 0.141 * a ** 4}},
            "components": {"block": {"section": "block", "start_m": list(map(float, xyz - half)),
                                     "end_m": list(map(float, xyz + half)), "n_elements": 2, "roll_deg": 0.0}},
            "joints": {"pairs": [list(p) for p in cfg.joints.pairs] + [[node, "block:1"]]}}


def make_case(family: str, rng: np.random.Generator) -> tuple[dict, dict]:
    """(config overrides, truth) of one case of ``family``."""
    from simulator.config import FrameConfig

    cfg = FrameConfig.load()
    if family == "added_mass":
        comp = str(rng.choice(["top", "top", "left", "right"]))
        n = cfg.components[comp].n_elements
        node = int(rng.integers(1, n))
        mass = float(rng.uniform(1.0, 5.0))
        return steel_block(cfg, f"{comp}:{node}", mass), {"cause": family, "point": f"{comp}:{node}", "mass_kg": mass}
    if family in ("support_stiffness", "joint_stiffness"):
        f = float(np.exp(rng.uniform(np.log(0.2), np.log(0.6)))) if family == "support_stiffness" else \
            float(np.exp(rng.uniform(np.log(0.02), np.log(0.1))))
        key = "supports" if family == "support_stiffness" else "joints"
        k = list(getattr(cfg, key).stiffness)
        return {key: {"stiffness": k[:3] + [x * f for x in k[3:]]}}, {"cause": family, "factor_rotational": f}
    if family in ("member_mass", "member_stiffness"):
        comp = str(rng.choice(list(cfg.components)))
        f = float(rng.uniform(1.15, 1.4)) if family == "member_mass" else float(rng.uniform(0.65, 0.9))
        sec = cfg.sections[cfg.components[comp].section]
        new = _explicit(sec, area=f) if family == "member_mass" else _explicit(sec, inertia=f)
        return ({"sections": {"changed": new}, "components": {comp: {"section": "changed"}}},
                {"cause": family, "component": comp, "factor": f})
    if family == "mass_loading":
        m = float(rng.uniform(0.05, 0.3))
        return {"sensors": {"accelerometer": {"mass_kg": m}}}, {"cause": family, "mass_kg": m}
    if family == "stiffness_shift":
        f = float(rng.choice([-1, 1]) * rng.uniform(0.05, 0.12) + 1.0)
        return ({"material": {"youngs_modulus_pa": cfg.material.youngs_modulus_pa * f}},
                {"cause": family, "stiffness_factor": f})
    raise ValueError(family)


def null_case(kind: str, rng: np.random.Generator) -> tuple[dict, dict, list]:
    """(overrides, truth, extra capture args) of a null or out-of-catalogue case."""
    from simulator.config import FrameConfig

    cfg = FrameConfig.load()
    if kind == "seed":
        return {}, {"cause": "none"}, []
    if kind == "mesh":
        def fine(p: str) -> str:
            c, n, d = p.split(":")
            return f"{c}:{2 * int(n)}:{d}"

        plan = cfg.test_plan
        return ({"components": {c: {"n_elements": 2 * comp.n_elements} for c, comp in cfg.components.items()},
                 "supports": {"nodes": ["left:0", "right:0"]},
                 "joints": {"pairs": [["left:20", "top:0"], ["right:20", "top:16"]]},
                 "test_plan": {"sensors": [fine(p) for p in plan.sensors], "reference": fine(plan.reference),
                               "points": [fine(p) for p in plan.points]}},
                {"cause": "none", "relabel": 2}, [])
    if kind == "window":
        return {}, {"cause": "none"}, ["--exp-window", "5%"]
    if kind == "span":
        s = 1.06
        return ({"components": {"right": {"start_m": [1.7 * s, 0.0, 0.0], "end_m": [1.7 * s, 0.0, 0.668]},
                                "top": {"end_m": [1.7 * s, 0.0, 0.668]}}}, {"cause": "unexplained"}, [])
    if kind == "roll":
        return {"components": {"right": {"roll_deg": 40.0}}}, {"cause": "unexplained"}, []
    raise ValueError(kind)


def _relabel(frf, factor: int):
    from analysis.points import parse_point

    def lab(p: str) -> str:
        q = parse_point(p)
        return str(p).replace(f"{q.component}:{q.node}:", f"{q.component}:{q.node // factor}:", 1)

    return replace(frf, outputs=tuple(map(lab, frf.outputs)), references=tuple(map(lab, frf.references)))


def capture_case(tmp: Path, seed: int, overrides: dict, finer_mesh: bool, extra: list,
                 points: tuple[str, ...] = POINTS) -> tuple[int, Path]:
    """Capture one case through ``sim://?seed=...`` (the frame changed by ``overrides``) with the default
    plan (or ``points``), 3 hits per point, into ``tmp/rec.h5``; ``finer_mesh``: the points and sensors renumbered for
    a mesh twice as fine (the same places). Returns the capture's exit code and the recording."""
    from acquisition.cli_capture import main as capture
    from simulator.config import overrides_to_toml

    device = f"sim://?seed={seed}"
    if overrides:
        cfg = tmp / "frame.toml"
        cfg.write_text(overrides_to_toml(overrides))
        device += f"&config={cfg}"
    pts = tuple(points)
    if finer_mesh:
        from acquisition.setup import default_setup
        from analysis.points import parse_point

        def fine(p: str) -> str:
            q = parse_point(p)
            return str(p).replace(f"{q.component}:{q.node}:", f"{q.component}:{2 * q.node}:", 1)

        pts = tuple(map(fine, pts))
        setup = default_setup().to_dict()                 # the sensors at the same places on the finer mesh
        for ch in setup["channels"]:
            ch["point"] = fine(ch["point"])
        (tmp / "setup.json").write_text(json.dumps(setup))
        extra = [*extra, "--setup", str(tmp / "setup.json")]
    rec = tmp / "rec.h5"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        rc = capture(["--device", device, "--out", str(rec), "--points", ",".join(pts), "--hits", "3",
                      "--auto", "-q", *extra])
    return rc, rec


def run_case(spec: dict) -> dict:
    """Capture and diagnose one case; returns the truth, the verdict, the fitted parameters, the time."""
    from analysis.bands import default_band
    from analysis.diagnosis import diagnose
    from analysis.inputs import load_input
    from simulator.physical import FrameVariants

    over, truth, extra = spec["overrides"], spec["truth"], spec.get("extra", [])
    with tempfile.TemporaryDirectory() as tmp:
        rc, rec = capture_case(Path(tmp), spec["seed"], over, bool(truth.get("relabel")), extra)
        if rc != 0:
            return {**spec, "verdict": f"capture failed ({rc})", "right": False}
        m = load_input(rec)
        if truth.get("relabel"):
            m = _relabel(m, truth["relabel"])
        t0, c0 = time.perf_counter(), time.process_time()
        lo, hi = default_band(m)
        fv = FrameVariants(None, m.outputs, m.references)
        m = m.band(lo, min(hi, fv.converged_below_hz()))
        from analysis.diagnosis.compare import line_weights
        from analysis.diagnosis.hit_noise import hit_scatter_noise_db

        hits_db = hit_scatter_noise_db(rec, m, line_weights(m)) if not truth.get("relabel") else None
        d = diagnose(m, fv.model(None, {}), physical=fv, extra_noise_db={"hits": hits_db})
        dt, cpu = time.perf_counter() - t0, time.process_time() - c0
    params = next((c["parameters"] for c in d.causes if c["effect"] == d.verdict), {})
    phys = [{k: c[k] for k in ("effect", "parameters", "gain_db", "significant", "adequate")}
            for c in (d.causes if d.causes and d.causes[0].get("kind") == "physical" else d.physical.get("causes", []))]
    out = {"family": spec["family"], "seed": spec["seed"], "truth": truth, "verdict": d.verdict,
           "parameters": params, "time_s": dt, "cpu_s": cpu, "reason": d.reason,
           "physical": {k: v for k, v in d.physical.items() if k != "causes"}, "physical_causes": phys}
    out.update(score(truth, d.verdict, params))
    return out


def _node_xyz(label: str) -> np.ndarray:
    from simulator.physical import FrameVariants

    fv = _node_xyz.__dict__.setdefault("fv", FrameVariants(None, ["top:4:Z"], ["top:4:Z"]))
    c, n = label.split(":")[:2]
    return fv.frame.node_coords[fv.frame.node_index[(c, int(n))]]


def score(truth: dict, verdict: str, p: dict) -> dict:
    """right (cause named), and the parameter checks of the module docstring."""
    cause = truth["cause"]
    if verdict != cause:
        return {"right": False, "params_ok": False}
    ok = True
    if cause == "added_mass":
        from simulator.config import FrameConfig

        cfg = FrameConfig.load()
        comp = truth["point"].split(":")[0]
        c = cfg.components[comp]
        elem = float(np.linalg.norm(np.subtract(c.end_m, c.start_m))) / c.n_elements
        dist = float(np.linalg.norm(_node_xyz(p["point"]) - _node_xyz(truth["point"])))
        ok = dist <= 1.01 * elem and abs(p["mass_kg"] / truth["mass_kg"] - 1) <= 0.25
    elif cause in ("support_stiffness", "joint_stiffness"):
        # every support (joint) was changed: the place named must be all of them
        place = p.get("support" if cause == "support_stiffness" else "joint", "all")
        ok = place == "all" and abs(p["factor_rotational"] / truth["factor_rotational"] - 1) <= 0.10
    elif cause in ("member_mass", "member_stiffness"):
        ok = p["component"] == truth["component"] and abs(p["factor"] / truth["factor"] - 1) <= 0.10
    elif cause == "mass_loading":
        ok = abs(p["mass_kg"] / truth["mass_kg"] - 1) <= 0.25
    elif cause == "stiffness_shift":
        ok = abs(p["stiffness_factor"] / truth["stiffness_factor"] - 1) <= 0.10
    return {"right": True, "params_ok": bool(ok)}


def cases(per_family: int, nulls: int, seed: int = 2026, families=FAMILIES) -> list[dict]:
    rng = np.random.default_rng(seed)
    out = []
    for fam in families:
        for _ in range(per_family):
            over, truth = make_case(fam, rng)
            out.append({"family": fam, "overrides": over, "truth": truth, "seed": int(rng.integers(1, 10**6))})
    for kind in ("seed", "mesh", "window") if nulls else ():
        for _ in range(nulls):
            over, truth, extra = null_case(kind, rng)
            out.append({"family": f"null:{kind}", "overrides": over, "truth": truth, "extra": extra,
                        "seed": int(rng.integers(1, 10**6))})
    for kind in ("span", "roll") if nulls else ():
        over, truth, extra = null_case(kind, rng)
        out.append({"family": f"out-of-catalogue:{kind}", "overrides": over, "truth": truth, "extra": extra,
                    "seed": int(rng.integers(1, 10**6))})
    return out


def table(results: list[dict]) -> str:
    rows = ["| family | cases | named right | parameters right | median s | max s |", "|---|---|---|---|---|---|"]
    fams = list(dict.fromkeys(r["family"] for r in results))
    for fam in fams:
        rs = [r for r in results if r["family"] == fam]
        t = [r.get("time_s", np.nan) for r in rs]
        rows.append(f"| {fam} | {len(rs)} | {sum(r['right'] for r in rs)} | {sum(r.get('params_ok', False) for r in rs)} | "
                    f"{np.nanmedian(t):.1f} | {np.nanmax(t):.1f} |")
    phys = [r for r in results if r["family"] in FAMILIES]
    nul = [r for r in results if r["family"].startswith("null")]
    if phys:
        rows.append(f"\nphysical: {sum(r['right'] for r in phys)}/{len(phys)} named right "
                    f"({100 * np.mean([r['right'] for r in phys]):.0f} %), parameters right "
                    f"{sum(r.get('params_ok', False) for r in phys)}/{len(phys)}")
    if nul:
        rows.append(f"nulls: {sum(not r['right'] for r in nul)} false alarms in {len(nul)}")
    return "\n".join(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=15)
    ap.add_argument("--nulls", type=int, default=10, help="cases of each null kind")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", help="write every case's result")
    ap.add_argument("--families", default=",".join(FAMILIES), help="comma-separated families to run")
    add_write_option(ap, RESULTS)
    args = ap.parse_args()
    with recorded(RESULTS, args.write):
        _run(args)


def _run(args: argparse.Namespace) -> None:
    """The run itself (what :func:`main` records with ``--write``)."""
    todo = cases(args.per_family, args.nulls, families=[f for f in args.families.split(",") if f])
    run_all(run_case, todo, args.workers, _case_line, args.json)


def _case_line(r: dict) -> str:
    mark = "ok " if r["right"] and r.get("params_ok", True) else ("~  " if r["right"] else "BAD")
    shown = {k: v for k, v in (r.get("parameters") or {}).items() if not isinstance(v, (list, dict))}
    return (f"{mark} {r['family']:28s} truth {r['truth']} -> {r['verdict']} {shown} "
            f"({r.get('time_s', 0):.1f} s, CPU {r.get('cpu_s', 0):.1f} s)")


def run_all(run: Callable[[dict], dict], todo: list, workers: int, line: Callable[[dict], str],
            json_path: str | None) -> list[dict]:
    """Run the cases on ``workers`` processes, print one ``line(result)`` per case as it ends, then the
    table and the wall time; write every result to ``json_path`` when given."""
    t0 = time.perf_counter()
    results = []
    with ProcessPoolExecutor(workers) as pool:
        for r in pool.map(run, todo):
            results.append(r)
            print(line(r), flush=True)
    print(table(results))
    print(f"wall time {time.perf_counter() - t0:.0f} s for {len(results)} cases, {workers} workers")
    if json_path:
        Path(json_path).write_text(json.dumps(results, indent=1, default=str))
    return results


if __name__ == "__main__":
    main()
