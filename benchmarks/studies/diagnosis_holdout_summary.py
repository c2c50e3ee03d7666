"""A summary of hold-out runs: per family the cases, how many were named, each miss with its truth and what was
said, and the diagnosis' CPU per case.

Reads results files written by the hold-out studies (``diagnosis_one_place.py run --write``,
``diagnosis_pairs_nulls_fleets.py run --write`` and ``run-fleets --write``: ``CASES[.LABEL].results.json``) and
prints one markdown table with a row per file and family, then the misses. A case is named when the study scored
it ``right``; a null is right when its verdict is ``none`` (a miss there is a false alarm); a fleet's row counts
its defective units (named with kind and place, no other local cause) and its good units given a local cause.

    python benchmarks/studies/diagnosis_holdout_summary.py benchmarks/studies/diagnosis_*_seed1206.results.json ...
    # --write: the summary replaces diagnosis_holdout_summary.md beside this script (with the command line)
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from benchmarks.results import add_write_option, recorded  # noqa: E402

#: this script's results file (``--write`` replaces it with the run's summary)
RESULTS = Path(__file__).with_name("diagnosis_holdout_summary.md")


def _truth(r: dict) -> str:
    """A case's truth in the study's words."""
    fam = r["family"]
    if fam == "null":
        return f"unchanged ({r.get('setup', 'points ' + ','.join(r.get('points') or []))})"
    if fam == "pair":
        return " + ".join(f"{d['family']} {d['place']} x{d['factor']}" for d in r["defects"])
    if fam == "attached_block":
        return f"block {r['mass_kg']} kg at {r['place']}"
    if fam == "section_change":
        return f"{r['place']} of another bar, w x{r['width_factor']} d x{r['depth_factor']}"
    return f"{fam} {r['place']} x{r['factor']}"


def _param(v: object) -> str:
    return f"{v:.3g}" if isinstance(v, float) else str(v)


def _said(verdict: str | None, named: list[dict]) -> str:
    """The verdict and the named causes with their scalar parameters."""
    causes = "; ".join(f"{c['effect']} " + ", ".join(f"{k}={_param(v)}" for k, v in c["parameters"].items()
                                                      if not isinstance(v, (list, dict)))
                       for c in named)
    return f"`{verdict or '-'}`" + (f": {causes}" if causes else "")


def _cpu(rs: list[dict]) -> str:
    cpu = [r.get("cpu_s", 0.0) + r.get("cpu_children_s", 0.0) for r in rs if "cpu_s" in r]
    return f"{np.median(cpu):.1f} / {max(cpu):.1f}" if cpu else "-"


def summary(files: list[Path]) -> str:
    """The markdown summary of the results ``files``: the table, then every miss."""
    rows = ["| results file | family | cases | named (right) | misses / false alarms | CPU per case s (median / largest) |",
            "|---|---|---|---|---|---|"]
    misses = []
    for f in files:
        results = json.loads(f.read_text())
        if results and "units" in results[0]:        # fleets: one row per fleet list
            units = [u for r in results for u in r["units"]]
            bad = [u for u in units if u["defect"] is not None]
            good = [u for u in units if u["defect"] is None]
            diag = sum(r["info"].get("diagnosis_cpu_seconds", 0.0) for r in results)
            n_diag = sum(r["info"].get("diagnosed", 0) for r in results)
            per = f"{diag / n_diag:.1f} per flagged unit (mean)" if n_diag else "-"
            wrong_good = [u for u in good if not u["right"]]
            rows.append(f"| {f.name} | fleet ({len(results)} fleets) | {len(bad)} defective, {len(good)} good | "
                        f"{sum(u['right'] for u in bad)}/{len(bad)} | {len(bad) - sum(u['right'] for u in bad)} "
                        f"missed; {len(wrong_good)} good units given a local cause | {per} |")
            for u in [u for u in bad if not u["right"]] + wrong_good:
                d = u["defect"]
                truth = "good unit" if d is None else f"{d['family']} {d['place']} x{d['factor']}"
                flag = "flagged" if u["flagged"] else "not flagged"
                misses.append(f"- {f.name} {u['fleet']} {u['name']}: {truth}, {flag} -> {_said(u['verdict'], u['named'])}")
            continue
        fams: dict[str, list[dict]] = {}
        for r in results:
            fams.setdefault(r["family"], []).append(r)
        for fam, rs in fams.items():
            wrong = [r for r in rs if not r["right"]]
            what = "false alarms" if fam == "null" else "misses"
            rows.append(f"| {f.name} | {fam} | {len(rs)} | {len(rs) - len(wrong)}/{len(rs)} | {len(wrong)} {what} | "
                        f"{_cpu(rs)} |")
            for r in wrong:
                misses.append(f"- {f.name} {r['name']}: {_truth(r)} -> {_said(r.get('verdict'), r.get('named') or [])}")
    return "\n".join(rows + ["", "Misses and false alarms:" if misses else "No misses and no false alarms.", *misses]) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", nargs="+", help="results files of hold-out runs (CASES[.LABEL].results.json)")
    add_write_option(ap, RESULTS)
    args = ap.parse_args()
    with recorded(RESULTS, args.write):
        print(summary([Path(p) for p in args.results]), end="")


if __name__ == "__main__":
    main()
