"""The linearity check pairs the two levels' modes by frequency and MAC before any verdict: two
different structures (or other points) get one line and exit 1, never "linear within the noise" or
"nonlinear"; ``--z`` must be a finite number of standard deviations > 0."""
from __future__ import annotations

import json

import numpy as np
import pytest
from quality_support import level_hits

from analysis.linearity import LevelsDoNotPair, check_levels_pair, compare_levels, level_frfsets
from simulator.config import FrameConfig

BAND = (5.0, 220.0)


@pytest.fixture(scope="module")
def frames():
    """The default frame's soft and hard hits, and the hard hits of two other frames: a lighter one
    (every mode 25 % higher) and one with a shorter beam (other modes, other shapes)."""
    levels, sets = level_frfsets(level_hits(None, 1))
    others = {}
    for name, over in (("lighter", {"material": {"density_kg_m3": 5000.0}}),
                       ("shorter beam", {"components": {"top": {"end_m": [1.2, 0.0, 0.668]}}})):
        lv, s = level_frfsets(level_hits(FrameConfig.from_dict(over), 2))
        others[name] = (lv[1], s[1])
    return levels, sets, others


@pytest.mark.parametrize("other", ["lighter", "shorter beam"])
def test_two_different_structures_get_no_linearity_verdict(frames, other):
    levels, sets, others = frames
    level_b, set_b = others[other]
    with pytest.raises(LevelsDoNotPair) as err:
        compare_levels([sets[0], set_b], [levels[0], level_b], band=BAND)
    msg = str(err.value)
    assert msg.startswith("the modes of the two measurements do not pair: ")
    n_pairs, n_low = (int(x) for x in msg.split(": ", 1)[1].split(" resonance")[0].split(" of the "))
    assert n_low >= 5 and n_pairs < n_low / 2
    assert "in 5..220 Hz" in msg and "MAC >= 0.9" in msg and "\n" not in msg


def test_one_structure_at_two_levels_pairs(frames):
    levels, sets, _ = frames
    assert check_levels_pair(sets[0], sets[1], BAND, levels) >= 6
    assert compare_levels(sets, levels, band=BAND).verdict == "linear"


def test_levels_of_other_points_are_refused(frames):
    levels, sets, _ = frames
    high = sets[1].select(outputs=sets[1].outputs[:2])
    with pytest.raises(LevelsDoNotPair, match="the levels hold different FRFs"):
        compare_levels([sets[0], high], levels, band=BAND)


def test_cli_says_the_modes_do_not_pair_in_one_line_with_exit_1(frames, tmp_path, capsys):
    from analysis.cli_linearity import main
    from analysis.uff import write_uff58

    levels, sets, others = frames
    low, high = tmp_path / "low.uff", tmp_path / "other.uff"
    write_uff58(low, sets[0])
    write_uff58(high, others["lighter"][1])
    out = tmp_path / "lin.json"
    assert main([str(low), str(high), "--levels", f"{levels[0]},{others['lighter'][0]}", "--band", "5:220",
                 "--json", str(out)]) == 1
    captured = capsys.readouterr()
    assert captured.err.startswith("analysis linearity: the modes of the two measurements do not pair")
    assert captured.err.count("\n") == 1 and "verdict" not in captured.out and not out.exists()


@pytest.mark.parametrize("z", ["nan", "0", "-1", "inf"])
def test_z_must_be_finite_and_positive(frames, tmp_path, capsys, z):
    from analysis.cli_linearity import main
    from analysis.uff import write_uff58

    levels, sets, _ = frames
    paths = [tmp_path / "a.uff", tmp_path / "b.uff"]
    for p, s in zip(paths, sets):
        write_uff58(p, s)
    assert main([str(paths[0]), str(paths[1]), "--levels", f"{levels[0]},{levels[1]}", f"--z={z}"]) == 2
    err = capsys.readouterr().err
    assert f"argument --z: {z} must be a finite number of standard deviations > 0" in err
    with pytest.raises(ValueError, match="z must be a finite number of standard deviations > 0"):
        compare_levels(sets, levels, band=BAND, z=float(z))


def test_json_of_a_pairing_comparison_is_unchanged(frames, tmp_path):
    from analysis.cli_linearity import main
    from analysis.uff import write_uff58

    levels, sets, _ = frames
    paths = [tmp_path / "a.uff", tmp_path / "b.uff"]
    for p, s in zip(paths, sets):
        write_uff58(p, s)
    out = tmp_path / "lin.json"
    assert main([str(paths[0]), str(paths[1]), "--levels", f"{levels[0]},{levels[1]}", "--band", "5:220",
                 "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["verdict"] == "linear" and np.allclose(doc["levels"], sorted(levels))
