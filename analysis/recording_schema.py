"""The recording's schema constants and the helpers its writer and reader share (``docs/recording-format.md``)."""
from __future__ import annotations

import datetime as _dt
import zlib
from collections.abc import Sequence
from types import ModuleType
from typing import Any

import numpy as np

from analysis.hit import scale_counts

__all__ = ["SCHEMA", "SCHEMA_VERSION", "CHANNEL_FIELDS", "scale_counts", "counts_crc32"]


SCHEMA = "impactlab-recording"
SCHEMA_VERSION = 1
CHANNEL_FIELDS = ("name", "point", "direction", "quantity", "sensitivity", "sensitivity_unit", "unit",
                  "range_v", "coupling", "iepe")


#: what h5py, json and numpy raise on damaged file content; the reader turns it into RecordingError
_DAMAGE = (OSError, KeyError, ValueError, TypeError, RuntimeError, IndexError, AttributeError, OverflowError,
           MemoryError)


def _h5py() -> ModuleType:
    import h5py  # local import keeps module import cheap and side-effect free

    return h5py


def counts_crc32(counts: np.ndarray) -> int:
    """CRC-32 (zlib) of the counts as little-endian int16 in C order."""
    return int(zlib.crc32(np.ascontiguousarray(counts, dtype="<i2").tobytes()) & 0xFFFFFFFF)


def _now_iso() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")


def _channel_table(channels: Sequence[dict]) -> np.ndarray:
    h5py = _h5py()
    s = h5py.string_dtype()
    dt = np.dtype([("name", s), ("point", s), ("direction", s), ("quantity", s), ("sensitivity", "f8"),
                   ("sensitivity_unit", s), ("unit", s), ("range_v", "f8"), ("coupling", s), ("iepe", "?")])
    rows = []
    for ch in channels:
        rows.append((str(ch.get("name", "")), str(ch.get("point", "")), str(ch.get("direction", "")),
                     str(ch.get("quantity", "")), float(ch.get("sensitivity", np.nan)),
                     str(ch.get("sensitivity_unit", "")), str(ch.get("unit", "")),
                     float(ch.get("range_v", np.nan)), str(ch.get("coupling", "")), bool(ch.get("iepe", False))))
    return np.array(rows, dtype=dt)


def channel_rows(table: np.ndarray) -> list[dict]:
    """The rows of the set-up's channel table (:func:`_channel_table`) as dicts of Python values."""
    return [{k: (_as_str(row[k]) if isinstance(row[k], (bytes, str)) else row[k].item()) for k in table.dtype.names or ()}
            for row in table]


def _as_str(v: Any) -> str:
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    return str(v)


#: longest :func:`verify_recording` lets the reading child work (s)
