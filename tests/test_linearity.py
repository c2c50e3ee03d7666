"""The linearity check (analysis.linearity, python -m analysis linearity) on hits of the simulated frame at
20 and 400 N: the linear frame, and the frame with a micro-slip joint simulated in the time domain."""
from __future__ import annotations

import json

import numpy as np
import pytest
from quality_support import FRICTION_JOINT, level_hits

from analysis.linearity import compare_levels, group_by_force, level_frfsets
from simulator.config import FrameConfig

BAND = (5.0, 220.0)


def test_group_by_force_splits_soft_and_hard_hits_only_when_they_differ():
    assert group_by_force([20, 21, 400, 380, 19, 410]).tolist() == [0, 0, 1, 1, 0, 1]
    assert group_by_force([100, 104, 96, 110, 99]).tolist() == [0] * 5
    assert group_by_force([5.0]).tolist() == [0]


def test_linear_frame_is_linear_within_the_noise():
    for seed in (1, 2):
        levels, sets = level_frfsets(level_hits(None, seed))
        assert len(sets) == 2 and levels[1] / levels[0] > 10
        res = compare_levels(sets, levels, band=BAND)
        assert res.verdict == "linear", res.summary()
        assert len(res.modes) >= 4
        assert all(abs(m.df_percent) < 0.05 for m in res.modes if m.determined)


def test_friction_joint_softens_and_damps_the_modes_that_rotate_it():
    from simulator.fem import FrameModel
    from simulator.nonlinear_joint import joint_dof_vector, joint_law

    cfg = FrameConfig.from_dict({"nonlinear": FRICTION_JOINT})
    levels, sets = level_frfsets(level_hits(cfg, 3))
    res = compare_levels(sets, levels, band=BAND)
    assert res.verdict == "nonlinear"
    sig = [m for m in res.modes if m.significant]
    assert len(sig) >= 2 and all(m.df_percent < 0 for m in sig)
    # the joint's share of each mode's strain energy, k0 delta_r^2 / omega_r^2: the mode that softens most
    # is one of the joint's (and gains damping)
    model = FrameModel.from_config(cfg)
    ms = model.modes()
    share = joint_law(cfg).k0 * (joint_dof_vector(model, cfg) @ ms.shapes) ** 2 / ms.omega ** 2
    judged = [m for m in res.modes if m.determined]
    at = np.array([share[int(np.argmin(np.abs(ms.freq_hz - m.freq_hz)))] for m in judged])
    df = np.array([m.df_percent for m in judged])
    most = int(np.argmin(df))
    assert at[most] > 0.5 * at.max() and judged[most].dzeta_percent > 10
    # a mode that moves beyond the noise is one whose shape loads the joint
    assert all(a >= 0.1 * at.max() for a, m in zip(at, judged) if m.significant)
    d = res.to_dict()
    assert d["verdict"] == "nonlinear" and {"freq_hz", "df_percent", "df_std_percent", "dzeta_percent",
                                            "significant"} <= set(d["modes"][0])


def test_cli_two_files_json_contract_and_bad_input(tmp_path, capsys):
    from analysis.cli_linearity import main
    from analysis.uff import write_uff58

    cfg = FrameConfig.from_dict({"nonlinear": FRICTION_JOINT})
    levels, sets = level_frfsets(level_hits(cfg, 4))
    paths = []
    for lv, s in zip(levels, sets):
        paths.append(str(tmp_path / f"level{lv:.0f}.uff"))
        write_uff58(paths[-1], s)
    out = tmp_path / "lin.json"
    # the high level first: the comparison orders by level
    assert main([paths[1], paths[0], "--levels", f"{levels[1]},{levels[0]}", "--band", "5:220",
                 "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["verdict"] == "nonlinear" and doc["levels"] == sorted(doc["levels"])
    for m in doc["modes"]:
        assert {"freq_hz", "df_percent", "df_std_percent", "dzeta_percent", "significant"} <= set(m)
    assert "verdict: nonlinear" in capsys.readouterr().out
    assert main([paths[0], paths[1], "--levels", "1"]) == 2
    assert "one level per input" in capsys.readouterr().err
    assert main([paths[0], paths[1]]) == 2
    assert "give --levels" in capsys.readouterr().err
    assert main([paths[0]]) == 2
    assert "recording with hits" in capsys.readouterr().err


@pytest.mark.realdata
def test_bolted_beam_softens_and_damps_more_at_the_higher_drive(shared_data, tmp_path):
    from benchmarks.accuracy.validation import unesp_boltedbeam as ub

    res = compare_levels([ub.load(shared_data, "0p05"), ub.load(shared_data, "0p30")], [0.05, 0.30],
                         band=(10.0, 400.0))
    assert res.verdict == "nonlinear"
    near = {round(m.freq_hz): m for m in res.modes}
    m98 = next(m for f, m in near.items() if 95 <= f <= 101)
    assert -1.3 < m98.df_percent < -0.8 and m98.significant and m98.dzeta_percent > 15
    assert sum(m.significant and m.df_percent < 0 for m in res.modes) >= 3


def test_level_spread_for_the_station():
    from analysis.linearity import level_spread
    from analysis.spectra import WindowSettings, hit_spectra

    out = []
    for cfg in (None, FrameConfig.from_dict({"nonlinear": FRICTION_JOINT})):
        hs = [hit_spectra(h.force, h.responses, h.fs_hz, h.trigger_index, WindowSettings())
              for h in level_hits(cfg, 5, n_hits=6)]
        out.append(level_spread(hs, (5.0, 400.0)))
        assert level_spread(hs[::2], (5.0, 400.0)) is None  # soft hits only: one level
    assert out[0]["n_hits"] == [3, 3] and out[0]["force_ratio"] > 10
    assert all(abs(p["df_percent"]) < 0.05 for p in out[0]["peaks"])
    assert min(p["df_percent"] for p in out[1]["peaks"]) < -0.2
    assert "soft (3) and hard (3) hits" in out[1]["line"]
