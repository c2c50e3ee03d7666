"""The library functions behind ``export`` and ``import`` refuse outputs like their commands do
(:func:`analysis.outputs.check_outputs`): an output that is an input, also through a link, or a
recording a live writer holds is refused before anything is written."""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np
import pytest

from acquisition.cli_export import export, export_sep005
from acquisition.importers import read_sep005_test, write_imported
from analysis.errors import OutputBusy, UsageError
from analysis.hit import Hit
from analysis.recording_writer import RecordingWriter
from analysis.spectra import WindowSettings

HIT = dict(eu_per_count=[0.01, 0.02], volts_per_count=[3e-5, 1.5e-4], trigger_index=8, sample_rate_hz=6400.0,
           timestamp=1.0, measurement=0, point="right:6:-X", reference="right:6:-X", outputs=["left:9:Y"],
           force_channel=0, response_channels=[1], overload=[False, False], accepted=True)
CHANNELS = [{"name": "force", "point": "right:6:-X", "quantity": "force", "unit": "N"},
            {"name": "acc", "point": "left:9:Y", "quantity": "acceleration", "unit": "m/s^2"}]


def _recording(path: Path) -> Path:
    rng = np.random.default_rng(3)
    with RecordingWriter(path, instrument={}, setup={}, channels=CHANNELS, windows=WindowSettings()) as w:
        for k in range(2):
            w.write_hit(Hit(counts=rng.integers(-900, 900, (2, 64)).astype(np.int16), sequence=k + 1, **HIT))
    return path


def _digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_export_export_sep005_and_write_imported_refuse_an_input_or_a_live_recording_as_output(tmp_path):
    rec = _recording(tmp_path / "rec.h5")
    os.symlink(rec, tmp_path / "link.h5")
    sep = tmp_path / "hits.json"
    assert export_sep005(rec, sep) == 4
    before = {p: _digest(p) for p in (rec, sep)}

    with pytest.raises(UsageError, match="is the input"):
        export(rec, rec, overwrite=True)
    with pytest.raises(UsageError, match="through a link"):
        export(rec, tmp_path / "link.h5", overwrite=True)
    with pytest.raises(UsageError, match="is the input"):
        export_sep005(rec, rec, overwrite=True)
    test = read_sep005_test(sep)
    with pytest.raises(UsageError, match="is the input"):
        write_imported(test, sep, overwrite=True)
    assert {p: _digest(p) for p in (rec, sep)} == before

    live = tmp_path / "live.h5"
    with RecordingWriter(live, instrument={}, setup={}, channels=CHANNELS, windows=WindowSettings()) as w:
        w.write_hit(Hit(counts=np.ones((2, 64), np.int16), sequence=1, **HIT))
        held = _digest(live)
        for write in (lambda: export(rec, live, overwrite=True), lambda: export_sep005(rec, live, overwrite=True),
                      lambda: write_imported(test, live, overwrite=True)):
            with pytest.raises(OutputBusy):
                write()
        assert _digest(live) == held
