"""The ULiege plane's 74-point roving-hammer test through the command line, as the lab's files would come in.

The shared data hold 3 of the second lab's 79 DataPhysics SignalCalc exports (``sec_lab_original/DPsv*.mat``)
and all 79 packed in ``sec_lab_all_H1_coh_time.npz`` (the analyser's H1 and coherence, the last hit's raw and
windowed time blocks). :func:`write_lab_files` writes the 74 impact files of the pack back out in the lab's own
layout (the variables of the DPsv files the pack holds: channel table, ``X{k}``/``W{k}`` time blocks
[t s, value], ``H1_{k}`` [f Hz, H1 g/N], ``C1_{k}`` [f Hz, coherence], ``DP_Info`` naming each; the cross and
auto spectra the pack does not hold are left out) into a folder of the caller's (never the shared data or the
repository), with the point map ``points.csv`` from ``node_shock.csv``'s order (files 1-28, 31-58, 61-78 are its
74 rows; the first 68 struck in z, the last 6 in x; the accelerometers' places are undocumented:
``acc:1..3:Z``). For the three files the shared data hold, the written file equals the lab's in every variable
written. Then ``main`` runs the two commands a user runs on them and prints their output::

    python -m acquisition import --points DIR/points.csv --analyser-exp-window 32.9% --out DIR/plane74.h5
    python -m analysis fit DIR/plane74.h5 --json DIR/plane74-fit.json

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/studies/uliege_roving_files.py [--data ../shared/data]
[--out DIR]`` (default: a new temporary folder, kept and named).
Source: GitHub VictorRenkin/MECA0062-1_vibration_testing (University of Liege, MECA0062); no licence in the
source: internal validation only.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.accuracy.validation.uliege_plane import IMPACT_FILES  # noqa: E402
from benchmarks.studies.study_args import data_folder, study_parser  # noqa: E402

__all__ = ["write_lab_files", "point_label", "FOLDER", "EXP_WINDOW_OPTION"]

FOLDER = "uliege_meca0062_plane_hammer"
#: the analyser's exponential window, as docs/validation.md states it to ``acquisition import``
EXP_WINDOW_OPTION = "32.9%"
#: the rows of node_shock.csv struck in z (the rest in x)
Z_ROWS = 68
OUTPUTS = ("acc:1:Z", "acc:2:Z", "acc:3:Z")


def point_label(row: int) -> str:
    """The reference point of ``node_shock.csv``'s row ``row`` (1-based): ``plane:ROW:Z`` for the first
    ``Z_ROWS`` rows, ``plane:ROW:X`` after."""
    return f"plane:{row}:{'Z' if row <= Z_ROWS else 'X'}"


def _dp_info(template: np.ndarray, written: set[str]) -> np.ndarray:
    """The template's ``DP_Info`` (triplets: 'Signal NAME', format and unit, range) kept for the signals written."""
    t = [str(x) for x in np.ravel(template)]
    keep = [t[i:i + 3] for i in range(0, len(t) - 2, 3) if t[i].split(" ", 1)[-1] in written]
    return np.array([x for triple in keep for x in triple])


def write_lab_files(data_dir: Path, out_dir: Path) -> Path:
    """Write the 74 impact files of the second lab's pack as ``DPsv#####.mat`` (the lab's layout, see the module
    docstring) into ``out_dir`` (created; must not be inside ``data_dir``) and the map ``points.csv`` (file,
    reference, outputs); returns the map's path."""
    import scipy.io

    src = Path(data_dir) / FOLDER
    out = Path(out_dir)
    if out.resolve().is_relative_to(Path(data_dir).resolve()):
        raise ValueError(f"{out} lies inside the shared data {data_dir}; write the files elsewhere")
    out.mkdir(parents=True, exist_ok=True)
    template = scipy.io.loadmat(str(sorted((src / "sec_lab_original").glob("DPsv*.mat"))[0]))
    with np.load(src / "sec_lab_all_H1_coh_time.npz") as z:   # each item read once (an npz reads it on every access)
        d = {k: z[k] for k in ("file_id", "freq_hz", "t_s", "x_last_block", "w_last_block", "H1_g_per_N", "coherence",
                               "sensitivity_mV_per_EU")}
    ids = [int(x) for x in d["file_id"]]
    f, t = np.asarray(d["freq_hz"], float), np.asarray(d["t_s"], float)
    n_ch = int(d["x_last_block"].shape[1])
    table = {k: template[k] for k in ("ChanNum", "Sensitivity", "SerialNo", "Unit", "ChanName")}
    table["Sensitivity"] = np.asarray(d["sensitivity_mV_per_EU"], float).reshape(-1, 1)
    rows = ["file,reference,outputs"]
    for row, fid in enumerate(IMPACT_FILES, start=1):
        i = ids.index(fid)
        m: dict[str, np.ndarray] = dict(table)
        for k in range(1, n_ch + 1):
            m[f"X{k}"] = np.column_stack([t, d["x_last_block"][i, k - 1]])
            m[f"W{k}"] = np.column_stack([t, d["w_last_block"][i, k - 1]])
        for k in range(2, n_ch + 1):
            m[f"H1_{k}"] = np.column_stack([f.astype(complex), d["H1_g_per_N"][i, k - 2]])
            m[f"C1_{k}"] = np.column_stack([f, np.asarray(d["coherence"][i, k - 2], float)])
        m["DP_Info"] = _dp_info(template["DP_Info"], set(m))
        path = out / f"DPsv{fid:05d}.mat"
        scipy.io.savemat(str(path), m)
        rows.append(f"{path},{point_label(row)},{';'.join(OUTPUTS)}")
    points = out / "points.csv"
    points.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return points


def _run(args: list[str]) -> int:
    """Run ``python -m ...`` with ``args`` from the project root, print the command, its output and its time."""
    print("$ python -m " + " ".join(args), flush=True)
    t0 = time.perf_counter()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    p = subprocess.run([sys.executable, "-m", *args], cwd=ROOT, env=env, capture_output=True, text=True, check=False)
    for line in (p.stdout + p.stderr).splitlines():
        print("    " + line)
    print(f"    (exit {p.returncode}, {time.perf_counter() - t0:.1f} s)", flush=True)
    return p.returncode


def main() -> int:
    ap = study_parser(__doc__, data=True)
    ap.add_argument("--out", default=None, help="folder for the written files (default: a new temporary folder)")
    args = ap.parse_args()
    data = data_folder(args)
    if data is None:
        return 2
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="uliege74-"))
    t0 = time.perf_counter()
    points = write_lab_files(data, out)
    print(f"wrote {len(IMPACT_FILES)} files and {points} in {time.perf_counter() - t0:.1f} s", flush=True)
    rec = out / "plane74.h5"
    rc = _run(["acquisition", "import", "--points", str(points), "--analyser-exp-window", EXP_WINDOW_OPTION,
               "--out", str(rec)])
    if rc:
        return rc
    return _run(["analysis", "fit", str(rec), "--json", str(out / "plane74-fit.json")])


if __name__ == "__main__":
    sys.exit(main())
