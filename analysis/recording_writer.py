"""The recording's writer: appends hits and FRF results as the test goes, each flushed before the
analyser is armed again (``docs/recording-format.md``); :class:`RecordingWriter.resume` reopens an
interrupted file.

A full disk stops the writer cleanly: each change first reserves the room it needs on the disk
(:func:`analysis.disk_space.reserve`, with :data:`SLACK_BYTES` more for the file's own bookkeeping
and for closing it); when the disk has no room the change raises :class:`DiskFullError` before
anything of it is written, every later change raises it too, and :meth:`RecordingWriter.close`
closes the file in the room kept back. Every hit written before stays readable and the test can be
resumed."""
from __future__ import annotations

import contextlib
import json
import logging
import os
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from analysis.atomic import atomic_path, fsync_file
from analysis.disk_space import release_reserve, reserve
from analysis.errors import DiskFullError, RecordingError
from analysis.frf import FRFSet
from analysis.hit import Hit
from analysis.spectra import AveragedSpectra, WindowSettings

from .disk_space import disk_full_cause
from .recording_changes import OPS, recover
from .recording_journal import Journal, journal_path, plain
from .recording_lock import WriterLock, busy_error, held_by_other_program, is_lock_error, locked, locked_error, writer_alive
from .recording_schema import _DAMAGE, _as_str, _channel_table, _h5py, _now_iso, channel_rows, counts_crc32

__all__ = ["RecordingWriter", "FRFPoint", "SLACK_BYTES", "whole_recording"]

log = logging.getLogger(__name__)

#: room (bytes) reserved after the recording's end beyond a change's own data: the HDF5 groups,
#: attributes and index blocks the change adds, and what closing the file writes
SLACK_BYTES = 256 * 1024
#: room (bytes) reserved after the journal's end beyond a change's own data (its record's header and text)
JOURNAL_SLACK_BYTES = 64 * 1024


@dataclass(frozen=True)
class FRFPoint:
    """Where a measurement point's FRFs sit in the recording: its index in the test plan, its point
    label and the indices of the hits averaged into them."""

    measurement: int
    label: str
    hits: tuple = ()


@contextlib.contextmanager
def whole_recording(path: str | Path, overwrite: bool = False) -> Iterator[Path]:
    """A recording written whole at once (``import``, ``replay``): yield a temporary path beside
    ``path`` to write it to, which replaces ``path`` only when the body ends normally; a failure (a
    full disk included) removes it and leaves ``path`` as it was. An existing ``path`` is replaced
    only with ``overwrite``, and never while a writer has it open."""
    p = Path(path)
    if p.exists() and not overwrite:
        raise RecordingError(f"{p} exists: choose another --out file or delete it first")
    if writer_alive(p):
        raise busy_error(p)
    existed = p.exists()
    try:
        with atomic_path(p) as tmp:
            yield tmp
    except DiskFullError:
        raise DiskFullError(f"no room on the disk to write {p}: nothing was written"
                            + (", the file there is unchanged" if existed else "")
                            + "; free space (or raise the file size limit) or write elsewhere, then run the command "
                              "again") from None


def _json_safe(value: Any) -> Any:
    """``value`` as the JSON the recording stores it as (a value JSON cannot hold becomes its text)."""
    return json.loads(json.dumps(value, default=str))


def _frf_room(counts_shape: tuple) -> int:
    """Bytes the FRF results of a point need whose hits have counts of ``counts_shape`` (channels,
    samples): each hit keeps this room, so the point in progress can be written when the disk fills."""
    n_channels, n_samples = (int(counts_shape[0]), int(counts_shape[-1])) if len(counts_shape) == 2 else (1, 1)
    n_freq = n_samples // 2 + 1
    return n_freq * (16 + 64 * n_channels)  # freq, Gff; H1, H2, Gfx complex, coherence, Gxx per output


#: root attributes the header (``create``) writes, and the mark of a clean close
_HEADER_ATTRS = ("schema", "schema_version", "created_utc", "software", "plan_json", "closed_utc")


def _as_changes(f: Any, path: Path, cut: list[str], kept: list[int]) -> Iterator[tuple[str, dict]]:
    """The changes that make the open recording ``f`` as it is, hit by hit (a resumed recording's
    journal starts with them); the names of hits cut short by a crash are added to ``cut`` (not
    included), the indices of the others to ``kept``. Damage raises :class:`RecordingError`."""
    try:
        channels = channel_rows(f["setup/channels"][()])
        yield "create", plain({
            "instrument": json.loads(_as_str(f["instrument"].attrs["json"])),
            "setup": json.loads(_as_str(f["setup"].attrs["json"])), "channels": channels,
            "windows": json.loads(_as_str(f["windows"].attrs["json"])),
            "plan": json.loads(_as_str(f.attrs.get("plan_json", "{}"))),
            "software": _as_str(f.attrs.get("software", "")), "created_utc": _as_str(f.attrs.get("created_utc", ""))})
        for name in sorted(f["hits"].keys()):
            g = f["hits"][name]
            if not g.attrs.get("complete", False):
                cut.append(name)
                continue
            kept.append(int(name))
            yield "hit", {"index": int(name), "counts": g["counts"][()], "attrs": plain(dict(g.attrs))}
        for name in sorted(f["frf"].keys()):
            g = f["frf"][name]
            yield "frf", {"name": name, "datasets": {k: g[k][()] for k in g}, "attrs": plain(dict(g.attrs))}
        ev = f["events"]
        for t, level, message in zip(ev["time_unix_s"][()], ev["level"][()], ev["message"][()], strict=True):
            yield "event", plain({"time_unix_s": t, "level": level, "message": message})
        for key, value in f.attrs.items():
            if key not in _HEADER_ATTRS:
                yield "attr", plain({"key": key, "value": value})
    except _DAMAGE as exc:
        raise RecordingError(f"{path} is damaged and cannot be resumed ({type(exc).__name__}: {exc})") from None


class RecordingWriter:
    """Write a schema-v1 recording as the test goes (see module doc). Use as a context manager.

    Parameters
    ----------
    path : output file (created; an existing file is replaced only with ``overwrite=True``).
    instrument : the analyser's identity (vendor, model, serial, firmware...).
    setup : ``AcquisitionSetup.to_dict()`` (stored as JSON).
    channels : one dict per analyser channel with the keys of :data:`CHANNEL_FIELDS`.
    windows : the window settings used for the FRFs.
    plan : the test plan (kind "roving_hammer"/"roving_accelerometer", points...), stored as JSON.
    journal : keep the journal ``REC.h5.journal`` beside the recording while it is open
        (``analysis.recording_journal``: what makes a killed writer lose nothing). False only for a
        file written whole into a temporary and renamed into place (:func:`whole_recording`), which
        a killed writer leaves unfinished and never renamed anyway.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        instrument: dict,
        setup: dict,
        channels: Sequence[dict],
        windows: WindowSettings,
        plan: dict | None = None,
        software: str = "impactlab",
        overwrite: bool = False,
        journal: bool = True,
    ) -> None:
        self.path = Path(path)
        self._full: DiskFullError | None = None
        self._n_hits = 0
        self._journal: Journal | None = None
        self._lock = WriterLock(self.path)  # OutputBusy when a live writer has the recording open
        try:
            if os.path.lexists(self.path) and not overwrite:
                raise RecordingError(f"{self.path} exists: choose another --out file or delete it first")
            if os.path.lexists(journal_path(self.path)) and not os.path.lexists(self.path):  # ours: we hold the lock
                raise RecordingError(
                    f"{journal_path(self.path)} holds the changes of a recording whose writer stopped without closing "
                    f"it: 'python -m acquisition capture --resume {self.path}' rebuilds that recording from it; move "
                    "the journal away to start a new recording there")
            if held_by_other_program(self.path):
                raise locked_error(self.path)
            header = plain({"instrument": _json_safe(instrument), "setup": _json_safe(setup),
                            "channels": _json_safe(list(channels)), "windows": windows.to_dict(),
                            "plan": _json_safe(plan or {}), "software": software, "created_utc": _now_iso()})
            with self._lock.changing():
                Journal.discard(journal_path(self.path))  # a journal left there belongs to the file replaced
                self._create_beside(header, journal)
        except BaseException:
            if getattr(self, "_f", None) is not None and self._f.id.valid:
                with contextlib.suppress(*_DAMAGE):
                    self._f.close()
            self._lock.release()
            raise

    def _start_journal(self, ops: Iterable[tuple[str, dict]]) -> None:
        """Start the journal with the changes that make the recording as it is now."""
        try:
            self._journal = Journal(journal_path(self.path))
            for op, args in ops:
                self._journal.append(op, args)
        except (RecordingError, OSError) as exc:
            if self._journal is not None:
                self._journal.remove()
                self._journal = None
            if isinstance(exc, RecordingError):
                raise
            if disk_full_cause(exc) is not None:
                raise DiskFullError(f"no room on the disk to start the journal of {self.path} ({exc.strerror}); free "
                                    "space (or raise the file size limit) and run the command again") from None
            raise RecordingError(f"cannot write the journal of {self.path} ({exc.strerror or exc}); check the "
                                 "folder's permissions and room") from None

    def _change(self, op: str, args: dict, what: str) -> None:
        """Journal the change ``op`` (``what`` names it in a message), apply it to the HDF5 file and
        flush: once this returns, the change survives the writer being killed."""
        args = plain(args)
        if self._journal is not None:
            try:
                self._journal.append(op, args)
            except OSError as exc:
                if disk_full_cause(exc) is None:
                    raise
                self._full = self._disk_full(what, exc)
                raise self._full from None
        OPS[op](self._f, args)
        self._f.flush()

    def _create_beside(self, header: dict, journal: bool) -> None:
        """Create the new recording in a temporary file beside the target, start its journal
        (``journal``) and rename it into place (a file there, replaced with ``overwrite``, stays whole
        until then; a disk without room for its header or journal leaves it as it was); the writer
        keeps it open."""
        with atomic_path(self.path) as tmp:
            try:
                self._f = _h5py().File(tmp, "x")
            except OSError as exc:
                raise RecordingError(f"cannot create recording {self.path}: {exc}") from None
            try:
                self._room(_channel_table(header["channels"]).nbytes + 4 * len(json.dumps(header["setup"])),
                           "its header")
                OPS["create"](self._f, header)
                self._f.flush()
                if journal:
                    self._start_journal([("create", header)])
            except BaseException:
                with contextlib.suppress(*_DAMAGE):
                    self._f.close()
                raise

    def _room(self, nbytes: int, what: str, *, after_full: bool = False) -> None:
        """Reserve room on the disk for a change writing ``nbytes`` of data (``what`` names it in the
        message), before any of it is written; raises :class:`DiskFullError` (and keeps raising it)
        when the disk or the file size limit has no room. ``after_full``: try even after that (the
        FRFs of the point in progress, in the room each hit keeps for them)."""
        if self._full is not None and not after_full:
            raise self._full
        try:
            reserve(self._f.id.get_vfd_handle(), int(nbytes) + SLACK_BYTES, self.path)
            if self._journal is not None and self._journal.fd is not None:
                reserve(self._journal.fd, int(nbytes) + JOURNAL_SLACK_BYTES, self._journal.path)
        except OSError as exc:
            full = self._disk_full(what, exc)
            if not after_full:
                self._full = full
            raise full from None

    def _disk_full(self, what: str, exc: OSError) -> DiskFullError:
        """The one message of a change the disk had no room for."""
        return DiskFullError(
            f"no room on the disk to write {what} to {self.path} ({exc.strerror}): the recording is closed "
            f"with the {self._n_hits} hit(s) written before it, all readable. Free space (or raise the file "
            f"size limit), then resume the test (capture --resume {self.path}, or station --resume)")

    def _open_locked(self, mode: str, failed: Any) -> None:
        """Open the HDF5 file for writing holding the lock readers follow (``analysis.recording_lock``)."""
        h5py = _h5py()
        try:
            self._f = h5py.File(self.path, mode)
        except OSError as exc:
            self._lock.release()
            raise (locked_error(self.path) if is_lock_error(exc) else failed(exc)) from None

    @classmethod
    def resume(cls, path: str | Path) -> RecordingWriter:
        """Reopen an existing recording to append to it (``capture --resume``).

        A recording whose writer stopped without closing it is first rebuilt from its journal
        (:func:`recover`). Hits cut short by a crash (no ``complete`` attribute) are removed; new
        hits are numbered after the last complete one. Raises :class:`RecordingError` when the file
        is not a recording this version writes or cannot be opened for writing."""
        from .recording import verify_recording  # the reader's check (the reader imports this module)

        self = cls.__new__(cls)
        self.path = Path(path)
        self._journal = None
        self._lock = WriterLock(self.path)  # OutputBusy when a live writer has the recording open
        try:
            with self._lock.changing():
                recover(self.path)
            verify_recording(path)  # in a child process: damage (even a libhdf5 crash) becomes RecordingError
        except BaseException:
            self._lock.release()
            raise
        with self._lock.changing():
            self._open_locked("r+", lambda exc: RecordingError(
                f"cannot open {self.path} for appending ({exc}); copy it and resume the copy, or start a new "
                "recording"))
            self._full = None
            self._n_hits = 0
            try:
                self._room(0, "the resumed test")
            except DiskFullError:
                self._f.close()
                self._lock.release()
                raise DiskFullError(f"no room on the disk to continue {self.path}: free space (or raise the file "
                                    "size limit) and resume again; the recording is unchanged") from None
            self._reopen_journaled()
        return self

    def _reopen_journaled(self) -> None:
        """Journal the recording as it is (its header, every complete hit, FRF group, event and
        attribute), then remove the hits cut short by a crash: from here on the journal alone can
        rebuild the file, whatever a later kill does to it."""
        cut: list[str] = []
        kept: list[int] = []
        try:
            self._room(self.path.stat().st_size, "the resumed test's journal")
            self._start_journal(_as_changes(self._f, self.path, cut, kept))
        except BaseException:
            self._f.close()
            self._lock.release()
            raise
        for name in cut:
            log.warning("%s: removing hit %s cut short by the crash", self.path, name)
        self._n_hits = 1 + max(kept, default=-1)
        self._change("drop_hits", {"names": cut}, "the removal of cut hits")

    # -- writing -------------------------------------------------------------------------------
    @property
    def n_hits(self) -> int:
        return self._n_hits

    @locked
    def log(self, level: str, message: str) -> None:
        """Append an event (time, level, message) and flush."""
        self._room(8 * len(str(message)) + 64, "an event")
        self._change("event", {"time_unix_s": time.time(), "level": str(level), "message": str(message)}, "an event")

    @locked
    def write_hit(self, hit: Hit) -> int:
        """Write one :class:`~analysis.hit.Hit` (its counts, scaling, roles, place and verdict) and
        flush; returns its index in the recording."""
        c = hit.counts
        idx = self._n_hits
        self._room(np.asarray(c).nbytes + 8 * len(json.dumps(hit.check, default=float)) + _frf_room(np.shape(c)),
                   f"hit {idx}")
        attrs = {
            "eu_per_count": hit.eu_per_count,
            "volts_per_count": hit.volts_per_count,
            "trigger_index": hit.trigger_index,
            "sample_rate_hz": hit.sample_rate_hz,
            "sequence": hit.sequence,
            "timestamp": hit.timestamp,
            "measurement": hit.measurement,
            "point": hit.point,
            "reference": hit.reference,
            "outputs": json.dumps(hit.outputs),
            "force_channel": hit.force_channel,
            "response_channels": np.asarray(hit.response_channels, dtype=np.int64),
            "overload": hit.overload,
            "accepted": hit.accepted,
            "reasons": json.dumps(hit.reasons),
            "check_json": json.dumps(hit.check, default=float),
            "crc32": counts_crc32(c),
            "complete": True,  # written last: a hit cut short by a crash lacks it
        }
        self._change("hit", {"index": idx, "counts": np.asarray(c), "attrs": attrs}, f"hit {idx}")
        self._n_hits += 1
        return idx

    @locked
    def withdraw_hit(self, index: int, reason: str) -> None:
        """Mark an accepted hit as not accepted after all (an operator's undo), adding ``reason``; flush."""
        name = f"{int(index):06d}"
        if name not in self._f["hits"]:
            raise RecordingError(f"{self.path} has no hit {index} to withdraw")
        self._room(4096, f"the withdrawal of hit {index}")
        self._change("withdraw", {"index": int(index), "reason": str(reason)}, f"the withdrawal of hit {index}")

    @locked
    def write_frf(self, point: FRFPoint, frfset: FRFSet, spectra: AveragedSpectra | None, *,
                  n_averages: int | None = None, windows: WindowSettings | None = None) -> None:
        """Write (or replace) the FRF results of one measurement point and flush.

        ``frfset``: the point's H1 estimate with one reference (``H[n_out, 1, n_freq]``), its
        coherence, window time constant, sample rate, record length and pre-trigger (all stored so
        that readers never recompute them); ``spectra``: the averaged spectra, the H2 estimate and the
        windows they were computed with.

        ``spectra`` None: FRFs an analyser computed (an imported FRF export): only ``freq_hz``, ``H1``
        and ``coherence`` are written, with ``n_averages`` (None: not known, stored as 0) and the
        ``windows`` the analyser is known to have used (default: none known).
        """
        if frfset.n_references != 1:
            raise RecordingError(f"write_frf takes the FRFs of one measurement point (one reference); got "
                                 f"{frfset.n_references} references")
        name = f"m{int(point.measurement):03d}"
        if spectra is None:
            self._write_frf_only(name, point, frfset, n_averages, windows or WindowSettings())
            return
        arrays = (frfset.freq_hz, frfset.H, frfset.coherence, spectra.H2, spectra.Gff, spectra.Gxx, spectra.Gfx)
        what = f"the FRFs of point {point.label}"
        self._room(sum(np.asarray(a).nbytes for a in arrays if a is not None), what, after_full=True)
        coh = frfset.coherence[:, 0, :] if frfset.coherence is not None else np.ones(frfset.H.shape[::2])
        datasets = {key: np.asarray(val) for key, val in (
            ("freq_hz", frfset.freq_hz), ("H1", frfset.H[:, 0, :]), ("H2", spectra.H2), ("coherence", coh),
            ("Gff", spectra.Gff), ("Gxx", spectra.Gxx), ("Gfx", spectra.Gfx))}
        self._change("frf", {"name": name, "datasets": datasets,
                             "attrs": self._frf_attrs(point, frfset, int(spectra.n_averages), spectra.windows)}, what)

    def _write_frf_only(self, name: str, point: FRFPoint, frfset: FRFSet, n_averages: int | None,
                        windows: WindowSettings) -> None:
        """The FRF group of an analyser's FRFs: frequencies, H1 and coherence (no spectra, no H2); an
        export that holds no coherence (e.g. SignalCalc ASCII) gets no coherence dataset."""
        arrays = [("freq_hz", frfset.freq_hz), ("H1", frfset.H[:, 0, :])]
        if frfset.coherence is not None:
            arrays.append(("coherence", frfset.coherence[:, 0, :]))
        what = f"the FRFs of point {point.label}"
        self._room(sum(np.asarray(a).nbytes for _, a in arrays), what, after_full=True)
        attrs = self._frf_attrs(point, frfset, 0 if n_averages is None else int(n_averages), windows)
        attrs["imported_frf"] = True
        self._change("frf", {"name": name, "datasets": {key: np.asarray(val) for key, val in arrays}, "attrs": attrs},
                     what)

    @staticmethod
    def _frf_attrs(point: FRFPoint, frfset: FRFSet, n_averages: int, windows: WindowSettings) -> dict:
        a: dict[str, Any] = {}
        a["measurement"] = int(point.measurement)
        a["point"] = str(point.label)
        a["outputs"] = json.dumps(list(frfset.outputs))
        a["reference"] = frfset.references[0]
        a["n_averages"] = n_averages
        a["hits"] = np.asarray(list(point.hits), dtype=np.int64)
        a["quantity"] = frfset.quantity
        a["unit"] = frfset.unit
        a["windows_json"] = json.dumps(windows.to_dict())
        for key in ("exp_window_tau_s", "sample_rate_hz", "record_s", "pretrigger_s"):
            value = getattr(frfset, key)
            a[key] = float("nan") if value is None else float(value)
        return a

    @locked
    def set_attr(self, key: str, value: Any) -> None:
        """Set a root attribute (str, number or bool) and flush."""
        self._room(len(str(value)) + 64, f"attribute {key}")
        self._change("attr", {"key": str(key), "value": value}, f"attribute {key}")

    def close(self, discard: bool = False) -> None:
        """Close the recording (``discard``: and delete it, still holding its lock, so that a writer
        that has started on the same path since is never touched)."""
        if self._f.id.valid:
            with self._lock.changing():
                self._f.attrs["closed_utc"] = _now_iso()  # in the room the last change kept back
                self._f.close()
                release_reserve(self.path)
                if self._journal is not None:  # the file is whole: synced, then its journal goes
                    fsync_file(self.path)
                    self._journal.remove()
                    self._journal = None
        if discard:
            self.path.unlink(missing_ok=True)
            Journal.discard(journal_path(self.path))
        self._lock.release()

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
