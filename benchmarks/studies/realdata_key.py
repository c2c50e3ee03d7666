"""Every real dataset of docs/validation.md fitted over its whole recorded range with the default band, scored
against the analyst's key (:mod:`benchmarks.accuracy.validation.key`): accepted resonances fitted, spurious
poles, poles above the excitation, and whether ``success`` says what the key says (true exactly when every
accepted resonance is fitted and no pole is spurious). Prints a markdown table (``--write``: the run's command
line and table to ``realdata_key.results.md`` beside the script); ``--json`` writes the rows;
``--markdown`` writes the section of docs/validation.md that shows the key's table
(``benchmarks/accuracy/validation/key_section.md``, which ``run_all`` puts at the end of the page).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/studies/realdata_key.py [--data ../shared/data] [--only KEY]
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/studies/realdata_key.py --markdown --write
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from analysis.atomic import write_text_atomic  # noqa: E402
from analysis.pipeline import fit_auto  # noqa: E402
from benchmarks.accuracy.validation.datasets import DATASETS, RealDataset  # noqa: E402
from benchmarks.accuracy.validation.key import KEYS, score  # noqa: E402
from benchmarks.results import add_write_option, recorded  # noqa: E402
from benchmarks.studies.study_args import data_folder, study_parser, table_head  # noqa: E402

RESULTS = Path(__file__).with_name("realdata_key.results.md")
#: the section of docs/validation.md this study writes with ``--markdown`` (run_all puts it at the page's end)
KEY_SECTION = ROOT / "benchmarks" / "accuracy" / "validation" / "key_section.md"

#: the section's columns: one row per dataset of the key
SECTION_COLUMNS = ("dataset", "accepted fitted", "missed [Hz]", "spurious [Hz]", "success", "the key says")

SECTION_HEAD = """## The automatic fit against an analyst's key

Each dataset above fitted by `fit_auto` over its whole recorded range with the default band, and scored
against an analyst's key written from the evidence (`benchmarks/accuracy/validation/key.py`: the
accepted resonances, the poles that are spurious, what is doubtful or a suspension mode, and where the
excitation ends; the evidence for each is in that module's docstring). A fit meets the key when every
accepted resonance has a pole, no pole is spurious (named as such, outside the excitation, or where the
key has no resonance), and `success` is true exactly then. Poles in doubtful, suspension or not-keyed
ranges count neither way. Run with
`OPENBLAS_NUM_THREADS=1 python benchmarks/studies/realdata_key.py --data ../shared/data` (`--markdown`
writes this section):"""

#: the text after the table; ``{unesp_54_*}`` are the bolted beam's 54 Hz pole as this run fitted it
SECTION_TAIL = """The bolted beam's {unesp_54_f:.4g} Hz resonance is fitted with a pole of its own: one accelerometer shows it as a
peak between two antiresonances, the others as a dip on the same line, and one pole shared by the four
FRFs, 60 times sharper than the beam's other modes, fits all of them (a pole started at the damping of the
beam's other modes does not: the fit then tries it again from the width of the peak's top). Its damping from the
whole-band fit is poorly determined ({unesp_54_zeta:.2g} +- {unesp_54_zeta_std:.2g} %). Where it stops working: the pyFRF hammer data's
weak modes of 700-1700 Hz (a shoulder, a 6.6 dB CMIF peak) are found over the whole range only because
the model misses the data there by more than the data's level; fit such a structure in bands of a few
modes. The bolted beam's 478 Hz mode is left out at both drive levels (the coherence does not carry its
top at 0.05 V, and at 0.30 V its margin would run past the data's end)."""


def key_row(d: RealDataset, data: Path) -> dict[str, Any]:
    """Dataset ``d`` (from the shared data folder ``data``) fitted over its whole range with the default band
    and scored against its key (:func:`benchmarks.accuracy.validation.key.score`), with the fit's ``poles``,
    ``zeta_percent`` and ``zeta_std_percent`` (sorted by frequency), ``problems`` and ``time_s``."""
    frf = d.load(data, **d.whole_range)
    t0 = time.perf_counter()
    res = fit_auto(frf)
    dt = time.perf_counter() - t0
    order = np.argsort(res.lsfd.freq_hz)
    s = score(KEYS[d.key], res.freq_hz, res.success)
    s.update(key=d.key, poles=[round(float(x), 3) for x in res.lsfd.freq_hz[order]],
             zeta_percent=[float(100 * x) for x in res.lsfd.damping[order]],
             zeta_std_percent=[float(100 * x) for x in res.lsfd.damping_std[order]],
             problems=list(res.problems), time_s=dt)
    return s


def _hz(values: list[float]) -> str:
    return ", ".join(f"{x:.5g}" for x in values) or "-"


def section_row(s: dict[str, Any]) -> str:
    """The section's table line of one scored dataset (:func:`key_row`)."""
    return (f"| {s['key']} | {s['fitted']} / {s['accepted']} | {_hz(s['missed'])} | {_hz(s['spurious'])} | "
            f"{s['success']} | {s['success_expected']} |")


def markdown_section(rows: list[dict[str, Any]]) -> str:
    """The section of docs/validation.md from every dataset's scored row (:func:`key_row`, all of
    :data:`DATASETS`, the bolted beam among them): heading, what the key is, the table, where it stops."""
    unesp = next(r for r in rows if r["key"] == "unesp_boltedbeam")
    k = int(np.argmin(np.abs(np.asarray(unesp["poles"]) - 54.0)))
    table = ["| " + " | ".join(SECTION_COLUMNS) + " |", "|" + "---|" * len(SECTION_COLUMNS),
             *(section_row(r) for r in rows)]
    tail = SECTION_TAIL.format(unesp_54_f=unesp["poles"][k], unesp_54_zeta=unesp["zeta_percent"][k],
                               unesp_54_zeta_std=unesp["zeta_std_percent"][k])
    return "\n\n".join([SECTION_HEAD, "\n".join(table), tail]) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = study_parser(__doc__, data=True)
    ap.add_argument("--only", nargs="*", default=None, help="dataset keys to run (default: all)")
    ap.add_argument("--json", default=None, help="write the rows as JSON here")
    ap.add_argument("--markdown", action="store_true",
                    help=f"write the section of docs/validation.md to {KEY_SECTION.relative_to(ROOT)} (every dataset)")
    add_write_option(ap, RESULTS)
    args = ap.parse_args(argv)
    if args.markdown and args.only:
        ap.error("--markdown writes the whole table: leave out --only")
    data = data_folder(args)
    if data is None:
        return 2
    with recorded(RESULTS, args.write, argv):
        rows = _run(args, data)
    if args.markdown:
        write_text_atomic(KEY_SECTION, markdown_section(rows))
        print(f"wrote {KEY_SECTION}", file=sys.stderr)
    return 0 if all(r["honest"] and r["success_expected"] for r in rows) else 1


def _run(args: Any, data: Path) -> list[dict[str, Any]]:
    """Every dataset (or those of ``--only``) scored, its table line printed; ``--json`` writes the rows."""
    table_head("dataset", "accepted fitted", "missed [Hz]", "spurious [Hz]", "doubtful/suspension [Hz]", "success",
               "key says", "problems", "fit s")
    rows = []
    for d in DATASETS:
        if args.only and d.key not in args.only:
            continue
        s = key_row(d, data)
        rows.append(s)
        print(f"| {d.key} | {s['fitted']} / {s['accepted']} | {_hz(s['missed'])} | {_hz(s['spurious'])} | "
              f"{_hz(s['ignored'])} | {s['success']} | {s['success_expected']} | {len(s['problems'])} | "
              f"{s['time_s']:.1f} |", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1), encoding="utf-8")
    return rows


if __name__ == "__main__":
    sys.exit(main())
