"""The test plan of an impact test: which points the roving hammer or accelerometer visits, and
what each measurement point configures (:class:`TestPlan`, :class:`Measurement`); the channel
table and the EU scaling of a set-up."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from analysis.frf import QUANTITY_UNIT
from analysis.points import parse_point

from .session_errors import SessionError

__all__ = ["FRF_QUANTITY", "PLAN_MODES", "Measurement", "TestPlan", "force_channel_of", "channel_table",
           "eu_per_count_for"]

#: channel quantity -> (FRF quantity, FRF unit for SI data)
FRF_QUANTITY = {response: (quantity, QUANTITY_UNIT[quantity]) for response, quantity in
                (("acceleration", "accelerance"), ("velocity", "mobility"), ("displacement", "receptance"))}
PLAN_MODES = ("roving_hammer", "roving_accelerometer")


@dataclass(frozen=True)
class Measurement:
    """One measurement point: the set-up to configure and the FRF labels it yields."""

    index: int
    point: str
    reference: str
    outputs: tuple
    setup: Any  # acquisition.setup.AcquisitionSetup


@dataclass(frozen=True)
class TestPlan:
    """mode: ``roving_hammer`` or ``roving_accelerometer``; points: where the roving item goes
    (empty: the set-up's own points, one measurement); hits_per_point: accepted hits to average;
    reference: the hammer point for a roving accelerometer (default: the set-up's force channel);
    levels: force levels struck in series at each point (e.g. ``("soft", "hard")``: the first
    ``hits_per_point / len(levels)`` hits soft, then the hard ones, so one recording holds both for
    ``analysis linearity``); empty: one level."""

    __test__ = False  # not a pytest test class despite the name

    mode: str = "roving_hammer"
    points: tuple = ()
    hits_per_point: int = 5
    reference: str | None = None
    levels: tuple = ()

    def __post_init__(self) -> None:
        if self.mode not in PLAN_MODES:
            raise ValueError(f"test plan mode {self.mode!r} must be one of {PLAN_MODES}")
        if self.hits_per_point < 1:
            raise ValueError(f"hits per point must be >= 1, got {self.hits_per_point}")
        object.__setattr__(self, "levels", tuple(str(v) for v in self.levels))
        if self.levels and self.hits_per_point % len(self.levels):
            raise ValueError(f"{self.hits_per_point} hits per point do not split into {len(self.levels)} equal "
                             f"series ({', '.join(self.levels)}): give a multiple of {len(self.levels)}")
        pts = tuple(str(parse_point(p)) for p in self.points)
        object.__setattr__(self, "points", pts)
        if self.reference is not None:
            object.__setattr__(self, "reference", str(parse_point(self.reference)))
        if self.mode == "roving_hammer" and self.reference is not None:
            raise ValueError("a roving-hammer plan moves the reference; give --reference only for a roving accelerometer")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def level_of(self, n_accepted: int) -> tuple[str, int, int] | None:
        """The force level of the next hit at a point with ``n_accepted`` accepted hits: (level, number
        of the hit in its series from 1, hits in the series); None for a plan of one level."""
        if not self.levels:
            return None
        per = self.hits_per_point // len(self.levels)
        k = min(n_accepted // per, len(self.levels) - 1)
        return self.levels[k], n_accepted - k * per + 1, per

    def measurements(self, setup: Any) -> list[Measurement]:
        """The measurement list for a base set-up (``acquisition.setup.AcquisitionSetup``)."""
        fch = force_channel_of(setup)
        rch = [i for i in range(len(setup.channels)) if i != fch]
        if not rch:
            raise SessionError("the set-up has no response channel: add at least one accelerometer")
        chans = list(setup.channels)
        if self.mode == "roving_accelerometer" and self.reference is not None:
            chans[fch] = replace(chans[fch], point=self.reference)
        base = replace(setup, channels=tuple(chans))
        points = self.points or (
            (base.channels[fch].point,) if self.mode == "roving_hammer" else (base.channels[rch[0]].point,)
        )
        out = []
        for k, p in enumerate(points):
            ch = list(base.channels)
            if self.mode == "roving_hammer":
                ch[fch] = replace(ch[fch], point=p)
            else:
                ch[rch[0]] = replace(ch[rch[0]], point=p)
            s = replace(base, channels=tuple(ch))
            out.append(Measurement(k, p, ch[fch].point, tuple(ch[i].point for i in rch), s))
        return out


def force_channel_of(setup: Any) -> int:
    """Index of the (single) force channel of a set-up."""
    idx = [i for i, ch in enumerate(setup.channels) if ch.quantity == "force"]
    if len(idx) != 1:
        raise SessionError(f"the set-up needs exactly one force channel (the hammer); it has {len(idx)}")
    return idx[0]


def channel_table(setup: Any) -> list[dict]:
    """The recording's channel table from an ``AcquisitionSetup``."""
    rows = []
    for ch in setup.channels:
        p = parse_point(ch.point)
        rows.append({"name": ch.name, "point": str(p), "direction": p.direction, "quantity": ch.quantity,
                     "sensitivity": float(ch.sensitivity), "sensitivity_unit": ch.sensitivity_unit,
                     "unit": ch.unit, "range_v": float(ch.range_v), "coupling": ch.coupling, "iepe": bool(ch.iepe)})
    return rows


def eu_per_count_for(setup: Any, volts_per_count: Sequence[float]) -> np.ndarray:
    """Engineering units per count per channel: volts per count / (volts per engineering unit)."""
    vpc = np.asarray(volts_per_count, dtype=float)
    vpu = np.array([ch.volts_per_unit for ch in setup.channels], dtype=float)
    if vpc.shape != vpu.shape:
        raise SessionError(f"block has {vpc.size} channels but the set-up {vpu.size}")
    return vpc / vpu

