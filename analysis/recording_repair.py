"""Recover the hits of a recording that no longer opens (``python -m acquisition repair``).

A recording whose writer died in the middle of a write (a full disk with an older impactlab, a
crash of libhdf5) can end before the end of file its HDF5 superblock records; libhdf5 then refuses
the whole file ("truncated file: eof < stored_eof") although the hits written before are intact.
:func:`repair_recording` never changes its input: it copies it beside the output, extends the copy
with zeros to the recorded end of file when it is short, reads every hit, keeps those that are
complete and pass their CRC-32 check (:func:`analysis.recording_schema.counts_crc32`; a hit cut
off by the failure reads back as zeros and fails it), drops the FRF results that were computed from
a dropped hit (``capture --resume`` of the repaired file measures them again), and writes a clean recording through
:func:`analysis.atomic.atomic_path`.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import struct
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .atomic import atomic_path, temporary_beside
from .errors import RecordingError
from .outputs import check_outputs
from .recording_changes import journal_left, replay_journal
from .recording_lock import writer_alive
from .recording_schema import _DAMAGE, SCHEMA, _as_str, _h5py, counts_crc32

__all__ = ["RepairResult", "stored_eof", "repair_recording"]

_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: largest end of file a superblock may claim for the copy to be padded to it (bytes)
MAX_PAD_BYTES = 64 * 1024**3
#: longest the reading child may work on a damaged file (s)
REPAIR_TIMEOUT_S = 600.0


@dataclass(frozen=True)
class RepairResult:
    """What :func:`repair_recording` did: hit indices kept and dropped, FRF groups dropped, and
    the bytes of zeros added to reach the recorded end of file (0 when the length was right)."""

    kept: tuple[int, ...]
    dropped: tuple[int, ...]
    dropped_frf: tuple[str, ...]
    padded_bytes: int

    def summary(self) -> str:
        """The one-line outcome the command prints."""
        text = f"{len(self.kept)} hits kept, {len(self.dropped)} cut-off hits dropped"
        if self.dropped_frf:
            text += (f"; FRF results {', '.join(self.dropped_frf)} dropped (they used a dropped hit: 'capture --resume' "
                     "of the repaired file measures the point again, 'replay' recomputes them from the kept hits)")
        return text


def stored_eof(path: str | os.PathLike[str]) -> int | None:
    """The end of file (bytes from the file's start, a user block included) the HDF5 superblock of
    ``path`` records, as libhdf5 checks it; None when no superblock is found (not an HDF5 file).
    Superblocks sit at 0, 512, 1024, 2048, ... bytes (versions 0-3 are read)."""
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        at = 0
        while at + 8 <= size:
            fh.seek(at)
            head = fh.read(96)
            if head[:8] == _SIGNATURE and len(head) >= 16:
                return _eof_from_superblock(head)
            at = 512 if at == 0 else at * 2
    return None


def _eof_from_superblock(head: bytes) -> int | None:
    version = head[8]
    if version in (0, 1):
        width, first = head[13], (24 if version == 0 else 28)
    elif version in (2, 3):
        width, first = head[9], 12
    else:
        return None
    if width not in (2, 4, 8) or len(head) < first + 3 * width:
        return None
    fmt = {2: "<H", 4: "<I", 8: "<Q"}[width]
    return int(struct.unpack_from(fmt, head, first + 2 * width)[0])  # after base and free-space/extension addresses


def _pad(copy: Path, source: Path) -> int:
    """Extend ``copy`` with zeros to its recorded end of file; returns the bytes added."""
    eof = stored_eof(copy)
    if eof is None:
        raise RecordingError(f"{source} is not an HDF5 file (no superblock): it cannot be repaired")
    size = copy.stat().st_size
    if eof <= size:
        return 0
    if eof > MAX_PAD_BYTES:
        raise RecordingError(f"{source}: its superblock records an end of file of {eof} bytes, which is damaged "
                             "itself; the file cannot be repaired, use a backup")
    os.truncate(copy, eof)
    return eof - size


def _copy_attrs(src: object, dst: object) -> None:
    for k, v in src.attrs.items():  # type: ignore[attr-defined]
        dst.attrs[k] = v  # type: ignore[attr-defined]


def _good_hit(g: object) -> bool:
    """Whether a hit group is complete and its counts pass their CRC-32."""
    try:
        a = g.attrs  # type: ignore[attr-defined]
        if not a.get("complete", False):
            return False
        counts = g["counts"][()]  # type: ignore[index]
        return counts_crc32(counts) == int(a["crc32"])
    except _DAMAGE:
        return False


def _frf_ok(g: object, kept: set[int]) -> bool:
    try:
        hits = [int(i) for i in np.atleast_1d(g.attrs["hits"])]  # type: ignore[attr-defined]
        for k in g.keys():  # type: ignore[attr-defined]
            g[k][()]  # type: ignore[index]
    except _DAMAGE:
        return False
    return all(i in kept for i in hits)


def _events(src: object) -> tuple[np.ndarray, list[str], list[str]]:
    """The readable event log (empty when it is damaged)."""
    try:
        ev = src["events"]  # type: ignore[index]
        t = np.asarray(ev["time_unix_s"][()], float)
        lv = [_as_str(x) for x in ev["level"][()]]
        ms = [_as_str(x) for x in ev["message"][()]]
        n = min(len(t), len(lv), len(ms))
        return t[:n], lv[:n], ms[:n]
    except _DAMAGE:
        return np.zeros(0), [], []


def _rewrite(padded: str, out: str, source: str) -> tuple[list[int], list[int], list[str]]:
    """Read ``padded`` and write the clean recording ``out`` (runs in a child process)."""
    h5py = _h5py()
    try:
        src = h5py.File(padded, "r")
    except OSError as exc:
        raise RecordingError(f"{source} cannot be repaired: even extended to its recorded length it does not open "
                             f"({exc}); use a backup") from None
    with src, h5py.File(out, "w") as dst:
        try:
            if _as_str(src.attrs.get("schema", "")) != SCHEMA:
                raise RecordingError(f"{source} is not an impactlab recording (no schema {SCHEMA!r}): nothing to "
                                     "repair")
            _copy_attrs(src, dst)
            for name in ("instrument", "setup", "windows"):
                src.copy(src[name], dst, name=name)
            hit_names = sorted(src["hits"].keys())
        except _DAMAGE as exc:
            raise RecordingError(f"{source} cannot be repaired: its set-up or hit index is damaged "
                                 f"({type(exc).__name__}: {exc}); use a backup") from None
        hits = dst.create_group("hits")
        kept: list[int] = []
        dropped: list[int] = []
        for name in hit_names:
            ok = False
            with contextlib.suppress(*_DAMAGE):
                ok = _good_hit(src["hits"][name])
                if ok:
                    src.copy(src["hits"][name], hits, name=name)
            (kept if ok else dropped).append(int(name))
        frf = dst.create_group("frf")
        dropped_frf: list[str] = []
        try:
            frf_names = sorted(src["frf"].keys())
        except _DAMAGE:
            frf_names = []
        for name in frf_names:
            ok = False
            with contextlib.suppress(*_DAMAGE):
                ok = _frf_ok(src["frf"][name], set(kept))
                if ok:
                    src.copy(src["frf"][name], frf, name=name)
            if not ok:
                dropped_frf.append(name)
        if not kept and not frf.keys():
            raise RecordingError(f"{source} cannot be repaired: none of its {len(hit_names)} hit(s) and none of its FRF "
                                 "results is intact; use a backup or re-run the test")
        t, lv, ms = _events(src)
        message = (f"repaired: {len(kept)} hits kept, {len(dropped)} cut-off hits dropped"
                   + (f", FRF results {', '.join(dropped_frf)} dropped" if dropped_frf else ""))
        t = np.append(t, time.time())
        lv, ms = [*lv, "warning"], [*ms, message]
        ev = dst.create_group("events")
        sdt = h5py.string_dtype()
        ev.create_dataset("time_unix_s", data=t, maxshape=(None,), dtype="f8", chunks=(256,))
        ev.create_dataset("level", data=np.array(lv, dtype=object), maxshape=(None,), dtype=sdt, chunks=(256,))
        ev.create_dataset("message", data=np.array(ms, dtype=object), maxshape=(None,), dtype=sdt, chunks=(256,))
    return kept, dropped, dropped_frf


def repair_recording(rec_path: str | os.PathLike[str], out_path: str | os.PathLike[str], *,
                     overwrite: bool = False, timeout_s: float = REPAIR_TIMEOUT_S) -> RepairResult:
    """Write the recoverable part of ``rec_path`` to ``out_path`` as a clean recording (see the
    module doc; a recording whose writer left its journal is rebuilt from the journal whole);
    ``rec_path`` is never changed. Raises :class:`RecordingError` with one line when
    nothing can be recovered, :class:`~analysis.errors.UsageError` when ``out_path`` is the input."""
    from ._isolated import run_isolated
    from .errors import ChildCrashed, ChildTimeout

    src, out = Path(rec_path), Path(out_path)
    if not src.is_file():
        raise RecordingError(f"recording {src} not found: check the path")
    check_outputs([out], [src])
    if writer_alive(src):
        raise RecordingError(f"{src} is being written by a live impactlab writer: a recording in progress needs no "
                             "repair; wait for the writer to finish")
    if out.exists() and not overwrite:
        raise RecordingError(f"{out} exists: choose another --out file or give --overwrite")
    if journal_left(src):  # its writer stopped without closing it: the journal holds every change
        with atomic_path(out) as tmp:
            replay_journal(src, tmp)
            with _h5py().File(tmp, "r") as f:
                kept = [int(name) for name in sorted(f["hits"].keys())]
        return RepairResult(kept=tuple(kept), dropped=(), dropped_frf=(), padded_bytes=0)
    with atomic_path(out) as tmp:
        padded = temporary_beside(out)
        try:
            shutil.copyfile(src, padded)
            added = _pad(padded, src)
            try:
                kept, dropped, dropped_frf = run_isolated(_rewrite, (str(padded), str(tmp), str(src)), timeout_s)
            except ChildCrashed as exc:
                raise RecordingError(f"{src} cannot be repaired: reading it crashed the HDF5 library ({exc}); "
                                     "use a backup") from None
            except RecordingError:
                raise
            except ChildTimeout:
                raise RecordingError(f"{src}: repairing it took over {timeout_s:g} s; the file is damaged beyond "
                                     "repair or on a stalled drive") from None
            except _DAMAGE as exc:
                raise RecordingError(f"{src} cannot be repaired ({type(exc).__name__}: {exc}); use a backup") from None
        finally:
            with contextlib.suppress(OSError):
                padded.unlink()
    return RepairResult(kept=tuple(kept), dropped=tuple(dropped), dropped_frf=tuple(dropped_frf), padded_bytes=added)

