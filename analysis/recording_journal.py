"""The recording's journal: every change a live writer makes is appended to ``REC.h5.journal`` and
synced to the disk before it touches the HDF5 file, so a writer killed at any moment loses nothing
it reported written.

Why a journal: libhdf5 does not write a flush atomically. Adding a hit adds a link to the ``hits``
group, whose index (a B-tree of symbol-table nodes and a name heap) splits and moves as it grows,
and the flush writes the changed pieces one after the other. A process killed inside that flush can
leave a file whose earlier hits are listed but unreachable, or that no longer opens. No HDF5 setting
h5py offers orders those writes (its single-writer/multiple-reader mode, tried, leaves a file a
killed writer cannot reopen either). The journal is the record that survives: the writer removes it
only after it has closed the HDF5 file cleanly and synced it, so a journal beside a recording that
no live writer holds means the writer stopped without closing, and the journal, not the HDF5 file,
holds everything that was written (``analysis.recording`` reads it from there, ``capture --resume``
rebuilds the file from it).

Format (little-endian): the line ``impactlab-journal 1\\n``, then one record per change::

    u32 payload length | u32 CRC-32 of the payload | payload

    payload = u32 length of the JSON text | JSON text (UTF-8) | the arrays' bytes, one after another

The JSON text is ``{"op": NAME, "args": {...}}``; an array in ``args`` is written as
``{"__array__": [dtype, shape, offset, nbytes]}`` (offset into the arrays' bytes). A record cut short
by the kill (the last one) fails its length or CRC and is ignored: its change was never applied to
the HDF5 file nor reported. The operations and what they do to the HDF5 file are in
``analysis.recording_writer`` (``OPS``).
"""
from __future__ import annotations

import json
import os
import struct
import zlib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import fsync_folder
from .errors import RecordingError

__all__ = ["MAGIC", "journal_path", "Journal", "JournalContents", "read_journal", "plain"]

#: the journal's first line: the format and its version
MAGIC = b"impactlab-journal 1\n"
_HEAD = struct.Struct("<II")
_JSON_LEN = struct.Struct("<I")
#: largest record a journal may claim (bytes): a longer length is damage, not a record
MAX_RECORD_BYTES = 1 << 31


def journal_path(path: str | Path) -> Path:
    """The journal of a recording: ``REC.h5`` -> ``REC.h5.journal``."""
    p = Path(path)
    return p.with_name(p.name + ".journal")


def plain(value: Any) -> Any:
    """``value`` with numpy scalars made Python numbers and bytes made text, arrays kept as arrays:
    the form a change is journaled and applied in, so a replay writes the same HDF5 values as the
    live writer did."""
    if isinstance(value, np.ndarray):
        return value
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


def _encode(args: Any, blobs: list[bytes], offset: list[int]) -> Any:
    if isinstance(args, np.ndarray):
        a = np.ascontiguousarray(args)
        if a.dtype.hasobject:
            raise TypeError(f"an array of {a.dtype} cannot be journaled")
        raw = a.tobytes()
        ref = {"__array__": [a.dtype.str, list(a.shape), offset[0], len(raw)]}
        blobs.append(raw)
        offset[0] += len(raw)
        return ref
    if isinstance(args, dict):
        return {k: _encode(v, blobs, offset) for k, v in args.items()}
    if isinstance(args, list):
        return [_encode(v, blobs, offset) for v in args]
    return args


def _decode(doc: Any, data: memoryview) -> Any:
    if isinstance(doc, dict):
        ref = doc.get("__array__")
        if ref is not None and len(doc) == 1:
            dtype, shape, off, n = ref
            if off < 0 or off + n > len(data):
                raise ValueError("an array runs past its record")
            return np.frombuffer(data[off:off + n], dtype=np.dtype(dtype)).reshape(shape).copy()
        return {k: _decode(v, data) for k, v in doc.items()}
    if isinstance(doc, list):
        return [_decode(v, data) for v in doc]
    return doc


def encode_record(op: str, args: Mapping[str, Any]) -> bytes:
    """One record's bytes (header and payload) for the change ``op`` with ``args`` (see module doc)."""
    blobs: list[bytes] = []
    text = json.dumps({"op": op, "args": _encode(plain(args), blobs, [0])}).encode()
    payload = b"".join([_JSON_LEN.pack(len(text)), text, *blobs])
    return _HEAD.pack(len(payload), zlib.crc32(payload) & 0xFFFFFFFF) + payload


class Journal:
    """The writer's open journal: :meth:`append` writes a change and syncs it to the disk before
    returning. Created empty (an older journal at the path is replaced); the writer removes it with
    :meth:`remove` once the recording is closed and synced."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
        try:
            self.fd: int | None = os.open(self.path, flags, 0o644)
        except OSError as exc:
            raise RecordingError(f"cannot create the journal {self.path} ({exc.strerror or exc}): a symbolic link or "
                                 "an unwritable file is in its place; move it away and run the command again") from None
        self._write(MAGIC)
        fsync_folder(self.path.parent)

    def _write(self, data: bytes) -> None:
        if self.fd is None:
            raise RecordingError(f"the journal {self.path} is closed")
        view = memoryview(data)
        while view:
            n = os.write(self.fd, view)
            view = view[n:]
        os.fsync(self.fd)

    def append(self, op: str, args: Mapping[str, Any]) -> None:
        """Append the change ``op`` with ``args`` and sync it (raises ``OSError`` when the disk is full;
        a record cut short by that is ignored by :func:`read_journal`)."""
        self._write(encode_record(op, args))

    def close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None

    def remove(self) -> None:
        """Close and delete the journal (the recording it kept is closed and synced)."""
        self.close()
        self.discard(self.path)

    @staticmethod
    def discard(path: str | Path) -> None:
        """Delete the journal file ``path`` if there is one (a symbolic link is removed, never followed)."""
        p = Path(path)
        if not os.path.lexists(p):
            return
        p.unlink()
        fsync_folder(p.parent)


@dataclass
class JournalContents:
    """What :func:`read_journal` found: the changes in order, and whether the journal ended with a
    record cut short (``torn``: the change a killed writer was making) or with damage before its end
    (``damage``: what is wrong, None when every byte after the header is a whole record)."""

    ops: list[tuple[str, dict]] = field(default_factory=list)
    torn: bool = False
    damage: str | None = None


def _records(data: bytes) -> Iterator[tuple[int, bytes | str | None]]:
    """(offset, payload) of each record; in place of the payload, None for a last record cut short
    (the iteration stops there) and the reason for a record that fails its check with more bytes
    after it (damage: the iteration stops there too)."""
    pos = len(MAGIC)
    while pos < len(data):
        if pos + _HEAD.size > len(data):
            yield pos, None
            return
        n, crc = _HEAD.unpack_from(data, pos)
        end = pos + _HEAD.size + n
        if n > MAX_RECORD_BYTES:
            yield pos, f"the record at byte {pos} claims {n} bytes"
            return
        if end > len(data):
            yield pos, None
            return
        payload = data[pos + _HEAD.size:end]
        if zlib.crc32(payload) & 0xFFFFFFFF != crc:
            yield pos, (None if end == len(data) else f"the record at byte {pos} fails its CRC-32")
            return
        yield pos, payload
        pos = end


def read_journal(path: str | Path) -> JournalContents:
    """The changes a journal holds (see module doc). Raises :class:`RecordingError` when the file is
    not a journal; a last record cut short is dropped (``torn``)."""
    p = Path(path)
    try:
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0))
        with os.fdopen(fd, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise RecordingError(f"cannot read the journal {p} ({exc.strerror or exc})") from None
    if not data.startswith(MAGIC):
        raise RecordingError(f"{p} is not an impactlab journal (it does not start with {MAGIC!r}); move it away")
    out = JournalContents()
    for pos, payload in _records(data):
        if payload is None:
            out.torn = True
            break
        if isinstance(payload, str):
            out.damage = payload
            break
        try:
            (k,) = _JSON_LEN.unpack_from(payload, 0)
            doc = json.loads(payload[_JSON_LEN.size:_JSON_LEN.size + k])
            args = _decode(doc["args"], memoryview(payload)[_JSON_LEN.size + k:])
            out.ops.append((str(doc["op"]), args))
        except (ValueError, KeyError, TypeError, struct.error) as exc:
            out.damage = f"the record at byte {pos} is damaged ({type(exc).__name__}: {exc})"
            break
    return out
