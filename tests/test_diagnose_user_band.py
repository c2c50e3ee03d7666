"""``diagnose --band LO:HI``: every fit the diagnosis runs (the measured modes held against an FE model,
the automatic fit of a simulation given as FRFs) works in the user's band, so no message names a band
edge the user did not give (analysis.diagnosis.entry)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from acquisition.cli_capture import main as capture_main
from acquisition.cli_export import main as export_main

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """The README tour's recording (seed 1) and a second capture (seed 2) exported as UFF."""
    d = tmp_path_factory.mktemp("userband")
    for seed, name in ((1, "rec.h5"), (2, "sim.h5")):
        assert capture_main(["--device", f"sim://?seed={seed}", "--out", str(d / name), "--hits", "3",
                             "--points", "right:6:-X", "--auto", "-q"]) == 0
    assert export_main([str(d / "sim.h5"), "--uff", str(d / "sim.uff")]) == 0
    return {"rec": d / "rec.h5", "uff": d / "sim.uff", "frame": ROOT / "simulator" / "frame.toml"}


def _edges_named(text: str) -> list[float]:
    """Every band edge (Hz) a message names: 'band edge X Hz' and the progress line 'band A..B Hz'."""
    got = [float(x) for x in re.findall(r"band edge ([0-9.]+) Hz", text)]
    for a, b in re.findall(r"\bband ([0-9.]+)\.\.([0-9.]+) Hz", text):
        got += [float(a), float(b)]
    return got


@pytest.mark.parametrize("simulated", ["frame", "uff"])
def test_diagnose_names_no_band_edge_but_the_users(files, simulated, capsys) -> None:
    from analysis.cli_diagnose import main as diagnose_main

    capsys.readouterr()
    assert diagnose_main(["--measured", str(files["rec"]), "--simulated", str(files[simulated]),
                          "--band", "10:300", "--effects", "mains_hum,residual_modes"]) == 0
    got = capsys.readouterr()
    edges = _edges_named(got.err + got.out)
    assert edges, got.err                        # the fits' progress names their band
    df = 0.78125                                 # the capture's line spacing: an edge is the line nearest the user's
    assert all(abs(e - 10) <= df or abs(e - 300) <= df for e in edges), (edges, got.err)
