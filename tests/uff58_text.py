"""A small ASCII UFF dataset-58 writer for tests, written from the format's documentation (SDRC's
dataset 58, "Function at nodal DOF"), independent of pyuff and of :mod:`analysis.uff`, so that
reading its files checks the project's reader against the format and not against itself.

Each record: ``    -1`` / ``    58`` / five 80-character ID lines / record 6
``(2(I5,I10),2(1X,10A1,I10,I4))`` function type, function id, version, load case, response entity,
node, direction, reference entity, node, direction / record 7 ``(3I10,3E13.5)`` ordinate data type
(4 real double, 6 complex double), number of points, even spacing 1, abscissa start, increment,
z value / records 8-11 ``(I10,3I5,2(1X,20A1))`` the abscissa, ordinate numerator, denominator and
z axis: specific data type (18 frequency, 12 acceleration, 13 force, 0 unknown), unit exponents,
label, unit label / record 12 the ordinate values, ``4E20.12`` (a complex value is two numbers) /
``    -1``.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class Record58:
    """One function: ``kind`` 4 (FRF, complex) or 6 (ordinary coherence, real); response and
    reference node and direction (1..3 = +X..+Z); the five ID lines."""

    kind: int
    rsp: tuple[int, int]
    ref: tuple[int, int]
    f0: float
    df: float
    values: np.ndarray
    ids: Sequence[str] = ("", "", "", "", "")
    unit: str = "g/N"


def _axis(spec: int, label: str, unit: str) -> str:
    return f"{spec:10d}{0:5d}{0:5d}{0:5d} {label[:20]:<20s} {unit[:20]:<20s}"


def record_text(r: Record58) -> str:
    """The text of one dataset-58 record (between and including its ``-1`` delimiters)."""
    complex_values = r.kind == 4
    v = np.asarray(r.values, complex if complex_values else float)
    numbers = np.column_stack([v.real, v.imag]).ravel() if complex_values else v
    lines = [f"{-1:6d}", f"{58:6d}"]
    lines += [(text or "NONE")[:80] for text in list(r.ids) + [""] * (5 - len(r.ids))][:5]
    lines.append(f"{r.kind:5d}{1:10d}{0:5d}{0:10d} {'NONE':<10s}{r.rsp[0]:10d}{r.rsp[1]:4d}"
                 f" {'NONE':<10s}{r.ref[0]:10d}{r.ref[1]:4d}")
    lines.append(f"{6 if complex_values else 4:10d}{v.size:10d}{1:10d}{r.f0:13.5E}{r.df:13.5E}{0.0:13.5E}")
    lines.append(_axis(18, "Frequency", "Hz"))
    lines.append(_axis(12 if complex_values else 0, "Acceleration" if complex_values else "Coherence",
                       r.unit if complex_values else "NONE"))
    lines.append(_axis(13 if complex_values else 0, "Force" if complex_values else "NONE", "N" if complex_values else "NONE"))
    lines.append(_axis(0, "NONE", "NONE"))
    for k in range(0, numbers.size, 4):
        lines.append("".join(f"{x:20.12E}" for x in numbers[k:k + 4]))
    lines.append(f"{-1:6d}")
    return "\n".join(lines) + "\n"


def write_uff58_text(path: Path, records: Sequence[Record58]) -> Path:
    """Write ``records`` as an ASCII UFF file."""
    Path(path).write_text("".join(record_text(r) for r in records), encoding="ascii")
    return Path(path)
