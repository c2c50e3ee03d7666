"""Poles picked by hand: the file the report's stabilization diagram saves and ``analysis fit
--poles FILE`` reads.

The file (schema ``impactlab.poles/1``, written by the report's "save picked poles" button) is a
small JSON document::

    {"schema": "impactlab.poles/1", "input": "rec.h5", "band_hz": [4.0, 215.0],
     "poles": [{"freq_hz": 12.93, "damping": 0.0086, "order": 14}, ...]}

``freq_hz``: natural frequency (Hz, > 0); ``damping``: viscous damping ratio (0 <= zeta < 1, not %),
optional; ``order``: the model order the pole was picked at (information only). When every pole has
its damping the fit starts from exactly these poles; when one lacks it, from the frequencies (the
damping then comes from the stabilization diagram). A plain text file with frequencies in Hz
(separated by commas, blanks or new lines) is accepted too.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .inputs import InputError
from .modal import pole_from_fz

__all__ = ["PICKS_SCHEMA", "PolePicks", "read_picks"]

#: the ``schema`` of a picked-poles file
PICKS_SCHEMA = "impactlab.poles/1"
_HOW = "save the picks again from the report's stabilization diagram (docs/report.md, 'Picking poles')"


@dataclass(frozen=True)
class PolePicks:
    """Picked poles: ``freq_hz`` (Hz), ``damping`` (ratio, or None when a pick has none), the
    ``band_hz`` they were picked in (or None) and the ``input`` they were picked on ("" unknown)."""

    freq_hz: np.ndarray
    damping: np.ndarray | None
    band_hz: tuple[float, float] | None = None
    input: str = ""

    def initial(self) -> np.ndarray:
        """What :func:`analysis.pipeline.fit_auto` takes as ``initial``: complex poles (rad/s)
        when every pick has its damping, else the natural frequencies (Hz)."""
        if self.damping is None:
            return self.freq_hz.copy()
        return pole_from_fz(self.freq_hz, self.damping)


def _number(value: Any, what: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{where}: {what} {value!r} is not a number; {_HOW}")
    v = float(value)
    if not math.isfinite(v):
        raise InputError(f"{where}: {what} {value!r} is not finite; {_HOW}")
    return v


def _from_json(doc: Any, where: str) -> PolePicks:
    if not isinstance(doc, dict) or doc.get("schema") != PICKS_SCHEMA:
        raise InputError(f"{where} is not a picked-poles file (no \"schema\": \"{PICKS_SCHEMA}\"); {_HOW}")
    items = doc.get("poles")
    if not isinstance(items, list) or not items:
        raise InputError(f"{where} holds no picked poles (\"poles\" is empty or missing): pick at least one pole "
                         "on the stabilization diagram before saving")
    freqs: list[float] = []
    damps: list[float | None] = []
    for k, item in enumerate(items, start=1):
        at = f"{where}, pole {k}"
        if not isinstance(item, dict) or "freq_hz" not in item:
            raise InputError(f"{at} has no \"freq_hz\"; {_HOW}")
        f = _number(item["freq_hz"], "freq_hz", at)
        if f <= 0:
            raise InputError(f"{at}: freq_hz {f} must be > 0 Hz; {_HOW}")
        freqs.append(f)
        z = item.get("damping")
        if z is None:
            damps.append(None)
            continue
        z = _number(z, "damping", at)
        if not 0 <= z < 1:
            raise InputError(f"{at}: damping {z} must be a ratio in [0, 1) (not %); {_HOW}")
        if not pole_from_fz(f, z).imag > 0:  # an oscillation: the pole is not on the real axis
            raise InputError(f"{at}: freq_hz {f:.6g} Hz with damping {z:.6g} gives no oscillation (its damped "
                             f"frequency is 0 Hz); {_HOW}")
        damps.append(z)
    band = doc.get("band_hz")
    band_hz = None
    if isinstance(band, list) and len(band) == 2 and all(isinstance(b, (int, float)) for b in band):
        band_hz = (float(band[0]), float(band[1]))
    damping = None if any(d is None for d in damps) else np.asarray(damps, float)
    return PolePicks(np.asarray(freqs, float), damping, band_hz, str(doc.get("input", "")))


def read_picks(path: str | Path) -> PolePicks:
    """Read a picked-poles file (JSON, schema :data:`PICKS_SCHEMA`) or a text file of frequencies
    (Hz). Raises :class:`analysis.inputs.InputError` naming the file and the problem."""
    from .input_limits import DOCUMENT_LIMIT_BYTES, read_bounded_text
    from .inputs import parse_float_list

    p = Path(path)
    try:
        text = read_bounded_text(p, "--poles file", DOCUMENT_LIMIT_BYTES, InputError)
    except FileNotFoundError:
        raise InputError(f"poles file {p} not found: check the path, or give the frequencies as F1,F2,...") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the poles file {p}: {exc}") from None
    if text.lstrip().startswith(("{", "[")):
        try:
            doc = json.loads(text)
        except ValueError as exc:
            raise InputError(f"{p} is not valid JSON ({exc}); {_HOW}") from None
        return _from_json(doc, str(p))
    words = text.replace("\n", ",").replace("\t", ",").replace(" ", ",")
    try:
        freqs = parse_float_list(words, "frequencies")
    except InputError as exc:
        raise InputError(f"{p} is neither a picked-poles JSON file nor a list of frequencies in Hz: {exc}") from None
    return PolePicks(np.asarray(freqs, float), None)
