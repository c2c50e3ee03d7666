"""analysis.hit: the one hit container: validation, engineering units, verdicts, stacking for the
time-data diagnosis, and a round trip through a recording."""
from __future__ import annotations

import numpy as np
import pytest

from analysis.errors import UsageError
from analysis.hit import Hit, group_hits, scale_counts, stack_hits


def make_hit(seed: int = 0, n: int = 64, reference: str = "right:6:-X", fs: float = 1024.0, **kw) -> Hit:
    rng = np.random.default_rng(seed)
    counts = rng.integers(-2000, 2000, size=(3, n)).astype(np.int16)
    return Hit(counts=counts, eu_per_count=[0.01, 2e-3, 4e-3], volts_per_count=[1e-4, 2e-4, np.nan],
               sample_rate_hz=fs, trigger_index=8, force_channel=1, response_channels=[0, 2], point=reference,
               reference=reference, outputs=["left:9:Y", "top:4:X"], channel_names=("a1", "F", "a2"), **kw)


def test_engineering_units_and_roles():
    h = make_hit()
    assert np.array_equal(h.data, scale_counts(h.counts, np.array([0.01, 2e-3, 4e-3])))
    assert np.array_equal(h.force, h.data[1]) and np.array_equal(h.responses, h.data[[0, 2]])
    assert h.pretrigger_s == pytest.approx(8 / 1024.0) and h.record_s == pytest.approx(64 / 1024.0)
    assert h.overload.tolist() == [False, False, False] and h.index == -1 and h.accepted
    assert np.isnan(h.volts[2]).all()


def test_verdict_and_index_give_new_hits():
    h = make_hit()
    v = h.with_verdict(False, ["double hit"], {"force_peak_n": 3.0}).with_index(4)
    assert (v.accepted, v.reasons, v.check, v.index) == (False, ["double hit"], {"force_peak_n": 3.0}, 4)
    assert h.accepted and h.reasons == [] and h.index == -1  # the original is unchanged
    with pytest.raises(AttributeError):
        h.accepted = False  # type: ignore[misc]


@pytest.mark.parametrize("change, words", [
    ({"counts": np.zeros((3, 8), float)}, "int16"),
    ({"eu_per_count": [1.0, 1.0]}, "eu_per_count has 2 values for 3 channels"),
    ({"sample_rate_hz": 0.0}, "sample rate"),
    ({"response_channels": [1]}, "channel roles"),
    ({"force_channel": 3}, "channel roles"),
    ({"channel_names": ("x",)}, "1 channel names for 3 channels"),
])
def test_bad_hits_are_refused_with_the_problem_named(change, words):
    h = make_hit()
    fields = dict(counts=h.counts, eu_per_count=h.eu_per_count, volts_per_count=h.volts_per_count,
                  sample_rate_hz=h.sample_rate_hz, trigger_index=8, force_channel=1, response_channels=[0, 2],
                  point=h.point, reference=h.reference, outputs=h.outputs, channel_names=h.channel_names)
    fields.update(change)
    with pytest.raises(UsageError, match=words.replace("(", r"\(")):
        Hit(**fields)


def test_stack_and_group_for_the_time_data_diagnosis():
    hits = [make_hit(0), make_hit(1, reference="top:4:Z"), make_hit(2), make_hit(3, n=32)]
    groups = group_hits(hits)
    assert [(k, [hits.index(h) for h in v]) for k, v in groups.items()] == [
        (("right:6:-X", 1024.0, 64), [0, 2]), (("top:4:Z", 1024.0, 64), [1]), (("right:6:-X", 1024.0, 32), [3])]
    force, resp, fs = stack_hits(groups[("right:6:-X", 1024.0, 64)])
    assert force.shape == (2, 64) and resp.shape == (2, 2, 64) and fs == 1024.0
    assert np.array_equal(force[1], hits[2].force) and np.array_equal(resp[0], hits[0].responses)
    with pytest.raises(UsageError, match="differ"):
        stack_hits(hits)


def test_a_hit_round_trips_through_a_recording_whole(tmp_path):
    from analysis.recording import Recording
    from analysis.recording_writer import RecordingWriter
    from analysis.spectra import WindowSettings

    h = make_hit(measurement=2, timestamp=12.5, sequence=7, overload=[False, True, False], accepted=False,
                 reasons=["overload on channel 2"], check={"force_peak_n": 9.0})
    channels = [{"name": n, "point": "n:1:Z"} for n in h.channel_names]
    with RecordingWriter(tmp_path / "r.h5", instrument={}, setup={}, channels=channels,
                         windows=WindowSettings()) as w:
        assert w.write_hit(h) == 0
    with Recording(tmp_path / "r.h5") as rec:
        back = rec.hit(0)
    assert np.array_equal(back.counts, h.counts) and back.index == 0 and back.crc_ok
    for name in ("eu_per_count", "volts_per_count", "overload"):
        assert np.array_equal(getattr(back, name), getattr(h, name), equal_nan=name == "volts_per_count")
    for name in ("sample_rate_hz", "trigger_index", "force_channel", "response_channels", "point", "reference",
                 "outputs", "measurement", "channel_names", "timestamp", "sequence", "accepted", "reasons", "check"):
        assert getattr(back, name) == getattr(h, name), name
