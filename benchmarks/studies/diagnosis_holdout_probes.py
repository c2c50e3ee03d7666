"""Why a hold-out case was missed: the model form behind a verdict, on the case's noise-free modes.

Not a hold-out (it fits the diagnosis' own causes, so it imports them): each probe builds the case's frame as
the one-place study configures it (:mod:`diagnosis_one_place`), takes its noise-free modes below 460 Hz at the
study's points (outputs: the test plan's sensors) and fits with the diagnosis' residuals (the chi2 the
diagnosis minimises; measured modes hold about one unit of chi2 per mode of noise):

* ``section CASES``: every section change of the list, fitted by ``member_stiffness`` and ``member_mass`` at
  the changed member (each alone, both together: the catalogue's best at the right place), then by the
  member's section with free factors on its area A, second moments Iy, Iz (explicit sections of the
  configuration, the rest nominal; the least squares start from no change, so a fit may stop in a local minimum:
  the chi2 at the true A, Iy, Iz is printed too): which freedoms a section change needs.
* ``block CASES NAME...``: an attached block's mass fitted by ``added_mass`` at its node with the rotary
  inertia about Y fixed at several multiples of the cube's: how far the modes pin the mass when the inertia is
  not known.
* ``refine CASES NAME...``: an attached block fitted by ``added_mass`` at its node with the mass alone and with
  the mass and each rotary-inertia factor, on the block frame's ten lowest noise-free modes (as the diagnosis
  uses): chi2 on all modes and held out per mode (leave one mode out, refitted from the full fit), and the
  held-out gain of the best refinement over the mass alone summed over all modes and as the diagnosis compares
  them (:func:`analysis.diagnosis.physical.refinement_gain_db`: without one mode neither predicts).

    OPENBLAS_NUM_THREADS=1 python benchmarks/studies/diagnosis_holdout_probes.py section \\
        benchmarks/studies/diagnosis_one_place_holdout_seed70.json
    OPENBLAS_NUM_THREADS=1 python benchmarks/studies/diagnosis_holdout_probes.py block \\
        benchmarks/studies/diagnosis_attached_block_holdout_seed72.json attached_block-02
    OPENBLAS_NUM_THREADS=1 python benchmarks/studies/diagnosis_holdout_probes.py refine \
        benchmarks/studies/diagnosis_attached_block_holdout_seed1207.json attached_block-09
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from diagnosis_one_place import POINTS, block_toml, frame  # noqa: E402
from scipy.optimize import least_squares, minimize_scalar  # noqa: E402

from analysis.diagnosis.physical import (  # noqa: E402
    MAX_MODES,
    N_SCREEN_FOLD,
    MeasuredModes,
    _held_out,
    fit_cause,
    gain_db,
    refinement_gain_db,
    residuals,
)
from simulator.config import FrameConfig  # noqa: E402
from simulator.fem import FrameModel, section_properties  # noqa: E402
from simulator.physical import FrameVariants  # noqa: E402

#: the measured band (Hz) and the simulation's (the diagnosis takes 1.5 times the highest measured mode)
BAND_HZ = 460.0
FMAX_HZ = 700.0


def _outputs(cfg: FrameConfig) -> list[str]:
    return list(cfg.test_plan.sensors)


def _modes(cfg: FrameConfig, fmax: float) -> tuple[np.ndarray, np.ndarray]:
    """Modes of a configured frame (accelerometers' mass at the outputs) below ``fmax`` (Hz): frequencies and
    residue vectors over (output, reference)."""
    outs = _outputs(cfg)
    sensors = {":".join(p.split(":")[:2]): cfg.sensors.accelerometer.mass_kg for p in outs}
    model = FrameModel.from_config(cfg, sensors).modal_model(outs, list(POINTS), "receptance")
    keep = (model.freq_hz > 1.0) & (model.freq_hz < fmax)
    return model.freq_hz[keep], model.residues[..., keep].reshape(-1, int(keep.sum()))


def measured(cfg: FrameConfig) -> MeasuredModes:
    """The configured frame's noise-free modes in the measured band."""
    f, P = _modes(cfg, BAND_HZ)
    return MeasuredModes(f, np.zeros(f.size), P)


def _least(fun: Callable[[np.ndarray], np.ndarray], n: int) -> tuple[float, np.ndarray]:
    """Least chi2 of residuals ``fun(log factors)`` from a few starts: (chi2, factors)."""
    best = None
    for x0 in (0.0, -0.3, 0.3):
        s = least_squares(fun, np.full(n, x0), bounds=(np.log(0.3), np.log(3.0)), diff_step=1e-3)
        if best is None or s.cost < best.cost:
            best = s
    assert best is not None
    return 2.0 * float(best.cost), np.exp(best.x)


def probe_section(case: dict, base: FrameConfig, fv: FrameVariants) -> list[str]:
    comp = case["place"]
    sec = base.sections[base.components[comp].section]
    cfg = base.with_overrides({"sections": {"changed": {"shape": "rect", "width_m": sec.width_m * case["width_factor"],
                                                        "depth_m": sec.depth_m * case["depth_factor"]}},
                               "components": {comp: {"section": "changed"}}})
    mm = measured(cfg)
    nom, tru = section_properties(sec), section_properties(cfg.sections["changed"])
    out = [f"{case['name']} {comp}: width x{case['width_factor']} depth x{case['depth_factor']} (A x{tru.A / nom.A:.3f}, "
           f"Iy x{tru.Iy / nom.Iy:.3f}, Iz x{tru.Iz / nom.Iz:.3f}, J x{tru.J / nom.J:.3f}); {mm.freq_hz.size} modes, "
           f"chi2 unchanged {float(np.sum(residuals(mm, *fv.modes(None, {}, FMAX_HZ)) ** 2)):.1f}"]
    for names in (("member_stiffness",), ("member_mass",), ("member_stiffness", "member_mass")):
        def r(x: np.ndarray, names: Sequence[str] = names) -> np.ndarray:
            changes = [(n, {"component": comp, "factor": float(np.exp(v))}) for n, v in zip(names, x)]
            return residuals(mm, *fv.modes_of(changes, FMAX_HZ)).ravel()
        chi2, x = _least(r, len(names))
        out.append(f"  {' + '.join(names)} at {comp}: chi2 {chi2:.2f}, factors {np.round(x, 3).tolist()}")
    for free in (("Iy", "Iz"), ("A", "Iy", "Iz")):
        def rs(x: np.ndarray, free: Sequence[str] = free) -> np.ndarray:
            fac = dict(zip(free, np.exp(x)))
            s = {"shape": "explicit", "area_m2": nom.A * fac.get("A", 1.0), "iy_m4": nom.Iy * fac.get("Iy", 1.0),
                 "iz_m4": nom.Iz * fac.get("Iz", 1.0), "j_m4": nom.J}
            trial = base.with_overrides({"sections": {"trial": s}, "components": {comp: {"section": "trial"}}})
            return residuals(mm, *_modes(trial, FMAX_HZ)).ravel()
        chi2, x = _least(rs, len(free))
        out.append(f"  section with free {', '.join(free)} (J nominal): chi2 {chi2:.2f}, "
                   f"factors {dict(zip(free, np.round(x, 3).tolist()))}")
    true = np.log([tru.A / nom.A, tru.Iy / nom.Iy, tru.Iz / nom.Iz])
    out.append(f"  section at the true A, Iy, Iz (J nominal): chi2 {float(np.sum(rs(true, ('A', 'Iy', 'Iz')) ** 2)):.2f}")
    return out


def probe_block(case: dict, fv: FrameVariants, inertia_y: Sequence[float] = (0.25, 0.5, 1.0, 2.0, 4.0)) -> list[str]:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "frame.toml"
        path.write_text(block_toml(case, frame()))
        mm = measured(FrameConfig.load(path))
    out = [f"{case['name']} {case['place']}: {case['mass_kg']} kg, span {case['span_m']} m along {case['span_axis']}, "
           f"section {case['section_m']} m"]
    for iy in inertia_y:
        def chi2(log_m: float, iy: float = iy) -> float:
            p = {"point": case["place"], "mass_kg": float(np.exp(log_m)), "inertia_factor": 1.0, "inertia_x": 1.0,
                 "inertia_y": iy, "inertia_z": 1.0}
            return float(np.sum(residuals(mm, *fv.modes("added_mass", p, FMAX_HZ)) ** 2))
        s = minimize_scalar(chi2, bounds=(np.log(0.3), np.log(10.0)), method="bounded")
        out.append(f"  rotary inertia about Y x{iy} the cube's: mass {np.exp(s.x):.3f} kg, chi2 {s.fun:.4f}")
    return out


def _cv_per_mode(fv: FrameVariants, spec: object, free: tuple, mm: MeasuredModes, ranked: list) -> np.ndarray:
    """Held-out chi2 of each mode as the diagnosis has it: the cause refitted on the other modes at the
    ``N_SCREEN_FOLD`` best nodes of the full fit (``ranked``), each from its full fit."""
    options = [o for _, o, _ in ranked[:N_SCREEN_FOLD]]
    starts = {o: q for _, o, q in ranked}
    return np.array([_held_out(fv, spec, free, mm, FMAX_HZ, options, starts, k)  # type: ignore[arg-type]
                     for k in range(mm.freq_hz.size)])


def probe_refine(case: dict, fv: FrameVariants) -> list[str]:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "frame.toml"
        path.write_text(block_toml(case, frame()))
        mm = measured(FrameConfig.load(path))
    mm = mm.subset(np.arange(mm.freq_hz.size) < MAX_MODES)
    spec = {c.name: c for c in fv.causes()}["added_mass"]
    out = [f"{case['name']} {case['place']}: {case['mass_kg']} kg, span {case['span_m']} m along {case['span_axis']}, "
           f"section {case['section_m']} m; modes {np.round(mm.freq_hz, 1).tolist()} Hz"]
    rows: list[tuple[tuple[str, ...], np.ndarray]] = []
    every = np.ones(mm.freq_hz.size, bool)
    # the mass alone searched over every node as the diagnosis does; each refinement from that fit at its node
    p, chi2, ranked = fit_cause(fv, spec, ("mass_kg",), mm, every, FMAX_HZ)
    nested = [q for _, _, q in ranked]
    frees: list[tuple[str, ...]] = [("mass_kg",)]
    frees += [("mass_kg", x) for x in ("inertia_factor", "inertia_x", "inertia_y", "inertia_z")]
    for free in frees:
        if len(free) > 1:
            p, chi2, ranked = fit_cause(fv, spec, free, mm, every, FMAX_HZ, nested=nested)
        cv = _cv_per_mode(fv, spec, free, mm, ranked)
        rows.append((free, cv))
        out.append(f"  {' + '.join(free)}: {p['point']}, {', '.join(f'{k} {p[k]:.3f}' for k in free)}; chi2 {chi2:.2f}; held out "
                   f"{cv.sum():.1f} per mode {np.round(cv, 2).tolist()}")
    base = rows[0][1]
    best = min(rows[1:], key=lambda r: float(r[1].sum()))
    out.append(f"  best refinement {best[0][1]}: held-out gain over the mass alone {gain_db(base, best[1]):.1f} dB over "
               f"all modes, {refinement_gain_db(base, best[1]):.1f} dB as compared (one mode neither predicts left out)")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("section", help="the section changes of a case list against the member causes")
    s.add_argument("cases")
    b = sub.add_parser("block", help="an attached block's mass against its rotary inertia")
    b.add_argument("cases")
    b.add_argument("names", nargs="+")
    r = sub.add_parser("refine", help="an attached block: the mass alone against each rotary-inertia refinement")
    r.add_argument("cases")
    r.add_argument("names", nargs="+")
    args = ap.parse_args()
    base = FrameConfig.load()
    fv = FrameVariants(None, _outputs(base), list(POINTS))
    cases = {c["name"]: c for c in json.loads(Path(args.cases).read_text())["cases"]}
    if args.cmd == "section":
        todo = [c for c in cases.values() if c["family"] == "section_change"]
        lines: Callable[[dict], list[str]] = lambda c: probe_section(c, base, fv)  # noqa: E731
    elif args.cmd == "refine":
        todo = [cases[n] for n in args.names]
        lines = lambda c: probe_refine(c, fv)  # noqa: E731
    else:
        todo = [cases[n] for n in args.names]
        lines = lambda c: probe_block(c, fv)  # noqa: E731
    for case in todo:
        print("\n".join(lines(case)), flush=True)


if __name__ == "__main__":
    main()
