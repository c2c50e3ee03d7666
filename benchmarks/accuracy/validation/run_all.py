"""Regenerate ``docs/validation.md`` and ``docs/validation/*.png``: every real dataset, ours vs sdypy-EMA.

Usage (from the project root; the peer's venv has both impactlab and sdypy-EMA)::

    ../peer-venv/bin/python -m benchmarks.accuracy.validation.run_all [--data ../shared/data] [--only NAME ...]
    ../peer-venv/bin/python benchmarks/accuracy/validation/run_all.py

With the project venv (``.venv/bin/python``) sdypy is absent: our side is produced and the report says
the peer was unavailable. Exit status 0 when every case ran, 1 when one failed (its error is in the report),
2 when the data folder is missing.
"""
from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import importlib  # noqa: E402
import logging  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402
from pathlib import Path  # noqa: E402

if __package__ in (None, ""):  # run as a script: make the project root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[3]))

import numpy as np  # noqa: E402

from analysis.atomic import write_text_atomic  # noqa: E402
from benchmarks.accuracy.validation.case import summary_row, summary_row_header  # noqa: E402
from benchmarks.accuracy.validation.common import md_table  # noqa: E402
from benchmarks.accuracy.validation.peer import _version, peer_available  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]
CASES = ("uliege_plane", "modelab_beam", "ladisk_beam", "pyfrf_5impacts", "f16_gvt", "plate_sweep", "pyuff_3frf",
         "unesp_boltedbeam")

DISCUSSION = Path(__file__).with_name("discussion.md")
#: the commands that take every dataset from its files to the results, with what they print
COMMANDS = Path(__file__).with_name("commands.md")
#: the automatic fit against the analyst's key, the page's last section (``benchmarks/studies/realdata_key.py
#: --markdown`` writes it)
KEY_SECTION = Path(__file__).with_name("key_section.md")

#: summary case name -> prefix of its figures in ``discussion.md`` (``{uliege_err_ours:.3g}`` ...)
CASE_KEYS = {
    "uliege_meca0062_plane_hammer": "uliege",
    "uliege_meca0062_plane_hammer (unweighted)": "uliege_unweighted",
    "modelab_beam_roving_hammer": "modelab",
    "ladisk_beam (1 hit)": "ladisk1",
    "ladisk_beam (4 hits)": "ladisk4",
    "pyfrf_hammer_5impacts (automatic)": "pyfrf",
    "pyfrf_hammer_5impacts (peak hints)": "pyfrf_hint",
    "f16_gvt_multisine": "f16",
    "ladisk_plate_sweep": "plate",
    "pyuff_3frf": "pyuff",
    "unesp_bert_boltedbeam_subset (0.05 V)": "unesp",
}


class _Unfilled:
    """Stands for a figure the run did not compute (case not run, or peer unavailable)."""

    def __init__(self, key: str):
        self.key = key

    def __format__(self, spec: str) -> str:
        return f"[{self.key}: not computed]"


class Figures(dict):
    """Figure name -> value for ``str.format_map``; unknown names are recorded in ``missing``."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.missing: list[str] = []

    def __missing__(self, key: str):
        self.missing.append(key)
        return _Unfilled(key)

    def __getitem__(self, key: str):
        v = super().__getitem__(key)
        return _Unfilled(key) if v is None else v


def figures_from(summaries: list[dict]) -> Figures:
    """The figures the discussion may quote: per summary row ``{key}_modes_ours``, ``{key}_modes_peer``,
    ``{key}_err_ours``, ``{key}_err_peer``, ``{key}_err_peer_fixed`` (percent) and every entry of the row's
    ``figures`` dict as ``{key}_{name}``; ``key`` from :data:`CASE_KEYS` (else the case name, lower case,
    non-alphanumerics as ``_``)."""
    out = Figures()
    for s in summaries:
        key = CASE_KEYS.get(s["case"]) or "".join(c if c.isalnum() else "_" for c in s["case"].lower())
        for name in ("modes_ours", "modes_peer", "err_ours", "err_peer", "err_peer_fixed"):
            out[f"{key}_{name}"] = s.get(name)
        for name, v in (s.get("figures") or {}).items():
            out[f"{key}_{name}"] = v
    return out


def fill_discussion(text: str, figures: Figures) -> tuple[str, list[str]]:
    """``text`` with its ``{name:spec}`` placeholders filled from ``figures`` (``str.format_map``);
    returns the text and the names that were not available (shown in the text as not computed)."""
    figures.missing = []
    return text.format_map(figures), list(dict.fromkeys(figures.missing))


def _defects_section() -> str:
    if not peer_available():
        return "sdypy-EMA unavailable in this interpreter: the reproduction was not run."
    from benchmarks.accuracy.validation.peer_defects import reproduce

    r = reproduce()
    return "\n".join([
        "1. **Pole bookkeeping.** `select_closest_poles` reports `nat_freq`/`nat_xi` from column c of its "
        "stabilization matrix, which `_stabilization` fills with the poles of model `all_poles[c + 1]`, but stores "
        "`pole_ind = [c, k]`, so `get_constants` (LSFD and reconstruction) uses the nearest pole of the previous "
        "model order. The reported and the used poles differ (every case above notes the largest difference); "
        "when the previous order lacks the mode the used pole is another mode's or unstable (ULiege with a 39 Hz "
        "search window: reported 0.022 Hz, used 100.47 Hz with negative damping). Repairing `pole_ind` "
        "(`peer.fit_peer(..., repair=True)`) changes the synthesis error by up to about 1 point (summary table).",
        "2. **Hint search drifts.** With a wide `f_window` (default 50 Hz) the least-squares walk of "
        "`select_closest_poles` moves hints to dense clusters of stable poles: on ULiege (39 Hz window) 5 of 10 "
        "hints ended on 89.64 Hz and one on 0 Hz; on the F-16 band (2-15 Hz) every hint came back as 0 Hz and the LSFD used "
        "poles with negative damping. The scripts use `f_window=4` (a +-2 Hz search), after which it takes the "
        "nearest stable LSCF pole. Not reduced to a synthetic reproduction.",
        "3. **Silent progress bar.** `select_closest_poles` prints a tqdm bar to stderr even after "
        "`get_poles(show_progress=False)` (`_stabilization` wraps its loop in tqdm unconditionally).",
        "4. **Scope, not defects:** no exponential-window correction (we shifted its poles by 1/tau), no "
        "automatic pole selection, and a linear LSFD (its damping is LSCF's).",
        "",
        "Reproduction (`python -m benchmarks.accuracy.validation.peer_defects`, two exactly known modes at 40 Hz / 1 % and "
        "95 Hz / 2 %, noise-free accelerance, `pol_order_high=12`, hints 40 and 95 Hz):",
        "",
        md_table(["", "mode 1", "mode 2"], [
            ["reported `nat_freq` [Hz]", *(f"{x:.9g}" for x in r["reported_f"])],
            ["reported `nat_xi`", *(f"{x:.9g}" for x in r["reported_zeta"])],
            ["model order index the reported pole comes from", *(str(x) for x in r["reported_from_order_index"])],
            ["`pole_ind` (order index, pole index) used by `get_constants`", *(str([int(v) for v in x]) for x in r["pole_ind"])],
            ["used pole f [Hz]", *(f"{x:.9g}" for x in r["used_f"])],
            ["used pole zeta", *(f"{x:.9g}" for x in r["used_zeta"])],
        ]),
    ])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"), help="the shared data folder")
    ap.add_argument("--out", default=str(ROOT / "docs"), help="where validation.md and validation/ go")
    ap.add_argument("--only", nargs="*", default=None, help=f"cases to run (default all: {', '.join(CASES)})")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    data = Path(args.data)
    if not data.is_dir():
        print(f"data folder {data} not found: give --data PATH (the shared real-data folder)", file=sys.stderr)
        return 2
    out = Path(args.out)
    pics = out / "validation"
    pics.mkdir(parents=True, exist_ok=True)
    reports, failures, times = [], [], {}
    for name in args.only or CASES:
        if name not in CASES:
            print(f"unknown case {name!r}; choose from {', '.join(CASES)}", file=sys.stderr)
            return 2
        t0 = time.perf_counter()
        try:
            mod = importlib.import_module(f"benchmarks.accuracy.validation.{name}")
            reports.append(mod.run(data, pics))
        except Exception:  # noqa: BLE001 - a failing case is reported, the others still run
            failures.append((name, traceback.format_exc()))
        times[name] = time.perf_counter() - t0
        print(f"{name}: {times[name]:.1f} s", file=sys.stderr)
    peer = f"sdypy-EMA {_version()}" if peer_available() else "sdypy-EMA unavailable (not importable here)"
    doc = [
        "# Validation on real measured data, side by side with sdypy-EMA",
        "",
        "Generated by `python -m benchmarks.accuracy.validation.run_all` in an environment with sdypy-EMA installed (do not edit by hand; the "
        "discussion comes from `benchmarks/accuracy/validation/discussion.md`, its figures filled in from this run's results, "
        "the commands section from `benchmarks/accuracy/validation/commands.md`, the key's section from "
        "`benchmarks/accuracy/validation/key_section.md`). "
        f"Python {platform.python_version()}, numpy {np.__version__}, peer: {peer}. Data: `../shared/data` "
        "(never copied into the repository; sources and terms per case below). Times are wall-clock on a shared "
        "2-core machine with single-threaded BLAS.",
        "",
        "impactlab = `analysis.pipeline.fit_auto`: LSCF stabilization, automatic hint-free pole selection, nonlinear "
        "LSFD (Levenberg-Marquardt, variable projection) with global poles and residual terms; exponential windows "
        "removed through `FRFSet.exp_window_tau_s`. sdypy-EMA = `Model.get_poles('lscf')` + "
        "`select_closest_poles(our frequencies)` (it has no automatic selection, so it is given ours) + "
        "`get_constants('lsfd')` (linear: its poles are LSCF's).",
        "",
        "## Summary",
        "",
    ]
    rows, summaries = [], []
    for r in reports:
        for s in (r.summary if isinstance(r.summary, list) else [r.summary]):
            rows.append(summary_row(s))
            summaries.append(s)
    doc += [md_table(summary_row_header(), rows), ""]
    if DISCUSSION.is_file():
        text, missing = fill_discussion(DISCUSSION.read_text(encoding="utf-8").strip(), figures_from(summaries))
        if missing:
            print(f"discussion: {len(missing)} figure(s) not computed in this run: {', '.join(missing)}",
                  file=sys.stderr)
        doc += [text, ""]
    if COMMANDS.is_file():
        doc += [COMMANDS.read_text(encoding="utf-8").strip(), ""]
    doc += ["## sdypy-EMA defects found", "", _defects_section(), ""]
    for r in reports:
        doc += [f"## {r.name}: {r.title}", "", f"Source: {r.source}.", "", r.markdown, ""]
    for name, tb in failures:
        doc += [f"## {name}: FAILED", "", "```", tb.strip(), "```", ""]
    if KEY_SECTION.is_file():
        doc += [KEY_SECTION.read_text(encoding="utf-8").strip(), ""]
    write_text_atomic(out / "validation.md", "\n".join(doc))   # a run cut short leaves the previous page
    print(f"wrote {out / 'validation.md'} ({len(reports)} cases, {len(failures)} failed)", file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
