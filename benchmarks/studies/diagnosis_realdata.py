"""Run the diagnosis on real measured data (docs/diagnosis-realdata.md, parts 2 and 3).

* ``unesp``: UNESP BERT bolted beam, random excitation at 0.05 V and 0.30 V (H1, 54 averages, four
  accelerometers per shaker voltage, g/V). The low level plays the simulation, the high level the
  measurement: the diagnosis names what changes with the drive level (a bolted joint's amplitude
  nonlinearity shows as softening and extra damping).
* ``uliege``: the ULiege MECA0062 plane (analyser H1 and coherence, g/N, exponential window on the
  responses) against the Samcef FE mode shapes at the impact points, see the function's docstring.

The data are converted to UFF 58 files in a temporary folder and ``python -m analysis diagnose`` is
run on them (the real command-line path); reports go to ``docs/diagnosis/diagnosis_realdata_<name>/``.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/studies/diagnosis_realdata.py unesp [--band 10:300]
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from analysis.cli_diagnose import main as diagnose_main  # noqa: E402
from analysis.frf import FRFSet  # noqa: E402
from analysis.mac import mac_matrix  # noqa: E402
from analysis.uff import write_uff58  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # the repository, for benchmarks.results
from benchmarks.results import add_write_option, recorded  # noqa: E402

#: this study's results file (``--write`` replaces it with the run's figures)
RESULTS = Path(__file__).with_name("diagnosis_realdata.md")
DATA = ROOT.parent / "shared" / "data"


def unesp_frfset(level: str) -> FRFSet:
    """Accelerometer FRFs (g/V) and coherence of one random-excitation level ("0p05" or "0p30"), read by the
    validation loader (the coherence matched to each FRF by its channel names), labelled for the UFF files."""
    import sys
    from dataclasses import replace

    sys.path.insert(0, str(ROOT))
    from benchmarks.accuracy.validation.unesp_boltedbeam import load

    frf = load(DATA, level)
    return replace(frf, outputs=tuple(f"n:{i + 1}:X" for i in range(len(frf.outputs))), references=("n:100:-X",),
                   meta={"averages": 54, "source": f"UNESP BERT Rand {level}"})


def run_unesp(band: str, out: Path) -> int:
    lo, hi = unesp_frfset("0p05"), unesp_frfset("0p30")
    with tempfile.TemporaryDirectory() as tmp:
        m, s = Path(tmp) / "rand_0p30.uff", Path(tmp) / "rand_0p05.uff"
        write_uff58(m, hi, overwrite=True)
        write_uff58(s, lo, overwrite=True)
        # the report folder holds diagnosis.json beside report.md and the plots
        return diagnose_main(["--measured", str(m), "--simulated", str(s), "--report", str(out), "--band", band])


def uliege_frfset() -> tuple[FRFSet, np.ndarray]:
    """Second-lab H1 (m/s^2)/N: outputs the three accelerometers, references the 68 z impacts; and the
    FE mode shapes uZ (68, 13) at those impact nodes (Samcef; frequencies not in the source)."""
    import csv

    d = DATA / "uliege_meca0062_plane_hammer"
    z = np.load(d / "sec_lab_all_H1_coh_time.npz")
    files = [i for i in range(79) if i not in (0, 29, 30, 59, 60)][:68]     # the z impacts, in node order
    H = np.transpose(z["H1_g_per_N"][files], (1, 0, 2))[..., 1:] * 9.80665
    C = np.transpose(z["coherence"][files], (1, 0, 2))[..., 1:]
    frf = FRFSet(freq_hz=z["freq_hz"][1:], H=H, coherence=C, quantity="accelerance",
                 outputs=[f"acc:{k + 1}:Z" for k in range(3)], references=[f"p:{i}:Z" for i in range(68)],
                 unit="(m/s^2)/N", meta={"source": "ULiege MECA0062 second lab"})
    rows = list(csv.DictReader(open(d / "samcef_fe_modeshapes_at_impact_nodes.csv")))
    n_modes = max(int(r["fe_mode"]) for r in rows)
    phi = np.zeros((68, n_modes))
    for r in rows:
        i = int(r["node_index"])
        if i < 68:
            phi[i, int(r["fe_mode"]) - 1] = float(r["uZ"])
    return frf, phi


def run_uliege(band: str, out: Path) -> int:
    """What can be compared without FE frequencies or accelerometer positions: the measured mode
    shapes over the 68 z impact points (LSFD residues, roving hammer) against the FE shapes (MAC),
    per accelerometer; a MAC matrix plot. No effect can be fitted (no simulation at the measured
    points), see docs/diagnosis-realdata.md."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from analysis.inputs import parse_band_text
    from analysis.pipeline import fit_auto

    frf, phi = uliege_frfset()
    lo, hi = parse_band_text(band)
    lines = []
    best = None
    for o in frf.outputs:
        r, _ = fit_auto(frf.select([o]).band(lo, hi))
        R = r.model.residues[0]
        mac = mac_matrix(R, phi.astype(complex))
        lines.append(f"accelerometer {o}: measured modes (Hz) and best FE mode by MAC")
        for m in range(R.shape[1]):
            j = int(np.argmax(mac[m]))
            second = np.sort(mac[m])[-2]
            lines.append(f"  {r.freq_hz[m]:7.2f} Hz  zeta {100 * r.damping[m]:.2f} %  -> FE mode {j + 1:2d}  "
                         f"MAC {mac[m, j]:.2f} (next {second:.2f})")
        if best is None or R.shape[1] > best[1].shape[0]:
            best = (o, mac, r.freq_hz)
    text = "\n".join(lines)
    print(text)
    (out / "mac.txt").write_text(text + "\n")
    o, mac, fm = best
    fig = Figure(figsize=(7, 4.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    im = ax.imshow(mac, vmin=0, vmax=1, cmap="viridis", aspect="auto")
    ax.set_yticks(range(len(fm)))
    ax.set_yticklabels([f"{x:.1f}" for x in fm], fontsize=7)
    ax.set_xticks(range(mac.shape[1]))
    ax.set_xticklabels([str(j + 1) for j in range(mac.shape[1])], fontsize=7)
    ax.set_xlabel("FE mode (Samcef)")
    ax.set_ylabel(f"measured mode (Hz), {o}")
    fig.colorbar(im, ax=ax, label="MAC")
    fig.tight_layout()
    fig.savefig(out / "mac.png", dpi=110)
    return 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", choices=("unesp", "uliege"))
    ap.add_argument("--band", default=None)
    add_write_option(ap, RESULTS)
    args = ap.parse_args()
    with recorded(RESULTS, args.write):
        _run(args)


def _run(args: argparse.Namespace) -> None:
    """The run itself (what :func:`main` records with ``--write``)."""
    out = ROOT / "docs" / "diagnosis" / f"diagnosis_realdata_{args.case}"
    out.mkdir(parents=True, exist_ok=True)
    if args.case == "unesp":
        raise SystemExit(run_unesp(args.band or "10:300", out))
    raise SystemExit(run_uliege(args.band or "3:200", out))


if __name__ == "__main__":
    main()
