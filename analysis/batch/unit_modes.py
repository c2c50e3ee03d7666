"""A fit's modes as arrays: what the fleet statistics need of one unit (or of a reference fit).

Reads the ``analysis fit --json`` document (schema ``impactlab.fit/1``), which is also the ``fit``
of a batch result, so a reference may be any earlier fit of a good unit.
"""
from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..inputs import InputError

__all__ = ["UnitModes", "modes_from_fit", "read_reference"]


@dataclass(frozen=True)
class UnitModes:
    """The modes of one fit, sorted by frequency: natural frequency (Hz), damping ratio (-), their
    standard deviations, and the shapes (n_outputs, n_modes) complex at ``outputs`` (the driving
    reference's residues or mode shapes, arbitrary scale: used only through the MAC)."""

    freq_hz: np.ndarray
    damping: np.ndarray
    freq_std_hz: np.ndarray
    damping_std: np.ndarray
    shapes: np.ndarray
    outputs: tuple[str, ...]

    @property
    def n_modes(self) -> int:
        return int(self.freq_hz.size)


def _pairs(values: Any) -> np.ndarray:
    a = np.asarray(values, dtype=float).reshape(-1, 2)
    return a[:, 0] + 1j * a[:, 1]


def _num(x: Any) -> float:
    return float("nan") if x is None else float(x)


def modes_from_fit(doc: Mapping[str, Any]) -> UnitModes:
    """:class:`UnitModes` of a fit document (poles, and mode_shapes or else the first reference's residues)."""
    poles = list(doc.get("poles") or [])
    f = np.array([_num(p.get("freq_hz")) for p in poles])
    order = np.argsort(f)
    outputs = tuple(map(str, doc.get("outputs") or ()))
    shapes = np.zeros((len(outputs), len(poles)), complex)
    if doc.get("mode_shapes"):
        for i, row in enumerate(doc["mode_shapes"][: len(outputs)]):
            shapes[i] = _pairs(row["values"])
    elif doc.get("residues"):
        ref0 = (doc.get("references") or [None])[0]
        for row in doc["residues"]:
            if row.get("reference") == ref0 and row.get("output") in outputs:
                shapes[outputs.index(row["output"])] = _pairs(row["values"])
    return UnitModes(
        freq_hz=f[order],
        damping=np.array([_num(p.get("damping")) for p in poles])[order],
        freq_std_hz=np.array([_num(p.get("freq_hz_std")) for p in poles])[order],
        damping_std=np.array([_num(p.get("damping_std")) for p in poles])[order],
        shapes=shapes[:, order],
        outputs=outputs,
    )


def read_reference(path: str | Path) -> UnitModes:
    """The modes of a reference fit: an ``analysis fit --json`` file or a batch result JSON."""
    from ..input_limits import RESULT_LIMIT_BYTES, read_bounded_text

    p = Path(path)
    try:
        doc = json.loads(read_bounded_text(p, "--reference file", RESULT_LIMIT_BYTES, InputError))
    except InputError:
        raise
    except FileNotFoundError:
        raise InputError(f"reference fit {p} not found: give the JSON of 'analysis fit --json' of a good unit") from None
    except (OSError, ValueError) as exc:
        raise InputError(f"reference fit {p} is not readable JSON ({exc}): give the JSON of 'analysis fit --json'") \
            from None
    if isinstance(doc, dict) and isinstance(doc.get("fit"), dict):
        doc = doc["fit"]
    if not isinstance(doc, dict) or not doc.get("poles"):
        raise InputError(f"reference fit {p} has no poles: give the JSON of 'analysis fit --json' of a good unit")
    return modes_from_fit(doc)
