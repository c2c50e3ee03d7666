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
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from analysis.atomic import atomic_path
from analysis.disk_space import release_reserve, reserve
from analysis.errors import DiskFullError, RecordingError
from analysis.frf import FRFSet
from analysis.hit import Hit
from analysis.spectra import AveragedSpectra, WindowSettings

from .recording_lock import WriterLock, busy_error, held_by_other_program, is_lock_error, locked, locked_error, writer_alive
from .recording_schema import _DAMAGE, SCHEMA, SCHEMA_VERSION, _as_str, _channel_table, _h5py, _now_iso, counts_crc32

__all__ = ["RecordingWriter", "FRFPoint", "SLACK_BYTES", "whole_recording"]

log = logging.getLogger(__name__)

#: room (bytes) reserved after the recording's end beyond a change's own data: the HDF5 groups,
#: attributes and index blocks the change adds, and what closing the file writes
SLACK_BYTES = 256 * 1024


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


def _frf_room(counts_shape: tuple) -> int:
    """Bytes the FRF results of a point need whose hits have counts of ``counts_shape`` (channels,
    samples): each hit keeps this room, so the point in progress can be written when the disk fills."""
    n_channels, n_samples = (int(counts_shape[0]), int(counts_shape[-1])) if len(counts_shape) == 2 else (1, 1)
    n_freq = n_samples // 2 + 1
    return n_freq * (16 + 64 * n_channels)  # freq, Gff; H1, H2, Gfx complex, coherence, Gxx per output


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
    ) -> None:
        self.path = Path(path)
        self._full: DiskFullError | None = None
        self._n_hits = 0
        self._lock = WriterLock(self.path)  # OutputBusy when a live writer has the recording open
        try:
            if os.path.lexists(self.path) and not overwrite:
                raise RecordingError(f"{self.path} exists: choose another --out file or delete it first")
            if held_by_other_program(self.path):
                raise locked_error(self.path)
            with self._lock.changing():
                self._create_beside(instrument, setup, channels, windows, plan, software)
        except BaseException:
            self._lock.release()
            raise

    def _create_beside(self, instrument: dict, setup: dict, channels: Sequence[dict], windows: WindowSettings,
                       plan: dict | None, software: str) -> None:
        """Create the new recording in a temporary file beside the target and rename it into place (a
        file there, replaced with ``overwrite``, stays whole until then; a disk without room for its
        header leaves it as it was); the writer keeps it open."""
        with atomic_path(self.path) as tmp:
            try:
                self._f = _h5py().File(tmp, "x")
            except OSError as exc:
                raise RecordingError(f"cannot create recording {self.path}: {exc}") from None
            try:
                self._room(_channel_table(channels).nbytes + 4 * len(json.dumps(setup, default=str)),
                           "its header")
                self._create(instrument, setup, channels, windows, plan, software)
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
        except OSError as exc:
            full = DiskFullError(
                f"no room on the disk to write {what} to {self.path} ({exc.strerror}): the recording is closed "
                f"with the {self._n_hits} hit(s) written before it, all readable. Free space (or raise the file "
                f"size limit), then resume the test (capture --resume {self.path}, or station --resume)")
            if not after_full:
                self._full = full
            raise full from None

    def _open_locked(self, mode: str, failed: Any) -> None:
        """Open the HDF5 file for writing holding the lock readers follow (``analysis.recording_lock``)."""
        h5py = _h5py()
        try:
            self._f = h5py.File(self.path, mode)
        except OSError as exc:
            self._lock.release()
            raise (locked_error(self.path) if is_lock_error(exc) else failed(exc)) from None

    def _create(self, instrument: dict, setup: dict, channels: Sequence[dict], windows: WindowSettings,
                plan: dict | None, software: str) -> None:
        h5py = _h5py()
        f = self._f
        f.attrs["schema"] = SCHEMA
        f.attrs["schema_version"] = SCHEMA_VERSION
        f.attrs["created_utc"] = _now_iso()
        f.attrs["software"] = software
        g = f.create_group("instrument")
        g.attrs["json"] = json.dumps(instrument, default=str)
        for k, v in instrument.items():
            if isinstance(v, (str, int, float, bool)):
                g.attrs[k] = v
        s = f.create_group("setup")
        s.attrs["json"] = json.dumps(setup, default=str)
        s.create_dataset("channels", data=_channel_table(channels))
        f.create_group("windows").attrs["json"] = json.dumps(windows.to_dict())
        f.attrs["plan_json"] = json.dumps(plan or {}, default=str)
        f.create_group("hits")
        f.create_group("frf")
        ev = f.create_group("events")
        sdt = h5py.string_dtype()
        ev.create_dataset("time_unix_s", shape=(0,), maxshape=(None,), dtype="f8", chunks=(256,))
        ev.create_dataset("level", shape=(0,), maxshape=(None,), dtype=sdt, chunks=(256,))
        ev.create_dataset("message", shape=(0,), maxshape=(None,), dtype=sdt, chunks=(256,))
        self._n_hits = 0
        f.flush()

    @classmethod
    def resume(cls, path: str | Path) -> RecordingWriter:
        """Reopen an existing recording to append to it (``capture --resume``).

        Hits cut short by a crash (no ``complete`` attribute) are removed; new hits are numbered
        after the last complete one. Raises :class:`RecordingError` when the file is not a
        recording this version writes or cannot be opened for writing."""
        from .recording import verify_recording  # the reader's check (the reader imports this module)

        verify_recording(path)  # in a child process: damage (even a libhdf5 crash) becomes RecordingError
        self = cls.__new__(cls)
        self.path = Path(path)
        self._lock = WriterLock(self.path)  # OutputBusy when a live writer has the recording open
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
            self._drop_cut_hits()
        return self

    def _drop_cut_hits(self) -> None:
        try:
            hits = self._f["hits"]
            last = -1
            for name in sorted(hits.keys()):
                if not hits[name].attrs.get("complete", False):
                    log.warning("%s: removing hit %s cut short by the crash", self.path, name)
                    del hits[name]
                else:
                    last = max(last, int(name))
            self._n_hits = last + 1
            if "closed_utc" in self._f.attrs:
                del self._f.attrs["closed_utc"]
            self._f.flush()
        except _DAMAGE as exc:
            self._f.close()
            self._lock.release()
            raise RecordingError(f"{self.path} is damaged and cannot be resumed ({type(exc).__name__}: {exc})") from None

    # -- writing -------------------------------------------------------------------------------
    @property
    def n_hits(self) -> int:
        return self._n_hits

    @locked
    def log(self, level: str, message: str) -> None:
        """Append an event (time, level, message) and flush."""
        self._room(8 * len(str(message)) + 64, "an event")
        ev = self._f["events"]
        n = ev["time_unix_s"].shape[0]
        for name, value in (("time_unix_s", time.time()), ("level", str(level)), ("message", str(message))):
            ev[name].resize((n + 1,))
            ev[name][n] = value
        self._f.flush()

    @locked
    def write_hit(self, hit: Hit) -> int:
        """Write one :class:`~analysis.hit.Hit` (its counts, scaling, roles, place and verdict) and
        flush; returns its index in the recording."""
        c = hit.counts
        idx = self._n_hits
        self._room(np.asarray(c).nbytes + 8 * len(json.dumps(hit.check, default=float)) + _frf_room(np.shape(c)),
                   f"hit {idx}")
        g = self._f["hits"].create_group(f"{idx:06d}")
        g.create_dataset("counts", data=c)
        a = g.attrs
        a["eu_per_count"] = hit.eu_per_count
        a["volts_per_count"] = hit.volts_per_count
        a["trigger_index"] = hit.trigger_index
        a["sample_rate_hz"] = hit.sample_rate_hz
        a["sequence"] = hit.sequence
        a["timestamp"] = hit.timestamp
        a["measurement"] = hit.measurement
        a["point"] = hit.point
        a["reference"] = hit.reference
        a["outputs"] = json.dumps(hit.outputs)
        a["force_channel"] = hit.force_channel
        a["response_channels"] = np.asarray(hit.response_channels, dtype=np.int64)
        a["overload"] = hit.overload
        a["accepted"] = hit.accepted
        a["reasons"] = json.dumps(hit.reasons)
        a["check_json"] = json.dumps(hit.check, default=float)
        a["crc32"] = counts_crc32(c)
        a["complete"] = True  # written last: a hit cut short by a crash lacks it
        self._n_hits += 1
        self._f.flush()
        return idx

    @locked
    def withdraw_hit(self, index: int, reason: str) -> None:
        """Mark an accepted hit as not accepted after all (an operator's undo), adding ``reason``; flush."""
        name = f"{int(index):06d}"
        if name not in self._f["hits"]:
            raise RecordingError(f"{self.path} has no hit {index} to withdraw")
        self._room(4096, f"the withdrawal of hit {index}")
        a = self._f["hits"][name].attrs
        a["accepted"] = False  # first: a crash between the two writes leaves the hit out, not in
        a["reasons"] = json.dumps(json.loads(_as_str(a["reasons"])) + [str(reason)])
        self._f.flush()

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
        self._room(sum(np.asarray(a).nbytes for a in arrays if a is not None), f"the FRFs of point {point.label}",
                   after_full=True)
        grp = self._f["frf"]
        if name in grp:
            del grp[name]
        g = grp.create_group(name)
        coh = frfset.coherence[:, 0, :] if frfset.coherence is not None else np.ones(frfset.H.shape[::2])
        for key, val in (("freq_hz", frfset.freq_hz), ("H1", frfset.H[:, 0, :]), ("H2", spectra.H2),
                         ("coherence", coh), ("Gff", spectra.Gff), ("Gxx", spectra.Gxx), ("Gfx", spectra.Gfx)):
            g.create_dataset(key, data=np.asarray(val))
        self._frf_attrs(g, point, frfset, int(spectra.n_averages), spectra.windows)
        self._f.flush()

    def _write_frf_only(self, name: str, point: FRFPoint, frfset: FRFSet, n_averages: int | None,
                        windows: WindowSettings) -> None:
        """The FRF group of an analyser's FRFs: frequencies, H1 and coherence (no spectra, no H2); an
        export that holds no coherence (e.g. SignalCalc ASCII) gets no coherence dataset."""
        arrays = [("freq_hz", frfset.freq_hz), ("H1", frfset.H[:, 0, :])]
        if frfset.coherence is not None:
            arrays.append(("coherence", frfset.coherence[:, 0, :]))
        self._room(sum(np.asarray(a).nbytes for _, a in arrays), f"the FRFs of point {point.label}", after_full=True)
        grp = self._f["frf"]
        if name in grp:
            del grp[name]
        g = grp.create_group(name)
        for key, val in arrays:
            g.create_dataset(key, data=np.asarray(val))
        self._frf_attrs(g, point, frfset, 0 if n_averages is None else int(n_averages), windows)
        g.attrs["imported_frf"] = True
        self._f.flush()

    @staticmethod
    def _frf_attrs(g: Any, point: FRFPoint, frfset: FRFSet, n_averages: int, windows: WindowSettings) -> None:
        a = g.attrs
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

    @locked
    def set_attr(self, key: str, value: Any) -> None:
        """Set a root attribute (str, number or bool) and flush."""
        self._room(len(str(value)) + 64, f"attribute {key}")
        self._f.attrs[str(key)] = value
        self._f.flush()

    def close(self, discard: bool = False) -> None:
        """Close the recording (``discard``: and delete it, still holding its lock, so that a writer
        that has started on the same path since is never touched)."""
        if self._f.id.valid:
            with self._lock.changing():
                self._f.attrs["closed_utc"] = _now_iso()  # in the room the last change kept back
                self._f.close()
                release_reserve(self.path)
        if discard:
            self.path.unlink(missing_ok=True)
        self._lock.release()

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
