"""The automatic fit against the analyst's key of the real datasets (benchmarks/accuracy/validation/key.py):
every accepted resonance fitted, no spurious pole, no pole outside the excitation, and ``success`` true
exactly then. The data sources are cited in ../shared/data/README.md and docs/validation.md; the tests skip
without the data. The whole table: ``python benchmarks/studies/realdata_key.py``."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

_ROOT = str(Path(__file__).resolve().parents[1])
if _ROOT not in sys.path:
    sys.path.insert(0, _ROOT)

from analysis.pipeline import fit_auto  # noqa: E402
from benchmarks.accuracy.validation.datasets import DATASETS  # noqa: E402
from benchmarks.accuracy.validation.key import KEYS, score  # noqa: E402

BY_KEY = {d.key: d for d in DATASETS}


def test_the_key_scores_missed_spurious_and_doubtful_poles():
    """No data needed: the scoring itself."""
    key = KEYS["pyuff_3frf"]
    all_six = [a.freq_hz for a in key.accepted]
    s = score(key, all_six, True)
    assert s["fitted"] == 6 and s["spurious"] == [] and s["success_expected"] and s["honest"]
    s = score(key, all_six[1:] + [300.0], True)           # one missed, one pole where the key has nothing
    assert s["missed"] == [51.52] and s["spurious"] == [300.0] and not s["success_expected"] and not s["honest"]
    s = score(KEYS["uliege_plane"], [a.freq_hz for a in KEYS["uliege_plane"].accepted] + [190.3, 26.0], False)
    assert s["spurious"] == [190.3] and s["ignored"] == [26.0] and s["honest"]
    pair = score(KEYS["uliege_plane"], [a.freq_hz for a in KEYS["uliege_plane"].accepted] + [125.7], True)
    assert pair["spurious"] == [] and pair["honest"]     # the 125.4 Hz resonance may be a close pair
    above = score(KEYS["plate_sweep"], [a.freq_hz for a in KEYS["plate_sweep"].accepted] + [520.0], True)
    assert above["spurious"] == [520.0]                   # outside the sweep's 60-500 Hz


def _fit(shared_data: Path, key: str):
    d = BY_KEY[key]
    frf = d.load(shared_data, **d.whole_range)
    res = fit_auto(frf)
    return res, score(KEYS[key], res.freq_hz, res.success)


@pytest.mark.realdata
def test_uliege_plane_whole_range_thirteen_modes_no_190_hz_pole_and_a_success(shared_data):
    """222 FRFs over 0-200 Hz: the 13 accepted modes fitted, no pole at 190.2 Hz (no CMIF peak, shapes
    that disagree between accelerometers) nor at 55.4 Hz, the humps 1-3 FRFs show named, not counted;
    a success."""
    res, s = _fit(shared_data, "uliege_plane")
    assert s["missed"] == [], s
    assert s["spurious"] == [], (s, res.warnings)
    assert not np.any(np.abs(np.asarray(res.freq_hz) - 190.2) < 3.0)
    assert res.success, res.problems
    assert any("only a few FRFs show" in w for w in res.warnings)


@pytest.mark.realdata
@pytest.mark.parametrize("key", ["modelab_beam", "ladisk_single", "ladisk_multi", "f16_gvt", "plate_sweep",
                                 "pyuff_3frf"])
def test_every_accepted_mode_fitted_nothing_spurious_and_a_success(shared_data, key):
    """The datasets whose key the fit meets: the LADISK plate's 352 Hz peak is its 349.5 Hz mode (2 %
    damping: within the pole's bandwidth), the pyuff beam's one-line peaks are counted."""
    res, s = _fit(shared_data, key)
    assert s["missed"] == [] and s["spurious"] == [], (s, res.problems)
    assert res.success and s["honest"], res.problems
