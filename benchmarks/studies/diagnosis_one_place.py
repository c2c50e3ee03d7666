"""Damage at one place, in the simulator's own words: an independent hold-out of the physical diagnosis.

The cases are written from the frame configuration's vocabulary only (the ``[damage]`` table of
``simulator/frame.toml``; the places read from that file's ``[supports]``, ``[joints]`` and
``[components]``), not from the diagnosis' catalogue: this script imports neither
``analysis.diagnosis`` nor ``simulator.physical``. Each case is captured through the simulated analyser
(``sim://?seed=S&config=frame.toml``, the time-domain chain: hammer, sensors, anti-alias filter, ADC, H1)
and diagnosed with the command line against the unchanged ``simulator/frame.toml``::

    python -m analysis diagnose --measured rec.h5 --simulated simulator/frame.toml --json out.json

Families and ranges (fixed before any run; factors log-uniform):

* ``loose_support``: one support node (``[supports] nodes``), ``loose_support_factor`` in 0.05..0.3;
* ``soft_joint``: one node of a joint pair (``[joints] pairs``: either node names the pair),
  ``soft_joint_factor`` in 0.02..0.2;
* ``cracked_element``: one element away from its member's ends (1..n-2), ``crack_bending_factor`` in 0.3..0.6;
* ``attached_block``: a steel block of its own size (1-5 kg; a plate, a bar or a cube: two sides drawn
  from 2..20 cm and the third from the mass) fixed across a member at an inner node: in the
  configuration an extra component of two elements with the block's own section, its middle node
  joined to the frame's node by the joint springs (``[joints] pairs`` extended). Right: ``added_mass``
  at that node or a neighbour on the same member, mass within 25 %;
* ``section_change``: one member (``[components]``) made of another stock bar: its own section of the frame's
  shape (``[sections]`` ``rect``, ``width_m`` and ``depth_m``), each side scaled by a factor drawn log-uniformly
  in 0.8..1.25, at least one side by 5 % or more (another bar, not a tolerance); mass and both bending
  stiffnesses change together, by different factors. Right: every named cause is a member's cause
  (``member_stiffness`` or ``member_mass``) of that member, at least one named;
* ``null``: the unchanged frame at another capture seed, with the default test plan's points or with six
  hammer points drawn from the frame's nodes (any of X, Y, Z across the member).

Right: the verdict is the damage's cause with its place (a support's node; the joint pair that holds the
damaged node; the element) - ``named`` with kind and place. A null is right when the verdict is ``none``.

    # draw a hold-out list (commit it before running it)
    python benchmarks/studies/diagnosis_one_place.py draw --seed 33 --damage 20 --nulls 10 --out CASES.json
    # with section changes (drawn from their own seed, seed + 2)
    python benchmarks/studies/diagnosis_one_place.py draw --seed 70 --damage 15 --nulls 0 --sections 5 --out CASES.json
    # run it (one case after the other; the diagnosis forks its own processes); --write: the results go to
    # CASES.results.json beside the list (replaced after every case, atomically)
    OPENBLAS_NUM_THREADS=1 nice -n 10 python benchmarks/studies/diagnosis_one_place.py run CASES.json --write

The hold-out lists kept beside this script (:data:`CASE_LISTS`) each have their results beside them.
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import resource
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from analysis.atomic import write_text_atomic  # noqa: E402
from benchmarks.results import results_of_cases  # noqa: E402
from benchmarks.studies.study_args import add_draw, add_run, study_commands  # noqa: E402

FRAME = ROOT / "simulator" / "frame.toml"
#: the hold-out case lists drawn by this script and kept beside it (their results: results_of_cases)
CASE_LISTS = "diagnosis_one_place_holdout_seed*.json diagnosis_attached_block_holdout_seed*.json diagnosis_nulls_holdout_seed*.json"
#: The points of the damage cases' captures (the physical benchmark's six hammer points).
POINTS = ("right:6:-X", "right:4:-X", "left:6:X", "top:4:Z", "top:2:Z", "left:9:Y")
RANGES = {"loose_support": (0.05, 0.3), "soft_joint": (0.02, 0.2), "cracked_element": (0.3, 0.6)}
#: Attached blocks: mass (kg) and the two drawn sides (m); steel density of frame.toml's [material].
BLOCK_MASS_KG = (1.0, 5.0)
BLOCK_SIDE_M = (0.02, 0.20)
#: Section changes: each side of the member's section scaled by a factor in this range (log-uniform), at least
#: one side by SECTION_MIN_CHANGE or more (relative).
SECTION_SCALE = (0.8, 1.25)
SECTION_MIN_CHANGE = 0.05
#: The causes that name a member (a section change is right when every named cause is one of them at its member).
MEMBER_CAUSES = ("member_stiffness", "member_mass", "member_section")
#: The ``[damage]`` lists of each family: (places, factors).
DAMAGE_KEYS = {"loose_support": ("loose_supports", "loose_support_factor"),
               "soft_joint": ("soft_joints", "soft_joint_factor"),
               "cracked_element": ("cracked_elements", "crack_bending_factor")}
#: What the diagnosis must name for each family (the cause and the key of its place).
EXPECTED = {"loose_support": ("support_stiffness", "support"), "soft_joint": ("joint_stiffness", "joint"),
            "cracked_element": ("element_stiffness", "element")}


def frame() -> dict:
    """``simulator/frame.toml`` as read by any TOML reader (the configuration file, not the simulator's code)."""
    try:
        import tomllib as toml
    except ImportError:  # Python 3.10
        import tomli as toml  # type: ignore[no-redef]
    with open(FRAME, "rb") as fh:
        return toml.load(fh)


def places(family: str, cfg: dict) -> list[str]:
    if family == "loose_support":
        return [str(n) for n in cfg["supports"]["nodes"]]
    if family == "soft_joint":
        return [str(n) for pair in cfg["joints"]["pairs"] for n in pair]
    comps = cfg["components"]
    return [f"{c}:{e}" for c, comp in comps.items() for e in range(1, int(comp["n_elements"]) - 1)]


def hammer_points(cfg: dict, rng: np.random.Generator, n: int = 6) -> list[str]:
    """``n`` distinct hammer points on interior nodes, each in a direction across its member."""
    pool = []
    for c, comp in cfg["components"].items():
        axis = int(np.argmax(np.abs(np.subtract(comp["end_m"], comp["start_m"]))))
        dirs = [d for i, d in enumerate("XYZ") if i != axis]
        pool += [f"{c}:{k}:{d}" for k in range(1, int(comp["n_elements"])) for d in dirs]
    return [str(p) for p in rng.choice(pool, size=n, replace=False)]


def draw_blocks(seed: int, n: int) -> list[dict]:
    """``n`` attached blocks: an inner node, a mass, two sides, the direction the block spans (across its member)."""
    rng = np.random.default_rng(seed)
    cfg = frame()
    rho = float(cfg["material"]["density_kg_m3"])
    out = []
    for i in range(n):
        comp = str(rng.choice(sorted(cfg["components"])))
        c = cfg["components"][comp]
        node = f"{comp}:{int(rng.integers(1, int(c['n_elements'])))}"
        axis = int(np.argmax(np.abs(np.subtract(c["end_m"], c["start_m"]))))
        mass = float(rng.uniform(*BLOCK_MASS_KG))
        while True:         # two sides drawn, the third from the mass, all within the range
            b, h = np.exp(rng.uniform(np.log(BLOCK_SIDE_M[0]), np.log(BLOCK_SIDE_M[1]), 2))
            span = mass / (rho * b * h)
            if BLOCK_SIDE_M[0] <= span <= BLOCK_SIDE_M[1]:
                break
        along = int(rng.choice([a for a in range(3) if a != axis]))
        out.append({"name": f"attached_block-{i:02d}", "family": "attached_block", "place": node, "mass_kg": round(mass, 4),
                    "span_m": round(float(span), 4), "section_m": [round(float(b), 4), round(float(h), 4)],
                    "span_axis": "XYZ"[along], "seed": int(rng.integers(1, 10 ** 6)), "points": list(POINTS)})
    return out


def block_toml(case: dict, cfg: dict) -> str:
    """An attached block as the configuration states it: a component of two elements spanning the block across
    its member, centred on the node, with the block's own rectangular section; its middle node joined to the node
    by joint springs."""
    comp, i = case["place"].split(":")
    c = cfg["components"][comp]
    start, end = np.asarray(c["start_m"], float), np.asarray(c["end_m"], float)
    xyz = start + (end - start) * int(i) / int(c["n_elements"])
    half = np.zeros(3)
    half["XYZ".index(case["span_axis"])] = case["span_m"] / 2
    b, h = case["section_m"]
    a, t = max(b, h), min(b, h)
    j = a * t ** 3 * (1 / 3 - 0.21 * t / a * (1 - t ** 4 / (12 * a ** 4)))     # a rectangle's torsion constant
    pairs = [list(p) for p in cfg["joints"]["pairs"]] + [[case["place"], "block:1"]]
    return (f"[sections.block]\nshape = \"explicit\"\narea_m2 = {b * h!r}\niy_m4 = {b * h ** 3 / 12!r}\n"
            f"iz_m4 = {h * b ** 3 / 12!r}\nj_m4 = {j!r}\n\n[components.block]\nsection = \"block\"\n"
            f"start_m = {[float(x) for x in xyz - half]}\nend_m = {[float(x) for x in xyz + half]}\n"
            f"n_elements = 2\nroll_deg = 0.0\n\n[joints]\npairs = {json.dumps(pairs)}\n")


def draw_sections(seed: int, n: int) -> list[dict]:
    """``n`` section changes: a member, and the factors on its section's width and depth (``rect`` sections)."""
    rng = np.random.default_rng(seed)
    cfg = frame()
    out = []
    for i in range(n):
        comp = str(rng.choice(sorted(cfg["components"])))
        while True:
            fw, fd = np.exp(rng.uniform(np.log(SECTION_SCALE[0]), np.log(SECTION_SCALE[1]), 2))
            if max(abs(fw - 1.0), abs(fd - 1.0)) >= SECTION_MIN_CHANGE:
                break
        out.append({"name": f"section_change-{i:02d}", "family": "section_change", "place": comp,
                    "width_factor": round(float(fw), 4), "depth_factor": round(float(fd), 4),
                    "seed": int(rng.integers(1, 10 ** 6)), "points": list(POINTS)})
    return out


def section_toml(case: dict, cfg: dict) -> str:
    """A section change as the configuration states it: the member's own ``rect`` section, its width and depth
    those of the frame's section times the case's factors."""
    comp = case["place"]
    sec = cfg["sections"][cfg["components"][comp]["section"]]
    if sec["shape"] != "rect":
        raise ValueError(f"section change of {comp}: its section is {sec['shape']!r}, the study draws 'rect' only")
    w, d = float(sec["width_m"]) * case["width_factor"], float(sec["depth_m"]) * case["depth_factor"]
    return (f"[sections.changed]\nshape = \"rect\"\nwidth_m = {w!r}\ndepth_m = {d!r}\n\n"
            f"[components.{comp}]\nsection = \"changed\"\n")


def draw(seed: int, n_damage: int, n_nulls: int) -> list[dict]:
    """The case list: ``n_damage`` damage cases (families in turn), ``n_nulls`` nulls (half with drawn points)."""
    rng = np.random.default_rng(seed)
    cfg = frame()
    fams = list(RANGES)
    out = []
    for i in range(n_damage):
        fam = fams[i % len(fams)]
        lo, hi = RANGES[fam]
        where = str(rng.choice(places(fam, cfg)))
        factor = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
        out.append({"name": f"{fam}-{i:02d}", "family": fam, "place": where, "factor": round(factor, 4),
                    "seed": int(rng.integers(1, 10 ** 6)), "points": list(POINTS)})
    for i in range(n_nulls):
        pts = hammer_points(cfg, rng) if i % 2 else list(cfg["test_plan"]["points"])
        out.append({"name": f"null-{i:02d}", "family": "null", "seed": int(rng.integers(1, 10 ** 6)), "points": pts})
    return out


def frame_toml(case: dict) -> str:
    """The case's frame configuration (a user file merged over frame.toml): its ``[damage]`` table, or the
    attached block."""
    if case["family"] == "null":
        return "# the unchanged frame\n"
    if case["family"] == "attached_block":
        return block_toml(case, frame())
    if case["family"] == "section_change":
        return section_toml(case, frame())
    where, factors = DAMAGE_KEYS[case["family"]]
    return f'[damage]\n{where} = ["{case["place"]}"]\n{factors} = [{case["factor"]}]\n'


def same_place(case: dict, named: str, cfg: dict) -> bool:
    if case["family"] == "soft_joint":
        return any(case["place"] in pair and named in pair for pair in cfg["joints"]["pairs"])
    return named == case["place"]


def score(case: dict, doc: dict, cfg: dict) -> dict:
    verdict = doc["verdict"]
    named = doc.get("named") or []
    if case["family"] == "null":
        return {"right": verdict == "none", "named_among": verdict == "none"}
    if case["family"] == "attached_block":
        comp, i = case["place"].split(":")

        def near(p: dict) -> bool:
            c, k = str(p.get("point", "")).split(":")[:2] if ":" in str(p.get("point", "")) else ("", "-9")
            return c == comp and abs(int(k) - int(i)) <= 1 and abs(float(p["mass_kg"]) / case["mass_kg"] - 1) <= 0.25

        hits = [c for c in named if c["effect"] == "added_mass" and near(c["parameters"])]
        out = {"right": verdict == "added_mass" and bool(hits), "named_among": bool(hits)}
        mass = [c["parameters"]["mass_kg"] for c in named if c["effect"] == "added_mass"]
        if mass:
            out["factor_fitted"] = mass[0]
            out["factor_error"] = abs(float(mass[0]) / case["mass_kg"] - 1.0)
        return out
    if case["family"] == "section_change":
        ours = [c["effect"] in MEMBER_CAUSES and c["parameters"].get("component") == case["place"] for c in named]
        out = {"right": bool(ours) and all(ours), "named_among": any(ours)}
        sides = [c["parameters"] for c, o in zip(named, ours) if o and c["effect"] == "member_section"]
        if sides:       # the bar's width and depth as fitted: the larger of their relative errors
            out["factor_fitted"] = [sides[0]["width_factor"], sides[0]["depth_factor"]]
            out["factor_error"] = max(abs(float(sides[0][f"{k}_factor"]) / case[f"{k}_factor"] - 1.0)
                                      for k in ("width", "depth"))
        return out
    cause, key = EXPECTED[case["family"]]
    hits = [c for c in named if c["effect"] == cause and same_place(case, str(c["parameters"].get(key)), cfg)]
    out = {"right": verdict == cause and bool(hits), "named_among": bool(hits)}
    if hits:
        p = hits[0]["parameters"]
        fitted = p.get("factor", p.get("factor_rotational"))
        out["factor_fitted"] = fitted
        out["factor_error"] = abs(float(fitted) / case["factor"] - 1.0)
    return out


def run_case(case: dict, cfg: dict) -> dict:
    return diagnosed_capture(case, cfg, frame_toml(case), ["--points", ",".join(case["points"]), "--hits", "3"], score)


def diagnosed_capture(case: dict, cfg: dict, toml: str, capture_args: list[str],
                      score_case: Callable[[dict, dict, dict], dict]) -> dict:
    """The frame ``toml`` (a case's changes) captured through ``sim://`` at the case's seed with ``capture_args``
    (points, hits) and diagnosed against the frame as designed, as the commands a user runs: the case's row
    (verdict, named causes without their arrays, the trace, wall and CPU seconds of the diagnosis - ``cpu_s`` this
    process', ``cpu_children_s`` its worker processes' -) scored by ``score_case(case, doc, cfg)``."""
    from acquisition.cli_capture import main as capture
    from analysis.cli_diagnose import main as diagnose

    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        (t / "frame.toml").write_text(toml)
        rec, out = t / "rec.h5", t / "out.json"
        device = f"sim://?seed={case['seed']}&config={t / 'frame.toml'}"
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            rc = capture(["--device", device, "--out", str(rec), *capture_args, "--auto", "-q"])
            if rc != 0:
                return {**case, "verdict": f"capture failed ({rc})", "right": False, "named_among": False}
            t0, c0, k0 = time.perf_counter(), time.process_time(), _children_cpu()
            rc = diagnose(["--measured", str(rec), "--simulated", str(FRAME), "--json", str(out), "-q"])
            dt, cpu, kids = time.perf_counter() - t0, time.process_time() - c0, _children_cpu() - k0
        if rc != 0:
            return {**case, "verdict": f"diagnose failed ({rc})", "right": False, "named_among": False}
        doc = json.loads(out.read_text())
    # the parameters without their arrays (a gain per channel); a parameter's range (``<name>_range``) kept
    named = [{"effect": c["effect"], "parameters": {k: v for k, v in c["parameters"].items()
                                                    if not isinstance(v, (list, dict)) or k.endswith("_range")}}
             for c in doc.get("named") or []]
    # the rules that decided (the pair search's values among them: what a second cause gained over the first)
    return {**case, "verdict": doc["verdict"], "named": named, "reason": doc.get("reason", ""), "time_s": dt,
            "cpu_s": cpu, "cpu_children_s": kids, "trace": doc.get("trace"), **score_case(case, doc, cfg)}


def _children_cpu() -> float:
    """CPU seconds (user + system) of this process' finished child processes."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def line(r: dict) -> str:
    mark = "ok " if r["right"] else ("~  " if r.get("named_among") else "BAD")
    what = ("unchanged" if r["family"] == "null" else f"{r['place']} {r['mass_kg']} kg" if "mass_kg" in r
            else f"{r['place']} w x{r['width_factor']} d x{r['depth_factor']}" if "width_factor" in r
            else f"{r['place']} x{r['factor']}")
    named = "; ".join(f"{c['effect']} {c['parameters']}" for c in r.get("named", []))
    cpu = r.get("cpu_s", 0) + r.get("cpu_children_s", 0)
    return f"{mark} {r['name']:20s} {what:22s} -> {r['verdict']} {named} ({r.get('time_s', 0):.1f} s, CPU {cpu:.1f} s)"


def table(results: list[dict]) -> str:
    rows = ["| family | cases | named with kind and place | named among others | median factor error | median s |",
            "|---|---|---|---|---|---|"]
    for fam in dict.fromkeys(r["family"] for r in results):
        rs = [r for r in results if r["family"] == fam]
        err = [r["factor_error"] for r in rs if "factor_error" in r]
        rows.append(f"| {fam} | {len(rs)} | {sum(r['right'] for r in rs)} | {sum(r['named_among'] for r in rs)} | "
                    f"{100 * np.median(err):.1f} % | {np.median([r.get('time_s', np.nan) for r in rs]):.1f} |"
                    if err else
                    f"| {fam} | {len(rs)} | {sum(r['right'] for r in rs)} | {sum(r['named_among'] for r in rs)} | - | "
                    f"{np.median([r.get('time_s', np.nan) for r in rs]):.1f} |")
    dmg = [r for r in results if r["family"] != "null"]
    nul = [r for r in results if r["family"] == "null"]
    if dmg:
        rows.append(f"\ndamage at one place: {sum(r['right'] for r in dmg)}/{len(dmg)} named with kind and place")
    if nul:
        rows.append(f"nulls: {sum(not r['right'] for r in nul)} false alarms in {len(nul)}")
    rows.append(cpu_line(results))
    return "\n".join(rows)


def cpu_line(results: list[dict]) -> str:
    """The diagnosis' CPU per case (this process and its workers): median and largest, s."""
    cpu = [r.get("cpu_s", 0.0) + r.get("cpu_children_s", 0.0) for r in results if "cpu_s" in r]
    return f"CPU of the diagnosis per case: median {np.median(cpu):.1f} s, largest {max(cpu):.1f} s" if cpu else ""


def main() -> None:
    ap, sub = study_commands(__doc__)
    d = add_draw(sub, "draw", "draw a case list", damage=20, nulls=10)
    d.add_argument("--blocks", type=int, default=0, help="attached blocks (drawn from their own seed, seed + 1)")
    d.add_argument("--sections", type=int, default=0, help="section changes (drawn from their own seed, seed + 2)")
    add_run(sub, "run", "capture and diagnose every case of a list")
    args = ap.parse_args()
    if args.cmd == "draw":
        cases = draw(args.seed, args.damage, args.nulls) + draw_blocks(args.seed + 1, args.blocks)
        cases += draw_sections(args.seed + 2, args.sections)
        ranges = {**RANGES, "attached_block": {"mass_kg": BLOCK_MASS_KG, "side_m": BLOCK_SIDE_M}}
        if args.sections:
            ranges["section_change"] = {"side_factor": SECTION_SCALE, "min_change": SECTION_MIN_CHANGE}
        write_text_atomic(args.out, json.dumps({"seed": args.seed, "ranges": ranges, "cases": cases}, indent=1) + "\n")
        print(f"{len(cases)} cases -> {args.out}")
        return
    cfg = frame()
    cases = json.loads(Path(args.cases).read_text())["cases"]
    results = []
    t0 = time.perf_counter()
    for case in cases:
        res = run_case(case, cfg)
        results.append(res)
        print(line(res), flush=True)
        for out in [args.json] * bool(args.json) + [results_of_cases(args.cases, args.label)] * args.write:
            write_text_atomic(out, json.dumps(results, indent=1, default=str))
    print(table(results))
    print(f"wall time {time.perf_counter() - t0:.0f} s for {len(results)} cases")


if __name__ == "__main__":
    main()
