"""The stabilization of a wide band (analysis.stabilization, ``wide_band``): the README's
``stabilization rec.h5 --png stab.png --max-order 30`` on the tour's capture (band 12.5-1102 Hz, the
frame's weak low modes beside strong high ones) shows the low modes as stable poles."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from acquisition.cli_capture import main as capture_main

#: the simulated frame's modes in the band that the capture at right:6:-X shows (python -m simulator modes)
LOW_MODES_HZ = (12.909, 35.144, 50.404, 81.683)


@pytest.fixture(scope="module")
def rec(tmp_path_factory) -> Path:
    """The README tour's recording: one point, 5 hits, simulated frame (seed 1)."""
    path = tmp_path_factory.mktemp("wide") / "rec.h5"
    assert capture_main(["--device", "sim://?seed=1", "--out", str(path), "--hits", "5", "--auto", "-q"]) == 0
    return path


def _listing(out: str) -> list[tuple[float, float, int]]:
    rows = []
    for ln in out.splitlines()[2:]:
        parts = ln.split()
        if len(parts) == 4 and parts[0].isdigit():
            rows.append((float(parts[1]), float(parts[2]), int(parts[3])))
    return rows


def test_the_readme_stabilization_shows_the_low_modes_as_stable_poles(rec, tmp_path, capsys) -> None:
    from analysis.cli_stabilization import main as stab_main

    assert stab_main([str(rec), "--png", str(tmp_path / "s.png"), "--max-order", "30"]) == 0
    got = capsys.readouterr()
    lines = got.out.splitlines()
    assert lines[0].startswith("stabilization (lscf) in 12.5..1102")
    assert lines[1].split() == ["pole", "f", "[Hz]", "zeta", "[%]", "orders"]   # every column headed
    rows = _listing(got.out)
    for f_true in LOW_MODES_HZ:
        near = [r for r in rows if abs(r[0] - f_true) < 0.01 * f_true]
        assert len(near) == 1, (f_true, rows)
        assert near[0][2] >= 5, (f_true, near)          # stable over several orders, not one lucky order
    # nothing the data show below 100 Hz is left without a pole, and no spurious pole there
    assert not any("have no stable pole" in ln and "35." in ln for ln in got.err.splitlines()), got.err
    assert len([r for r in rows if r[0] < 100]) == len(LOW_MODES_HZ), rows


def test_the_cuts_of_a_wide_band_fall_between_resonances(rec) -> None:
    from analysis.inputs import load_input
    from analysis.lscf import prepare_band
    from analysis.pipeline import default_band
    from analysis.stabilization import MAX_BAND_RATIO, sub_band_cuts

    frf = load_input(str(rec))
    bd = prepare_band(frf, default_band(frf))
    cuts = sub_band_cuts(bd)
    edges = [bd.band[0], *cuts, bd.band[1]]
    assert len(cuts) == 2
    assert all(b / a <= MAX_BAND_RATIO * 1.25 ** 2 for a, b in zip(edges[:-1], edges[1:]))
    true = np.array([12.909, 35.144, 50.404, 81.683, 128.198, 159.974, 161.027, 198.752, 283.436])
    for c in cuts:
        assert np.min(np.abs(true - c) / true) > 0.05, (c, cuts)   # off every resonance
    assert sub_band_cuts(prepare_band(frf, (100.0, 700.0))) == []   # a band of ratio 7: one band


def test_a_wide_band_is_taken_in_sub_bands_only_when_asked(rec) -> None:
    """The library default (fit_auto's starting poles) is the one-band LSCF; wide_band=True finds the weak
    low modes that one model of the whole band leaves out."""
    from analysis.inputs import load_input
    from analysis.modal import natural_freq_hz
    from analysis.pipeline import default_band
    from analysis.selection import select_clusters
    from analysis.stabilization import stabilization

    frf = load_input(str(rec))
    found = {}
    for wide in (False, True):
        st = stabilization(frf, 30, method="lscf", band=default_band(frf), wide_band=wide)
        f = np.array([natural_freq_hz(c.pole) for c in select_clusters(st)])
        found[wide] = [bool(np.any(np.abs(f - t) < 0.01 * t)) for t in LOW_MODES_HZ]
    assert found[True] == [True] * 4
    assert found[False] != [True] * 4
