"""The next measurement on a capture: a plan that cannot tell two places of a mass apart, the proposed
hammer point added to the plan and captured, and the ambiguity resolved.

A 2.5 kg steel block (two beam elements on joint springs, not the diagnosis' lumped mass) at ``top:3``
of the frame, captured through ``sim://?config=...`` with the beam hammered at its middle only
(``top:4:Z``): with the default three sensors a mass at ``top:3`` and one at ``top:5``, symmetric about
the hammer, give the same measured modes (their chi2 differ by less than 4), so the diagnosis proposes
the frame point whose FRFs would separate them. Adding that point to the plan and capturing again (the
same frame, the same seed) separates them: the mass is named at ``top:3`` and nothing more is asked.
"""
from __future__ import annotations

import contextlib
import io
from pathlib import Path

import pytest
from benchmark_modules import load_benchmark

from simulator.config import FrameConfig, overrides_to_toml
from simulator.physical import FrameVariants

HITS = "5"


def _diagnose(tmp: Path, device: str, points: list[str], tag: str):
    from acquisition.cli_capture import main as capture
    from analysis.diagnosis import diagnose
    from analysis.inputs import load_input

    rec = tmp / f"{tag}.h5"
    with contextlib.redirect_stdout(io.StringIO()):
        assert capture(["--device", device, "--out", str(rec), "--points", ",".join(points), "--hits", HITS,
                        "--auto", "-q"]) == 0
    m = load_input(rec)
    return diagnose(m, FrameVariants(None, m.outputs, m.references), band="data", effects=["added_mass"])


def test_the_proposed_point_separates_two_places_of_a_mass(tmp_path) -> None:
    over = load_benchmark("accuracy/bench_diagnosis_physical.py").steel_block(FrameConfig.load(), "top:3", 2.5)
    cfg = tmp_path / "block.toml"
    cfg.write_text(overrides_to_toml(over))
    device = f"sim://?seed=7&config={cfg}"

    before = _diagnose(tmp_path, device, ["top:4:Z"], "before")
    nm = before.next_measurement
    assert nm is not None, before.reason
    assert {c["parameters"]["point"] for c in nm["candidates"]} == {"top:3", "top:5"}
    assert "fit the measured modes alike" in nm["why"] and nm["separation_db"] > 10.0
    assert nm["point"] != "top:4:Z" and nm["point"] in FrameVariants(None, ["top:4:Z"], ["top:4:Z"]).points()
    assert before.to_json()["next_measurement"]["point"] == nm["point"]

    after = _diagnose(tmp_path, device, ["top:4:Z", nm["point"]], "after")
    assert after.verdict == "added_mass", after.reason
    (named,) = after.named
    assert named["parameters"]["point"] == "top:3"
    assert named["parameters"]["mass_kg"] == pytest.approx(2.5, rel=0.25)
    assert after.next_measurement is None
