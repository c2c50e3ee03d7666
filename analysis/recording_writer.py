"""The recording's writer: appends hits and FRF results as the test goes, each flushed before the
analyser is armed again (``docs/recording-format.md``); :class:`RecordingWriter.resume` reopens an
interrupted file."""
from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from analysis.errors import RecordingError
from analysis.frf import FRFSet
from analysis.hit import Hit
from analysis.spectra import AveragedSpectra, WindowSettings

from .atomic import atomic_path
from .recording_lock import WriterLock, held_by_other_program, is_lock_error, locked, locked_error
from .recording_schema import _DAMAGE, SCHEMA, SCHEMA_VERSION, _as_str, _channel_table, _h5py, _now_iso, counts_crc32

__all__ = ["RecordingWriter", "FRFPoint"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FRFPoint:
    """Where a measurement point's FRFs sit in the recording: its index in the test plan, its point
    label and the indices of the hits averaged into them."""

    measurement: int
    label: str
    hits: tuple = ()


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
        file there, replaced with ``overwrite``, stays whole until then); the writer keeps it open."""
        with atomic_path(self.path) as tmp:
            try:
                self._f = _h5py().File(tmp, "x")
            except OSError as exc:
                raise RecordingError(f"cannot create recording {self.path}: {exc}") from None
            try:
                self._create(instrument, setup, channels, windows, plan, software)
            except BaseException:
                self._f.close()
                raise

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
        a = self._f["hits"][name].attrs
        a["accepted"] = False  # first: a crash between the two writes leaves the hit out, not in
        a["reasons"] = json.dumps(json.loads(_as_str(a["reasons"])) + [str(reason)])
        self._f.flush()

    @locked
    def write_frf(self, point: FRFPoint, frfset: FRFSet, spectra: AveragedSpectra) -> None:
        """Write (or replace) the FRF results of one measurement point and flush.

        ``frfset``: the point's H1 estimate with one reference (``H[n_out, 1, n_freq]``), its
        coherence, window time constant, sample rate, record length and pre-trigger (all stored so
        that readers never recompute them); ``spectra``: the averaged spectra, the H2 estimate and the
        windows they were computed with.
        """
        if frfset.n_references != 1:
            raise RecordingError(f"write_frf takes the FRFs of one measurement point (one reference); got "
                                 f"{frfset.n_references} references")
        grp = self._f["frf"]
        name = f"m{int(point.measurement):03d}"
        if name in grp:
            del grp[name]
        g = grp.create_group(name)
        coh = frfset.coherence[:, 0, :] if frfset.coherence is not None else np.ones(frfset.H.shape[::2])
        for key, val in (("freq_hz", frfset.freq_hz), ("H1", frfset.H[:, 0, :]), ("H2", spectra.H2),
                         ("coherence", coh), ("Gff", spectra.Gff), ("Gxx", spectra.Gxx), ("Gfx", spectra.Gfx)):
            g.create_dataset(key, data=np.asarray(val))
        a = g.attrs
        a["measurement"] = int(point.measurement)
        a["point"] = str(point.label)
        a["outputs"] = json.dumps(list(frfset.outputs))
        a["reference"] = frfset.references[0]
        a["n_averages"] = int(spectra.n_averages)
        a["hits"] = np.asarray(list(point.hits), dtype=np.int64)
        a["quantity"] = frfset.quantity
        a["unit"] = frfset.unit
        a["windows_json"] = json.dumps(spectra.windows.to_dict())
        for key in ("exp_window_tau_s", "sample_rate_hz", "record_s", "pretrigger_s"):
            value = getattr(frfset, key)
            a[key] = float("nan") if value is None else float(value)
        self._f.flush()

    @locked
    def set_attr(self, key: str, value: Any) -> None:
        """Set a root attribute (str, number or bool) and flush."""
        self._f.attrs[str(key)] = value
        self._f.flush()

    def close(self, discard: bool = False) -> None:
        """Close the recording (``discard``: and delete it, still holding its lock, so that a writer
        that has started on the same path since is never touched)."""
        if self._f.id.valid:
            with self._lock.changing():
                self._f.attrs["closed_utc"] = _now_iso()
                self._f.close()
        if discard:
            self.path.unlink(missing_ok=True)
        self._lock.release()

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
