"""Reciprocity and driving-point checks on simulated roving-hammer tests (the frame's FE model through the
stand, sensor noise), and the linearity check on hits at two force levels."""
from __future__ import annotations

from dataclasses import replace

import pytest
from quality_support import SENSORS, roving_test

from analysis.driving_point import check_driving_point, driving_points
from analysis.quality import quality_checks, quality_lines
from analysis.reciprocity import reciprocity, same_dof
from simulator.stand import TestStand


@pytest.fixture(scope="module")
def clean():
    return roving_test(TestStand(seed=2))


def test_same_dof_sign():
    assert same_dof("right:6:-X", "right:6:X") == -1
    assert same_dof("right:6:X", "right:6:X") == 1
    assert same_dof("right:6:X", "right:6:Y") == 0 and same_dof("bad", "right:6:X") == 0


def test_reciprocal_structure_is_within_the_noise(clean):
    r = reciprocity(clean)
    assert len(r.pairs) == 3 and r.verdict == "reciprocal" and r.suspects == ()
    for p in r.pairs:
        used = [x for x, n in zip(p.r, p.lines) if n >= 10]
        assert used and max(used) < 3.0
    assert all(abs(c - 1) < 0.01 for c in r.calibration.values())


def test_a_sensor_ten_percent_off_is_named():
    frf = roving_test(TestStand(seed=5), gain={"top:2:Z": 1.1})
    r = reciprocity(frf)
    assert r.verdict == "not reciprocal" and r.suspects == ("top:2:Z",)
    assert r.calibration["top:2:Z"] == pytest.approx(1.1, abs=0.01)
    flagged = {(p.i, p.j) for p in r.pairs if p.any_flagged}
    assert flagged == {("left:9:Y", "top:2:Z"), ("top:2:Z", "right:6:-X")}
    assert any("top:2:Z" in line for line in quality_lines(quality_checks(frf)))


def test_driving_points_pass_and_a_wrong_sign_or_a_transfer_fails(clean):
    dps = driving_points(clean)
    assert len(dps) == 3
    for o, r, s in dps:
        c = check_driving_point(clean, o, r, s, band=(5, 400))
        assert c.ok, c
        assert len(c.antiresonances_hz) == len(c.resonances_hz) - 1 >= 2
    o, r, s = dps[0]
    flipped = check_driving_point(clean, o, r, -s, band=(5, 400))
    assert not flipped.phase_ok
    # a transfer FRF taken for a driving point: resonances without an antiresonance between some of them
    transfer = check_driving_point(clean, clean.outputs.index("left:9:Y"), clean.references.index("right:6:-X"),
                                   band=(5, 400))
    assert not transfer.ok


def test_no_pairs_without_struck_sensor_points(clean):
    sub = clean.select(references=["right:6:-X"])
    assert reciprocity(sub).verdict == "no pairs"
    q = quality_checks(replace(clean, meta={**clean.meta}))
    assert q["reciprocity"]["verdict"] == "reciprocal" and len(q["driving_points"]) == len(SENSORS)
