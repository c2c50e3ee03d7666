"""``simulator fleet`` into a folder that already holds a fleet: the same options complete it, other
options are refused before anything is captured, so ``truth.json`` always describes the recordings."""
from __future__ import annotations

import json

from simulator.cli_fleet import main as fleet


def test_a_folder_of_another_fleet_is_refused_and_its_truth_kept(tmp_path, capsys):
    out = tmp_path / "fleet"
    base = ["--units", "2", "--hits", "1", "--jobs", "1", "--seed", "5", "--out", str(out)]
    assert fleet([*base, "--defects", "2"]) == 0
    truth = (out / "truth.json").read_bytes()
    recordings = sorted(p.name for p in out.glob("unit-*.h5"))
    assert recordings == ["unit-001.h5", "unit-002.h5"]
    assert json.loads(truth)["defects"] == 2
    capsys.readouterr()

    assert fleet([*base, "--defects", "0"]) == 2
    err = capsys.readouterr().err
    assert "holds another fleet" in err and "--defects 2" in err and "new --out folder" in err
    assert (out / "truth.json").read_bytes() == truth
    assert sorted(p.name for p in out.glob("unit-*.h5")) == recordings

    assert fleet([*base, "--defects", "2", "--units", "3"]) == 2  # unit-002's config differs in a fleet of 3
    assert (out / "truth.json").read_bytes() == truth
    capsys.readouterr()

    assert fleet([*base, "--defects", "2"]) == 0  # the same options: nothing left to capture
    assert "2 of 2 units already on disk" in capsys.readouterr().err
    assert json.loads((out / "truth.json").read_bytes()) == json.loads(truth)
