"""Frames changed in one physical way, each captured through ``sim://?config=...`` (the default test
plan's six points, 3 hits each) and diagnosed against the unchanged frame.toml with the command line
(``python -m analysis diagnose``). Prints the table; ``--write`` replaces its results file,
``diagnosis_changed_frames_table.md`` beside it, with this run.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/studies/diagnosis_changed_frames_table.py --write
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
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks" / "accuracy"))

import bench_diagnosis_physical as bench  # noqa: E402

from benchmarks.results import add_write_option, recorded  # noqa: E402
from simulator.config import FrameConfig, overrides_to_toml  # noqa: E402
from simulator.fem import section_properties  # noqa: E402

#: this study's results file (``--write`` replaces it with the run's table)
RESULTS = Path(__file__).with_name("diagnosis_changed_frames_table.md")
POINTS = "right:6:-X,right:4:-X,left:6:X,top:4:Z,top:2:Z,left:9:Y"


def cases() -> list[tuple[str, dict, list]]:
    cfg = FrameConfig.load()
    col, beam = section_properties(cfg.sections["column"]), section_properties(cfg.sections["beam"])
    block = bench.steel_block(cfg, "top:4", 3.0)
    s, j = list(cfg.supports.stiffness), list(cfg.joints.stiffness)
    zeta = list(cfg.damping.zeta)
    return [
        ("a 3 kg steel block fixed on the beam (top:4)", block, []),
        ("one column (left) 25 % heavier", {"sections": {"heavy": {"shape": "explicit", "area_m2": 1.25 * col.A,
                                                                   "iy_m4": col.Iy, "iz_m4": col.Iz, "j_m4": col.J}},
                                            "components": {"left": {"section": "heavy"}}}, []),
        ("the beam 15 % less stiff in bending", {"sections": {"beam": {"shape": "explicit", "area_m2": beam.A,
                                                                       "iy_m4": 0.85 * beam.Iy, "iz_m4": 0.85 * beam.Iz,
                                                                       "j_m4": beam.J}}}, []),
        ("support rotational stiffness x0.4", {"supports": {"stiffness": s[:3] + [0.4 * v for v in s[3:]]}}, []),
        ("support rotational stiffness x0.5", {"supports": {"stiffness": s[:3] + [0.5 * v for v in s[3:]]}}, []),
        ("joint rotational stiffness x0.05", {"joints": {"stiffness": j[:3] + [0.05 * v for v in j[3:]]}}, []),
        ("heavier accelerometers (60 g)", {"sensors": {"accelerometer": {"mass_kg": 0.06}}}, []),
        ("nothing changed, captured with --exp-window 5%", {}, ["--exp-window", "5%"]),
        ("damping x2", {"damping": {"zeta": [2 * z for z in zeta], "zeta_default": 2 * cfg.damping.zeta_default}}, []),
        ("modulus +8 %", {"material": {"youngs_modulus_pa": 1.08 * cfg.material.youngs_modulus_pa}}, []),
        ("the right column's roll 20 -> 40 deg (out of the catalogue)", {"components": {"right": {"roll_deg": 40.0}}}, []),
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_write_option(ap, RESULTS)
    args = ap.parse_args()
    with recorded(RESULTS, args.write):
        _run()


def _run() -> None:
    """The run itself (what :func:`main` records with ``--write``)."""
    from acquisition.cli_capture import main as capture
    from analysis.cli_diagnose import main as diagnose

    print("| change made to the frame | verdict | parameters | held-out gain dB | FRF error before -> after (noise) dB | s |")
    print("|---|---|---|---|---|---|")
    for i, (label, over, extra) in enumerate(cases()):
        with tempfile.TemporaryDirectory() as tmp:
            device = f"sim://?seed={100 + i}"
            if over:
                (Path(tmp) / "c.toml").write_text(overrides_to_toml(over))
                device += f"&config={Path(tmp) / 'c.toml'}"
            rec, out = Path(tmp) / "r.h5", Path(tmp) / "d.json"
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                capture(["--device", device, "--out", str(rec), "--points", POINTS, "--hits", "3", "--auto", "-q", *extra])
                t0 = time.perf_counter()
                diagnose(["--measured", str(rec), "--simulated", str(ROOT / "simulator" / "frame.toml"), "--json", str(out),
                          "-q"])
                dt = time.perf_counter() - t0
            d = json.loads(out.read_text())
        best = next((c for c in d["causes"] if c["effect"] == d["verdict"]), None)
        params = ", ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}"
                           for k, v in (best["parameters"] if best else {}).items() if not isinstance(v, (list, dict)))
        gain = f"{best['gain_db']:.1f}" if best else ""
        noise = max(d["noise_db"].values())
        print(f"| {label} | `{d['verdict']}` | {params} | {gain} | {d['error_before_db']:.1f} -> {d['error_after_db']:.1f} "
              f"({noise:.1f}) | {dt:.1f} |", flush=True)


if __name__ == "__main__":
    main()
