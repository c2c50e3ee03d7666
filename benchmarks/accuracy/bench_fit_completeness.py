"""Completeness of the automatic fit: does ``fit_auto`` fit every mode the data show?

Cases
-----
Captures of the simulated frame through the simulated analyser (``sim://?seed=S``, the
roving-hammer test plan's three accelerometers, 5 hits per point, every hit that passes the
automatic checks accepted, default windows), fitted with ``analysis.pipeline.fit_auto`` as
``analysis fit REC`` does (default band, or a narrow band given as the user's). The hammer
points: the four combinations of right:6:-X, left:9:Y and top:4:Z, the one-point capture
right:6:-X (seed 1) in 4..215 Hz (a 160.0 / 161.0 Hz pair), and ``--draws`` captures whose
seed, hammer points (1 to 3 nodes of the frame, supports excluded, each with a direction drawn
from +-X, +-Y, +-Z) and band (default, or a narrow band of 120..400 Hz width starting between
10 and 700 Hz) are drawn by a seeded generator (``--draw-seed``), not chosen. Then the real
datasets of ``docs/validation.md`` (from ``--data``; skipped when absent) with their default band.

Visible modes (independent of the fit)
--------------------------------------
The visible peaks of :mod:`analysis.visibility` (data only): on the magnitude of every FRF and
on the first CMIF curve, a local maximum inside the band standing >= 10 dB above the higher of
its two neighbouring minima, with a coherence >= 0.9 over its top (the lines within 3 dB of
the maximum and one more each side) when the data carry coherence, else at least two lines
wide at 3 dB (without coherence and with more than 8 FRFs only the CMIF curve). On the
simulated frame a true mode (the frame model's modal solution with the capture's sensor
masses, :attr:`simulator.stand.TestStand.model`) is *visible* when a visible peak lies within
``max(0.5 % f, 1.5 lines)`` of it and it is the true mode nearest that peak. On real data (no
truth) the visible peaks themselves, merged within ``max(0.5 %, 1.5 lines)``, are the visible
modes.

Scores per capture
------------------
fitted: visible modes with a fitted pole within 0.5 %, each pole counted for one mode only (real data: within ``max(0.5 %, 1.5
lines)`` of the peak); named: visible modes left unfitted whose frequency (within 1 %) appears
in a warning or a problem of the result; spurious: fitted poles (in the band) with no true mode within 1 % or two poles on
one true mode (simulated frame only); dishonest: ``success`` is True while a visible mode is left.
Targets: >= 98 % of visible modes fitted, 0 dishonest fits, 0 spurious poles; the time of the
default fit of a default capture (3 FRFs, ~1.1 kHz) is printed as well.

Run (about 2 s per capture for the capture, plus the fits)::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/accuracy/bench_fit_completeness.py [--draws 16]
        [--data ../shared/data] [--no-real] [--json out.json] [--exp-window none]
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import re
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from analysis.frf import FRFSet  # noqa: E402
from analysis.pipeline import fit_auto  # noqa: E402
from analysis.visibility import visible_peaks as find_visible  # noqa: E402

MATCH_FRACTION = 0.005
MATCH_LINES = 1.5
SPURIOUS_FRACTION = 0.01
DIRECTIONS = ("X", "-X", "Y", "-Y", "Z", "-Z")
ISSUE_POINTS = ("right:6:-X", "left:9:Y", "top:4:Z")


@dataclass
class Case:
    name: str
    seed: int
    points: tuple[str, ...]
    band: tuple[float, float] | None = None


@dataclass
class Row:
    name: str
    band: tuple[float, float]
    visible: list[float]
    fitted: list[float]
    missed: list[float]
    named: list[float]
    spurious: list[float]
    success: bool
    time_s: float
    n_poles: int
    extra: dict = field(default_factory=dict)

    @property
    def dishonest(self) -> bool:
        return self.success and bool(self.missed)


def frame_nodes() -> list[str]:
    """``component:node`` of every node of the simulated frame that is not a support."""
    from simulator.config import FrameConfig
    from simulator.geometry import frame_geometry

    geo = frame_geometry(FrameConfig.load())
    return [n for n in geo.labels if n not in set(geo.supports)]


def cases(draws: int, draw_seed: int) -> list[Case]:
    out = [Case("issue: " + p, 1, (p,)) for p in ISSUE_POINTS]
    out.append(Case("issue: all three", 1, ISSUE_POINTS))
    out.append(Case("issue: right:6:-X 4-215 Hz", 1, ("right:6:-X",), (4.0, 215.0)))
    rng = np.random.default_rng(draw_seed)
    nodes = frame_nodes()
    for i in range(draws):
        seed = int(rng.integers(1, 1000))
        k = int(rng.integers(1, 4))
        pts = tuple(f"{nodes[j]}:{DIRECTIONS[int(rng.integers(len(DIRECTIONS)))]}"
                    for j in rng.choice(len(nodes), size=k, replace=False))
        band = None
        if rng.random() < 0.35:
            lo = float(rng.uniform(10.0, 700.0))
            band = (round(lo, 1), round(lo + float(rng.uniform(120.0, 400.0)), 1))
        out.append(Case(f"draw {i + 1}", seed, pts, band))
    return out


def capture(case: Case, folder: Path, exp_window: str | None = None) -> tuple[FRFSet, np.ndarray]:
    """The case captured through the simulated analyser: (FRFs, true natural frequencies Hz);
    ``exp_window``: the capture's ``--exp-window`` (None: its default)."""
    from acquisition.cli_capture import main as capture_main
    from analysis.recording import load_frfset
    from simulator.stand import TestStand

    rec = folder / f"{re.sub(r'[^A-Za-z0-9]+', '_', case.name)}_{case.seed}.h5"
    if rec.exists():
        rec.unlink()
    with contextlib.redirect_stdout(io.StringIO()):
        code = capture_main(["--device", f"sim://?seed={case.seed}", "--out", str(rec), "--points",
                             ",".join(case.points), "--hits", "5", "--auto", "-q"]
                            + ([] if exp_window is None else ["--exp-window", exp_window]))
    if code != 0:
        raise RuntimeError(f"capture of {case.name} failed with exit code {code}")
    frf = load_frfset(rec)
    truth = np.asarray(TestStand(seed=case.seed).model.modes(float(frf.freq_hz[-1]) * 1.2).freq_hz, float)
    return frf, truth[truth > 0]


def visible_peaks(frf: FRFSet, band: tuple[float, float]) -> np.ndarray:
    """Frequencies (Hz) of the visible peaks (:func:`analysis.visibility.visible_peaks`)."""
    return np.asarray([v.freq_hz for v in find_visible(frf, band)], float)


def visible_modes(peaks: np.ndarray, truth: np.ndarray | None, df: float) -> np.ndarray:
    """Visible true modes (truth given) or merged visible peaks (real data), sorted (Hz)."""
    if truth is None:
        merged: list[float] = []
        for p in np.sort(peaks):
            if merged and p - merged[-1] <= max(MATCH_FRACTION * p, MATCH_LINES * df):
                continue
            merged.append(float(p))
        return np.asarray(merged)
    vis = set()
    for p in peaks:
        k = int(np.argmin(np.abs(truth - p)))
        if abs(truth[k] - p) <= max(MATCH_FRACTION * truth[k], MATCH_LINES * df):
            vis.add(k)
    return np.sort(truth[sorted(vis)])


def named_in_warnings(f: float, warnings: Sequence[str]) -> bool:
    for w in warnings:
        for m in re.finditer(r"(\d+(?:\.\d+)?)\s*(?:/|Hz)", w):
            if abs(float(m.group(1)) - f) <= SPURIOUS_FRACTION * f:
                return True
    return False


def score(name: str, frf: FRFSet, truth: np.ndarray | None, band: tuple[float, float] | None) -> Row:
    t0 = time.perf_counter()
    try:
        res = fit_auto(frf, band=band)
        fit_f = np.asarray(res.freq_hz, float)
        success, warnings, fband = bool(res.success), list(res.warnings) + list(res.problems), tuple(res.band)
    except Exception as exc:  # a failed fit fits nothing; the benchmark goes on
        fit_f, success, warnings = np.zeros(0), False, [f"fit failed: {exc}"]
        fband = tuple(band) if band is not None else (float(frf.freq_hz[0]), float(frf.freq_hz[-1]))
    dt = time.perf_counter() - t0
    df = float(frf.line_spacing_hz)
    vis = visible_modes(visible_peaks(frf, fband), truth, df)
    tol = (lambda v: MATCH_FRACTION * v) if truth is not None else (lambda v: max(MATCH_FRACTION * v, MATCH_LINES * df))
    fitted: list[float] = []
    free = list(fit_f)
    for v in vis:   # one pole fits one mode: a pole between a close pair fits only the nearer one
        if free and min(abs(x - v) for x in free) <= tol(v):
            others = [w for w in vis if w != v]
            x = min(free, key=lambda x: abs(x - v))
            if not others or abs(x - v) <= min(abs(x - w) for w in others):
                fitted.append(float(v))
                free.remove(x)
    missed = [float(v) for v in vis if v not in fitted]
    named = [v for v in missed if named_in_warnings(v, warnings)]
    spurious: list[float] = []
    if truth is not None:
        used: set[int] = set()
        for x in sorted(fit_f):
            k = int(np.argmin(np.abs(truth - x)))
            if abs(truth[k] - x) > SPURIOUS_FRACTION * truth[k] or k in used:
                spurious.append(float(x))
            used.add(k)
    return Row(name, (float(fband[0]), float(fband[1])), vis.tolist(), fitted, missed, named, spurious, success, dt,
               int(fit_f.size), {"warnings": warnings})


def real_cases(data: Path) -> list[tuple[str, Any]]:
    """(name, loader) of the real datasets of docs/validation.md, loaded over their whole range."""
    from benchmarks.accuracy.validation.datasets import DATASETS

    return [(d.label, partial(d.load, data, **d.whole_range)) for d in DATASETS]


def _hz(values: Sequence[float], n: int = 8) -> str:
    s = ", ".join(f"{v:.5g}" for v in values[:n])
    return s + (", ..." if len(values) > n else "") if values else "-"


def print_table(rows: Sequence[Row], title: str) -> None:
    print(f"\n{title}\n")
    print("| case | band [Hz] | visible | fitted within 0.5 % | missed (named in a warning or problem *) | spurious | "
          "success | poles | fit s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        missed = [f"{v:.5g}" + ("*" if v in r.named else "") for v in r.missed]
        print(f"| {r.name} | {r.band[0]:.4g}-{r.band[1]:.4g} | {len(r.visible)} | {len(r.fitted)} | "
              f"{', '.join(missed) or '-'} | {_hz(r.spurious)} | {r.success} | {r.n_poles} | {r.time_s:.2f} |")


def totals(rows: Sequence[Row], title: str) -> dict:
    n_vis = sum(len(r.visible) for r in rows)
    n_fit = sum(len(r.fitted) for r in rows)
    out = {"visible": n_vis, "fitted": n_fit, "fraction": n_fit / n_vis if n_vis else float("nan"),
           "missed_named": sum(len(r.named) for r in rows), "missed": sum(len(r.missed) for r in rows),
           "dishonest": sum(r.dishonest for r in rows), "spurious": sum(len(r.spurious) for r in rows)}
    print(f"\n{title}: {n_fit} of {n_vis} visible modes fitted within 0.5 % ({100 * out['fraction']:.1f} %; "
          f"target >= 98 %), {out['missed']} missed of which {out['missed_named']} named in a warning, "
          f"{out['dishonest']} fit(s) claiming success with a visible mode left (target 0), "
          f"{out['spurious']} spurious pole(s) (target 0)")
    return out


def default_fit_time(frf: FRFSet, repeats: int = 3) -> float:
    """Best of ``repeats`` wall times (s) of ``fit_auto`` with the default band."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fit_auto(frf)
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=16, help="drawn captures beside the five fixed ones (default 16)")
    ap.add_argument("--draw-seed", type=int, default=2026, help="seed of the draws (default 2026)")
    ap.add_argument("--data", default=str(ROOT.parent.parent / "shared" / "data"), help="real datasets folder")
    ap.add_argument("--no-real", action="store_true", help="skip the real datasets")
    ap.add_argument("--only", default=None, help="run only the cases whose name contains this text")
    ap.add_argument("--json", default=None, help="write the rows as JSON here")
    ap.add_argument("--exp-window", default=None, metavar="PCT%|none",
                    help="the captures' exponential window (default: the capture's, 5 %%; none: the record as measured)")
    args = ap.parse_args(argv)

    rows: list[Row] = []
    default_frf = None
    with tempfile.TemporaryDirectory(prefix="fitcomplete-") as tmp:
        for case in cases(args.draws, args.draw_seed):
            if args.only and args.only not in case.name:
                continue
            frf, truth = capture(case, Path(tmp), args.exp_window)
            if case.name == "issue: right:6:-X" and case.band is None:
                default_frf = frf
            row = score(f"{case.name} [{','.join(case.points)} seed {case.seed}]", frf, truth, case.band)
            rows.append(row)
            print(f"{row.name}: {len(row.fitted)}/{len(row.visible)} fitted, missed {_hz(row.missed)}, "
                  f"spurious {_hz(row.spurious)}, success {row.success}, {row.time_s:.2f} s", flush=True)
    print_table(rows, "Simulated frame (captured through the simulated analyser, 5 hits per point)")
    summary = {"simulated": totals(rows, "simulated frame")}
    real_rows: list[Row] = []
    data = Path(args.data)
    if not args.no_real and data.is_dir():
        for name, load in real_cases(data):
            if args.only and args.only not in name:
                continue
            try:
                frf = load()
            except (OSError, FileNotFoundError) as exc:
                print(f"{name}: skipped ({exc})")
                continue
            row = score(name, frf, None, None)
            real_rows.append(row)
            print(f"{name}: {len(row.fitted)}/{len(row.visible)} fitted, missed {_hz(row.missed)}, "
                  f"success {row.success}, {row.time_s:.2f} s", flush=True)
        print_table(real_rows, "Real datasets (default band; visible modes = visible peaks, no truth)")
        summary["real"] = totals(real_rows, "real datasets")
    elif not args.no_real:
        print(f"\nreal datasets skipped: {data} not found")
    if default_frf is not None:
        t = default_fit_time(default_frf)
        summary["default_fit_s"] = t
        print(f"\ndefault fit of a default capture (right:6:-X, seed 1, {default_frf.n_outputs * default_frf.n_references} "
              f"FRFs, {default_frf.freq_hz.size} lines): best of 3 = {t:.2f} s wall")
    if args.json:
        doc = {"summary": summary, "rows": [{**r.__dict__, "dishonest": r.dishonest} for r in rows + real_rows]}
        Path(args.json).write_text(json.dumps(doc, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
