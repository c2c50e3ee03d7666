"""Every real dataset of docs/validation.md fitted over its whole recorded range with the default band, scored
against the analyst's key (:mod:`benchmarks.accuracy.validation.key`): accepted resonances fitted, spurious
poles, poles above the excitation, and whether ``success`` says what the key says (true exactly when every
accepted resonance is fitted and no pole is spurious). Prints a markdown table; ``--json`` writes the rows.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/studies/realdata_key.py [--data ../shared/data] [--only KEY]
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from analysis.pipeline import fit_auto  # noqa: E402
from benchmarks.accuracy.validation.datasets import DATASETS  # noqa: E402
from benchmarks.accuracy.validation.key import KEYS, score  # noqa: E402
from benchmarks.studies.study_args import data_folder, study_parser, table_head  # noqa: E402


def main() -> int:
    ap = study_parser(__doc__, data=True)
    ap.add_argument("--only", nargs="*", default=None, help="dataset keys to run (default: all)")
    ap.add_argument("--json", default=None, help="write the rows as JSON here")
    args = ap.parse_args()
    data = data_folder(args)
    if data is None:
        return 2
    table_head("dataset", "accepted fitted", "missed [Hz]", "spurious [Hz]", "doubtful/suspension [Hz]", "success",
               "key says", "problems", "fit s")
    rows = []
    for d in DATASETS:
        if args.only and d.key not in args.only:
            continue
        frf = d.load(data, **d.whole_range)
        t0 = time.perf_counter()
        res = fit_auto(frf)
        dt = time.perf_counter() - t0
        s = score(KEYS[d.key], res.freq_hz, res.success)
        s.update(key=d.key, poles=[round(float(x), 3) for x in sorted(res.freq_hz)], problems=list(res.problems),
                 time_s=dt)
        rows.append(s)
        print(f"| {d.key} | {s['fitted']} / {s['accepted']} | {', '.join(f'{x:.5g}' for x in s['missed']) or '-'} | "
              f"{', '.join(f'{x:.5g}' for x in s['spurious']) or '-'} | {', '.join(f'{x:.5g}' for x in s['ignored']) or '-'} | "
              f"{s['success']} | {s['success_expected']} | {len(res.problems)} | {dt:.1f} |", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1), encoding="utf-8")
    return 0 if all(r["honest"] and r["success_expected"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
