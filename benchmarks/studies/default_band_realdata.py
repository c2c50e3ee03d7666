"""The automatic band on every real dataset of docs/validation.md: what bounds it, and
whether the automatic fit keeps every pole inside it.

For each dataset the FRFs are loaded over their whole recorded range (no hand-picked band), the
default band is taken from the data (:func:`analysis.bands.default_band`: the analyser's flat band
fs/2.56 when the sample rate is known, the hammer's excitation band when force spectra are recorded,
the coherence when present) and :func:`analysis.pipeline.fit_auto` runs with it. Prints a markdown
table: the one of docs/validation.md, section "The automatic band on real data", kept in
benchmarks/accuracy/validation/discussion.md (paste the run's table there whole; a test re-runs the bolted
beam's row and compares every cell but the fit time).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/studies/default_band_realdata.py [--data ../shared/data]
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from analysis.bands import default_band, upper_limits  # noqa: E402
from analysis.pipeline import fit_auto  # noqa: E402
from benchmarks.accuracy.validation.datasets import DATASETS, RealDataset  # noqa: E402
from benchmarks.studies.study_args import data_folder, study_parser, table_head  # noqa: E402

#: the table's columns (the last, the fit's wall time, differs from run to run)
COLUMNS = ("dataset", "lines (range Hz)", "upper limits from the data [Hz]", "default band [Hz]", "modes",
           "poles [Hz]", "all inside", "success", "fit s")


def band_row(d: RealDataset, data: Path) -> tuple[list[str], bool]:
    """The table's row of dataset ``d`` (its cells, as printed) from the shared data folder ``data``, and
    whether every fitted pole lies inside the default band."""
    frf = d.load(data, **d.whole_range)
    f = frf.freq_hz
    lo, hi = default_band(frf)
    t0 = time.perf_counter()
    res = fit_auto(frf)
    dt = time.perf_counter() - t0
    fz = np.sort(res.lsfd.freq_hz)
    inside = bool(np.all((fz >= lo) & (fz <= hi)))
    lims = ", ".join(f"{k} {v:.4g}" for k, v in upper_limits(frf).items())
    poles = f"{fz[0]:.4g} .. {fz[-1]:.4g}" if fz.size else "-"
    return [d.label, f"{f.size} ({f[0]:.4g}-{f[-1]:.4g})", lims, f"{lo:.4g}-{hi:.4g}", str(fz.size), poles,
            "yes" if inside else "NO", str(res.success), f"{dt:.2f}"], inside


def main() -> int:
    ap = study_parser(__doc__, data=True)
    args = ap.parse_args()
    data = data_folder(args)
    if data is None:
        return 2
    table_head(*COLUMNS)
    bad = 0
    for d in DATASETS:
        try:
            cells, inside = band_row(d, data)
        except (OSError, ValueError) as exc:
            print(f"| {d.label} | not read: {exc} |")
            continue
        bad += not inside
        print("| " + " | ".join(cells) + " |", flush=True)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
