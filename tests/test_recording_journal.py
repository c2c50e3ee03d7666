"""The recording's journal (``analysis.recording_journal``): a writer killed at any moment, even in
the middle of libhdf5's flush (which can leave the HDF5 file's hit index or superblock half
written), loses no hit it reported written, no event and no operator's decision."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest

from analysis.errors import RecordingError
from analysis.frf import FRFSet
from analysis.hit import Hit
from analysis.recording import Recording
from analysis.recording_journal import MAGIC, encode_record, journal_path, read_journal
from analysis.recording_writer import FRFPoint, RecordingWriter
from analysis.spectra import AveragedSpectra, WindowSettings

WRITER = textwrap.dedent("""
    import sys, numpy as np
    from analysis.hit import Hit
    from analysis.recording_writer import RecordingWriter
    from analysis.spectra import WindowSettings
    rng = np.random.default_rng(int(sys.argv[2]))
    w = RecordingWriter(sys.argv[1], instrument={"model": "x"}, setup={"block_size": 512},
                        channels=[{"name": "f", "point": "n:1:Z"}], windows=WindowSettings())
    for i in range(int(sys.argv[3])):
        c = rng.integers(-30000, 30000, size=(2, 512)).astype(np.int16)
        idx = w.write_hit(Hit(counts=c, eu_per_count=[1.0, 2.0], volts_per_count=[1.0, 1.0], trigger_index=10,
                              sample_rate_hz=1000.0, sequence=i, timestamp=0.0, measurement=0, point="n:1:Z",
                              reference="n:1:Z", outputs=["n:2:Z"], force_channel=0, response_channels=[1],
                              overload=[False, False], accepted=True))
        w.log("INFO", f"hit {idx}")
        if idx == 1:
            w.withdraw_hit(1, "double hit")
        print(idx, int(c.sum()), flush=True)
    print("done", flush=True)
    sys.stdin.read()  # killed here, the recording still open
""")


def _killed_writer(tmp_path: Path, n_hits: int = 5) -> tuple[Path, dict[int, int]]:
    """A recording whose writer was killed (SIGKILL) after reporting ``n_hits`` hits; (path, {index: sum})."""
    p = tmp_path / "killed.h5"
    script = tmp_path / "writer.py"
    script.write_text(WRITER)
    proc = subprocess.Popen([sys.executable, str(script), str(p), "3", str(n_hits)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    reported = {}
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            if line.strip() == "done":
                break
            idx, total = map(int, line.split())
            reported[idx] = total
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stdout.close()  # type: ignore[union-attr]
        proc.stdin.close()  # type: ignore[union-attr]
    assert len(reported) == n_hits and journal_path(p).exists()
    return p, reported


def _wreck(path: Path) -> None:
    """What a kill inside libhdf5's flush can do at worst: every byte after the superblock's first
    block is garbage (the hit index, the name heap, the groups' headers)."""
    data = bytearray(path.read_bytes())
    rng = np.random.default_rng(0)
    data[96:] = rng.integers(0, 256, len(data) - 96, dtype=np.uint8).tobytes()
    path.write_bytes(bytes(data))


def test_a_killed_writer_whose_file_is_wrecked_loses_no_reported_hit_event_or_withdrawal(tmp_path):
    p, reported = _killed_writer(tmp_path)
    _wreck(p)
    with pytest.raises(OSError):  # the HDF5 file itself is beyond reading
        h5py.File(p, "r")["hits"].keys()
    before = (p.read_bytes(), journal_path(p).read_bytes())
    with Recording(p) as rec:
        assert rec.recovered and not rec.closed_cleanly and not rec.live
        hits = {h.index: h for h in rec.hits()}
        assert {i: int(h.counts.sum()) for i, h in hits.items()} == reported
        assert [h.accepted for h in rec.hits()] == [True, False, True, True, True]
        assert hits[1].reasons == ["double hit"]
        assert [m for _, _, m in rec.events()] == [f"hit {i}" for i in range(5)]
        assert rec.setup == {"block_size": 512} and rec.instrument["model"] == "x"
    assert (p.read_bytes(), journal_path(p).read_bytes()) == before  # reading changes neither file


def test_resume_rebuilds_the_file_from_its_journal_and_appends(tmp_path):
    p, reported = _killed_writer(tmp_path)
    _wreck(p)
    with RecordingWriter.resume(p) as w:
        assert w.n_hits == 5
        w.write_hit(Hit(counts=np.full((2, 512), 7, np.int16), eu_per_count=[1.0, 2.0], volts_per_count=[1.0, 1.0],
                        trigger_index=10, sample_rate_hz=1000.0, sequence=9, timestamp=0.0, measurement=0,
                        point="n:1:Z", reference="n:1:Z", outputs=["n:2:Z"], force_channel=0, response_channels=[1],
                        overload=[False, False], accepted=True))
        assert journal_path(p).exists()
    assert not journal_path(p).exists()  # closed cleanly: the file is whole, its journal gone
    with h5py.File(p, "r") as f:  # the file itself, not a rebuilt copy
        assert sorted(f["hits"].keys()) == [f"{i:06d}" for i in range(6)] and "closed_utc" in f.attrs
    with Recording(p) as rec:
        assert not rec.recovered and rec.closed_cleanly
        assert {h.index: int(h.counts.sum()) for h in rec.hits()} == {**reported, 5: 7 * 1024}
        assert len(rec.events()) == 5


def test_a_resumed_recording_killed_again_keeps_the_hits_of_both_sessions(tmp_path):
    """The journal of a resumed recording starts with the recording as it was: a second kill that
    wrecks the file loses neither the first session's hits nor the new ones."""
    p, reported = _killed_writer(tmp_path, 3)
    w = RecordingWriter.resume(p)
    w.write_hit(Hit(counts=np.full((2, 512), 3, np.int16), eu_per_count=[1.0, 2.0], volts_per_count=[1.0, 1.0],
                    trigger_index=10, sample_rate_hz=1000.0, sequence=9, timestamp=0.0, measurement=0, point="n:1:Z",
                    reference="n:1:Z", outputs=["n:2:Z"], force_channel=0, response_channels=[1],
                    overload=[False, False], accepted=True))
    w._f.close()  # as a kill leaves it: the lock dropped, the journal not removed
    w._lock.release()
    _wreck(p)
    with Recording(p) as rec:
        assert rec.recovered
        assert {h.index: int(h.counts.sum()) for h in rec.hits()} == {**reported, 3: 3 * 1024}


def _frf_point(path: Path) -> None:
    f = np.linspace(0.0, 200.0, 129)
    H = np.exp(1j * f / 50)[None, :]
    with RecordingWriter.resume(path) as w:
        w.write_frf(FRFPoint(0, "n:1:Z", (0, 2)),
                    FRFSet(freq_hz=f, H=H[:, None, :], quantity="accelerance", outputs=["n:2:Z"], references=["n:1:Z"],
                           unit="(m/s^2)/N", coherence=np.full((1, 1, 129), 0.9), sample_rate_hz=512.0),
                    AveragedSpectra(Gff=np.ones(129), Gxx=np.ones((1, 129)), Gfx=np.ones((1, 129), complex), H2=2 * H,
                                    n_averages=2, windows=WindowSettings()))
        w.set_attr("preferred_estimator", "H2")
        journal = journal_path(path).read_bytes()  # what a kill before closing would leave
    journal_path(path).write_bytes(journal)


def test_the_journal_rebuilds_what_the_writer_wrote(tmp_path):
    """Hits, withdrawals, FRF groups, events and attributes rebuilt from the journal are the live file's."""
    p, _ = _killed_writer(tmp_path, 3)
    _frf_point(p)  # resumes (rebuilding the file), writes an FRF group and an attribute, closes
    live = tmp_path / "live.h5"
    live.write_bytes(p.read_bytes())
    _wreck(p)

    def content(path: Path) -> dict:
        with Recording(path) as rec:
            hits = [(h.index, h.counts.tobytes(), h.accepted, h.reasons, h.eu_per_count.tolist()) for h in rec.hits()]
            frf = rec.frf_group("m000")
            groups = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in frf.items()}
            return {"hits": hits, "frf": json.dumps(groups, default=str), "events": rec.events(),
                    "estimator": rec.preferred_estimator, "H": rec.frfsets()[0].H.tolist()}

    assert content(p) == content(live)


def test_a_record_cut_short_is_left_out_and_damage_before_the_end_is_reported(tmp_path):
    jp = tmp_path / "r.h5.journal"
    first = encode_record("event", {"time_unix_s": 1.0, "level": "INFO", "message": "a"})
    second = encode_record("hit", {"index": 0, "counts": np.arange(6, dtype=np.int16).reshape(2, 3),
                                   "attrs": {"complete": True}})
    jp.write_bytes(MAGIC + first + second[:-3])
    got = read_journal(jp)
    assert got.torn and got.damage is None and [op for op, _ in got.ops] == ["event"]
    damaged = bytearray(second)
    damaged[20] ^= 0xFF
    jp.write_bytes(MAGIC + first + bytes(damaged) + first)
    got = read_journal(jp)
    assert not got.torn and "fails its CRC-32" in (got.damage or "") and len(got.ops) == 1
    jp.write_bytes(MAGIC + first + second)
    got = read_journal(jp)
    assert got.damage is None and not got.torn
    assert np.array_equal(got.ops[1][1]["counts"], np.arange(6, dtype=np.int16).reshape(2, 3))
    jp.write_bytes(b"something else")
    with pytest.raises(RecordingError, match="not an impactlab journal"):
        read_journal(jp)


def test_a_closed_recording_has_no_journal_and_a_new_writer_discards_a_stale_one(tmp_path):
    p = tmp_path / "r.h5"
    with RecordingWriter(p, instrument={}, setup={}, channels=[], windows=WindowSettings()) as w:
        assert journal_path(p).exists()
        w.log("INFO", "x")
    assert not journal_path(p).exists()
    journal_path(p).write_bytes(MAGIC)  # left by a writer of an earlier file at this path
    with RecordingWriter(p, instrument={}, setup={}, channels=[], windows=WindowSettings(), overwrite=True):
        assert read_journal(journal_path(p)).ops[0][0] == "create"
    assert not journal_path(p).exists()


def test_a_journal_that_cannot_be_replayed_is_a_clear_error(tmp_path):
    p, _ = _killed_writer(tmp_path, 1)
    journal_path(p).write_bytes(MAGIC + encode_record("event", {"time_unix_s": 1.0, "level": "I", "message": "m"}))
    with pytest.raises(RecordingError, match="journal.*cannot be replayed.*header"):
        Recording(p)


def test_a_journal_without_its_recording_is_never_discarded_by_a_new_writer(tmp_path):
    """A killed writer's journal whose HDF5 file was deleted still holds the hits: a new recording
    there is refused (the message says how to rebuild it), and a resume rebuilds it from the journal."""
    p, reported = _killed_writer(tmp_path, 2)
    p.unlink()
    kept = journal_path(p).read_bytes()
    with pytest.raises(RecordingError, match="capture --resume"):
        RecordingWriter(p, instrument={}, setup={}, channels=[], windows=WindowSettings(), overwrite=True)
    assert journal_path(p).read_bytes() == kept and not p.exists()
    RecordingWriter.resume(p).close()
    with Recording(p) as rec:
        assert {h.index: int(h.counts.sum()) for h in rec.hits()} == reported


def test_a_rebuilt_copy_still_locked_by_an_inherited_handle_is_read(tmp_path, monkeypatch):
    """While the reader rebuilds a killed writer's recording into its own copy, a subprocess forked by another
    thread inherits the copy's open file and, until it execs, holds the lock that writing took. The reader's copy
    is its own: it is read regardless (before, libhdf5 refused it: 'unable to lock file', errno 11)."""
    import fcntl

    import analysis.recording as recording

    p, reported = _killed_writer(tmp_path)
    real = recording.replay_journal
    held: list[int] = []

    def replay_then_held(path, out):
        result = real(path, out)
        fd = os.open(out, os.O_RDWR)
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)   # as the inherited handle holds it
        held.append(fd)
        return result

    monkeypatch.setattr(recording, "replay_journal", replay_then_held)
    try:
        with Recording(p) as rec:
            assert rec.recovered
            assert {h.index: int(h.counts.sum()) for h in rec.hits()} == reported
        assert held
    finally:
        for fd in held:
            os.close(fd)
