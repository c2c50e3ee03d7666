"""pyuff_3frf: three accelerance FRFs (response node 1, references 1-3), read from UFF58.

Source: GitHub ladisk/pyuff, ``data/measurement.uff`` (commit e2089be1) and ``data/meas_point_*.txt``
(HEAD 44a12caa), MIT. Read with the project's :func:`analysis.uff.read_uff58`; the text copies are
used to check the reader.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from analysis.frf import FRFSet
from analysis.uff import read_uff58

from .case import compare
from .common import CaseReport

NAME = "pyuff_3frf"
SOURCE = ("GitHub ladisk/pyuff, data/measurement.uff (commit e2089be1) and data/meas_point_{1,2,3}.txt "
          "(HEAD 44a12caa), MIT")
BAND = (20.0, 1000.0)


def load(data_dir: Path) -> FRFSet:
    """The three FRFs from the UFF file (H[1, 3, 1001], 0..1000 Hz, accelerance)."""
    return read_uff58(Path(data_dir) / NAME / "measurement.uff")


def load_text(data_dir: Path) -> np.ndarray:
    """The same FRFs from the text files, (3, 1001) complex."""
    return np.stack([np.genfromtxt(Path(data_dir) / NAME / f"meas_point_{k}.txt", dtype=complex)
                     for k in (1, 2, 3)])


def run(data_dir: Path, out_dir: Path) -> CaseReport:
    frf = load(data_dir)
    txt = load_text(data_dir)
    d = np.abs(frf.H[0] - txt)
    same = d[:, 1:].max() / np.abs(txt[:, 1:]).max()
    ours, peer, block, summary, plots = compare(NAME, frf, out_dir, band=BAND, plot_name=f"{NAME}.png",
                                                title=NAME)
    md = [
        f"Three accelerance FRFs (response node 1 X, references 1-3), 0..1000 Hz, df 1 Hz, read through "
        f"`analysis.uff.read_uff58`. Reader check: UFF vs text copies, max |difference| / max |H| = {same:.2g} above "
        f"DC (the UFF file itself holds 0 at DC for FRF 1, where the text has {abs(txt[0, 0]):.3g}). The band starts at 20 Hz: "
        f"with df = 1 Hz the lowest lines carry the rigid-body/IEPE roll-off.",
        "",
        block,
    ]
    return CaseReport(NAME, "pyuff 3 FRFs (UFF58)", SOURCE, "\n".join(md), summary, plots)
