"""modelab_beam_roving_hammer: a beam, 9 hammer points, one accelerometer (driving point = file 4).

Source: GitHub alxhslm/ModeLAB (HEAD 4a27c982), ``Example/SignalCalc/ASCII0000{1..9}/Hxysv0000{1..9}.txt``
and ``setup.csv``, GPL-3.0. DataPhysics SignalCalc ASCII FRF exports (9 header lines, then
frequency Hz, Re, Im), accelerance (m/s^2)/N, 0..1000 Hz, df 0.01953 Hz (51 201 lines), read by the
project's importer :func:`acquisition.frf_importers_ascii.read_signalcalc_ascii` (``acquisition import
--points``, docs/validation.md).

Known truth used: the accelerometer sits at 0.5 m = hammer position 4, so FRF 4 is a driving point.
For a lightly damped (nearly normal-mode) structure its modal constants ``A_r = psi_r^2`` are real and
positive, so each residue ``R = A / (2 j omega_d)`` has phase -90 deg (receptance form; the fitter
reports residues of the FRF's own partial fractions, which are the same for every form).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from analysis.frf import FRFSet

from .case import compare
from .common import CaseReport, fmt, md_table

NAME = "modelab_beam_roving_hammer"
SOURCE = ("GitHub alxhslm/ModeLAB (HEAD 4a27c982), Example/SignalCalc/ASCII0000{1..9}/Hxysv0000{1..9}.txt "
          "and setup.csv, GPL-3.0")
HAMMER_Z_M = (0.1, 0.25, 0.375, 0.5, 0.65, 0.8, 0.925, 1.05, 1.2)
DRIVING = 3  # index of file 4
BAND = (65.0, 1000.0)


def read_signalcalc_ascii(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """One SignalCalc ASCII FRF export: (freq_hz, H complex), read by the project's importer."""
    from acquisition.frf_importers_ascii import read_signalcalc_ascii as read

    s = read(Path(path)).sets[0]
    return s.freq_hz, s.H[0, 0]


def load(data_dir: Path, band: tuple[float, float] | None = None) -> FRFSet:
    """The 9 FRFs as H[1 accelerometer, 9 hammer points, n] (accelerance, (m/s^2)/N)."""
    d = Path(data_dir) / NAME
    fs, Hs = [], []
    for k in range(1, 10):
        f, h = read_signalcalc_ascii(d / f"Hxysv0000{k}.txt")
        fs.append(f)
        Hs.append(h)
    f = fs[0]
    for k, g in enumerate(fs[1:], start=2):
        if g.shape != f.shape or not np.allclose(g, f):
            raise ValueError(f"file {k} has a different frequency axis")
    refs = tuple(f"beam:{k}:Z" for k in range(1, 10))
    frf = FRFSet(freq_hz=f, H=np.stack(Hs)[None, :, :], quantity="accelerance", outputs=("beam:4:Z",),
                 references=refs, unit="(m/s^2)/N", meta={"source": SOURCE, "hammer_z_m": HAMMER_Z_M})
    return frf.band(*band) if band else frf


def driving_point_phases(result) -> np.ndarray:
    """Phase (deg) of the driving-point residue of every mode (should be near -90)."""
    R = np.asarray(result.model.residues)[0, DRIVING]
    return np.degrees(np.angle(R))


def run(data_dir: Path, out_dir: Path) -> CaseReport:
    frf = load(data_dir)
    ours, peer, block, summary, plots = compare(NAME, frf, out_dir, band=BAND, pair=(0, DRIVING),
                                                plot_name=f"{NAME}.png", title=NAME)
    res = ours.result
    ph = driving_point_phases(res)
    psi = np.asarray(res.participation) if res.participation is not None else None
    rows = []
    for i in range(res.poles.size):
        shape = ""
        if psi is not None:
            s = psi[i] * np.exp(-1j * np.angle(psi[i][np.argmax(np.abs(psi[i]))]))
            shape = " ".join(f"{x:+.2f}" for x in s.real)
        rows.append([fmt(res.freq_hz[i], 6), fmt(100 * res.damping[i], 3), f"{ph[i]:.1f}", shape])
    md = [
        "Nine accelerance FRFs (one accelerometer at 0.5 m, hammer at 0.1..1.2 m), 51 201 lines with df = 0.0195 Hz "
        "and very light damping: a half-power bandwidth of 2 zeta f = 0.04 Hz at 100 Hz and zeta = 0.02 % spans "
        "two lines, so the peaks are barely resolved. The band 65..1000 Hz is `setup.csv`'s fMin..fMax. "
        "Loader: the project's importer (`acquisition import --points`, `acquisition.frf_importers_ascii`).",
        "",
        block,
        "",
        "Driving point (file 4) check: residue phase should be -90 deg for real (normal) modes; "
        "participation along the beam (largest entry = 1, hammer points 1..9):",
        "",
        md_table(["f [Hz]", "zeta [%]", "driving-point residue phase [deg]", "participation at z = 0.1..1.2 m"], rows),
    ]
    return CaseReport(NAME, "ModeLAB beam, roving hammer", SOURCE, "\n".join(md), summary, plots)
