"""SEP005 time series (SDyPy's exchange format for measured signals): a list of channel dicts.

Each channel holds ``data`` (1-D samples), ``name``, ``unit_str`` and ``fs`` (Hz) or ``time`` (s),
and optionally ``quantity`` ('f' force, 'a' acceleration, 'v' velocity, 'd' displacement, 'e'
strain, 's' stress), ``unit_tex``, ``start_timestamp`` / ``end_timestamp`` (ISO 8601) and
``group``; any other key is allowed. SEP005 forbids a key named ``timestamp``.

impactlab writes one group per hit (``group`` = ``"hit-<n>"``) and adds the keys it needs to read
a test back: ``point`` (the channel's point label), ``trigger_index`` (sample of the trigger),
``accepted``. Files are JSON (``write_sep005`` / ``read_sep005``); :func:`check_sep005` validates
a list of channels and names what is wrong.
"""
from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import write_text_atomic
from .errors import SEP005Error
from .finite_checks import describe_nonfinite
from .input_limits import NESTING_LIMIT, read_bounded_text, text_data_limit_bytes, too_deeply_nested

__all__ = ["SEP005Error", "QUANTITY_CODES", "check_sep005", "read_sep005", "write_sep005"]

#: impactlab channel quantity -> SEP005 quantity code
QUANTITY_CODES = {"force": "f", "acceleration": "a", "velocity": "v", "displacement": "d"}


def check_sep005(channels: Any, source: str = "SEP005 data") -> list[dict]:
    """Validate ``channels`` (a list of channel dicts) against SEP005; returns them with ``data`` as
    float arrays and ``fs`` filled in from ``time`` when only that is given. Raises
    :class:`SEP005Error` naming the channel and the problem."""
    if not isinstance(channels, (list, tuple)) or not channels:
        raise SEP005Error(f"{source}: SEP005 data are a non-empty list of channel objects")
    out = []
    for k, ch in enumerate(channels):
        where = f"{source}: channel {k + 1}"
        if not isinstance(ch, Mapping):
            raise SEP005Error(f"{where} is not an object with data, name, unit_str and fs")
        missing = [key for key in ("data", "name", "unit_str") if key not in ch]
        if missing:
            raise SEP005Error(f"{where} lacks {', '.join(missing)} (SEP005 requires data, name, unit_str)")
        if "timestamp" in ch:
            raise SEP005Error(f"{where} ({ch['name']}): SEP005 forbids the key 'timestamp'; use start_timestamp")
        try:
            data = np.asarray(ch["data"], dtype=float)
        except (TypeError, ValueError):
            raise SEP005Error(f"{where} ({ch['name']}): data must be numbers") from None
        if data.ndim != 1 or data.size < 2:
            raise SEP005Error(f"{where} ({ch['name']}): data must be a 1-D list of at least 2 finite numbers")
        bad = describe_nonfinite(data)
        if bad is not None:
            raise SEP005Error(f"{where} ({ch['name']}): {bad}; measured samples must be finite numbers: fix the file")
        fs = ch.get("fs")
        if fs is None:
            t = ch.get("time")
            if t is None:
                raise SEP005Error(f"{where} ({ch['name']}): give fs (Hz) or time (s) to place the samples in time")
            try:
                t = np.asarray(t, dtype=float)
            except (TypeError, ValueError):
                raise SEP005Error(f"{where} ({ch['name']}): time must be a list of numbers (s)") from None
            if t.shape != data.shape:
                raise SEP005Error(f"{where} ({ch['name']}): time has {t.size} values for {data.size} samples")
            bad_t = describe_nonfinite(t)
            if bad_t is not None:
                raise SEP005Error(f"{where} ({ch['name']}): time {bad_t}; times must be finite numbers of seconds")
            step = np.diff(t)
            if np.any(step <= 0) or np.ptp(step) > 1e-6 * float(np.mean(step)):
                raise SEP005Error(f"{where} ({ch['name']}): time must be uniformly increasing (impact data are sampled)")
            fs = 1.0 / float(np.mean(step))
        if not (isinstance(fs, (int, float)) and math.isfinite(fs) and fs > 0):
            raise SEP005Error(f"{where} ({ch['name']}): fs must be a positive number of Hz, got {fs!r}")
        out.append({**dict(ch), "data": data, "fs": float(fs)})
    return out


def write_sep005(path: str | Path, channels: Sequence[Mapping[str, Any]], *, overwrite: bool = False) -> Path:
    """Write channels (checked by :func:`check_sep005`) as a JSON SEP005 file."""
    p = Path(path)
    if p.exists() and not overwrite:
        raise SEP005Error(f"{p} exists: choose another output file, or replace it (--overwrite)")
    doc = []
    for ch in check_sep005(list(channels), str(p)):
        doc.append({k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in ch.items()})
    write_text_atomic(p, json.dumps(doc))
    return p


def read_sep005(path: str | Path) -> list[dict]:
    """The checked channels of a JSON SEP005 file (a list of channels, or an object holding one
    under ``"channels"``)."""
    p = Path(path)
    if not p.exists():
        raise SEP005Error(f"{p} not found: check the path")
    try:
        text = read_bounded_text(p, "SEP005 file", text_data_limit_bytes(), SEP005Error)
        if too_deeply_nested(text):
            raise SEP005Error(f"{p} is not a JSON SEP005 file (nested deeper than {NESTING_LIMIT} levels)")
        doc = json.loads(text)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SEP005Error(f"{p} is not a JSON SEP005 file ({type(exc).__name__}: {exc})") from None
    except OSError as exc:
        raise SEP005Error(f"cannot read {p}: {exc.strerror or exc}") from None
    if isinstance(doc, dict) and "channels" in doc:
        doc = doc["channels"]
    return check_sep005(doc, str(p))
