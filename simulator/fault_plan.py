"""The fault plan of the simulated analyser: the fault kinds, their probabilities from URL options
(:func:`parse_faults`, :class:`FaultPlan`) and the faulty stand (the physical faults: no trigger,
double hit, overload). The byte-level faults are :class:`simulator.faults.FaultyFirmware`'s; the
whole story is in :mod:`simulator.faults`."""

from __future__ import annotations

import collections
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from acquisition import protocol as P

__all__ = ["FAULT_KINDS", "TRANSIENT_SENSES", "OVERLOAD_SCALE", "FAULT_OPTION_KEYS", "FaultPlan", "parse_faults",
           "FaultyStand"]

FAULT_KINDS = ("no_trigger", "double_hit", "overload", "short_transfer", "check_condition", "phase_error",
               "stall", "garbage", "disconnect", "slow")
_STAND_FAULTS = ("no_trigger", "double_hit", "overload")

#: sense data reported after an injected CHECK CONDITION (all say: the command was not run, try again)
TRANSIENT_SENSES = (
    P.Sense(P.SenseKey.ABORTED_COMMAND, 0x4B, 0x00),   # data phase error
    P.Sense(P.SenseKey.ABORTED_COMMAND, 0x47, 0x00),   # parity error
    P.Sense(P.SenseKey.NOT_READY, 0x04, 0x01),         # becoming ready
    P.Sense(P.SenseKey.UNIT_ATTENTION, 0x29, 0x00),    # power on or reset occurred
)

#: peak force factor of an injected overload (the default hammer saturates the force channel)
OVERLOAD_SCALE = 40.0
FAULT_OPTION_KEYS = ("faults", "fault_seed", "fault_gone_calls", "fault_slow_s")


def parse_faults(text: str | Mapping[str, float]) -> dict[str, float]:
    """``"short_transfer:0.05,garbage:0.02"`` -> ``{"short_transfer": 0.05, "garbage": 0.02}``.

    Each probability lies in [0, 1]; ``all:P`` sets every kind. Raises ValueError naming the bad
    entry and the known kinds."""
    if isinstance(text, Mapping):
        items: list[tuple[str, object]] = [(str(k), v) for k, v in text.items()]
    else:
        items = []
        for part in str(text).split(","):
            part = part.strip()
            if not part:
                continue
            name, sep, value = part.partition(":")
            if not sep:
                raise ValueError(f"fault {part!r}: write KIND:PROBABILITY, e.g. garbage:0.02 "
                                 f"(kinds: {', '.join(FAULT_KINDS)}, or all)")
            items.append((name.strip(), value.strip()))
    rates: dict[str, float] = {}
    for name, raw in items:
        try:
            p = float(raw)  # type: ignore[arg-type]  # checked: a non-number raises below
        except (TypeError, ValueError):
            raise ValueError(f"fault {name}: probability {raw!r} is not a number; give a value in [0, 1]") from None
        if not 0.0 <= p <= 1.0:
            raise ValueError(f"fault {name}: probability {p} is outside [0, 1]")
        if name == "all":
            rates.update({k: p for k in FAULT_KINDS})
        elif name in FAULT_KINDS:
            rates[name] = p
        else:
            raise ValueError(f"unknown fault kind {name!r}; known: {', '.join(FAULT_KINDS)}, all")
    return rates


@dataclass(frozen=True)
class FaultPlan:
    """Per-kind probabilities, the seed, and the size of the disconnect/slow faults.

    ``gone_calls``: link calls (reads, writes, resets) the vanished device misses before it comes
    back; ``slow_s``: delay of a slow read in seconds."""

    rates: Mapping[str, float] = field(default_factory=dict)
    seed: int = 0
    gone_calls: int = 6
    slow_s: float = 0.002

    def __post_init__(self) -> None:
        object.__setattr__(self, "rates", parse_faults(self.rates))
        if self.gone_calls < 1 or not 0 <= self.slow_s <= 1.0:
            raise ValueError("fault plan: gone_calls must be >= 1 and slow_s within 0..1 s")

    @classmethod
    def from_options(cls, options: Mapping[str, Any]) -> FaultPlan:
        """From URL options ``faults``, ``fault_seed`` (default: ``seed``), ``fault_gone_calls``, ``fault_slow_s``."""
        try:
            seed = int(options.get("fault_seed", options.get("seed", 0)))
            gone = int(options.get("fault_gone_calls", 6))
            slow = float(options.get("fault_slow_s", 0.002))
        except (TypeError, ValueError):
            raise ValueError("simulator options fault_seed and fault_gone_calls must be integers and fault_slow_s "
                             "a number of seconds") from None
        return cls(parse_faults(options.get("faults", "")), seed, gone, slow)

    def rate(self, kind: str) -> float:
        return float(self.rates.get(kind, 0.0))


class _StandEvent:
    def __init__(self, volts: np.ndarray, info: dict) -> None:
        self.volts = volts
        self.info = info


class FaultyStand:
    """Wraps a stand: misses, double hits and overloads at random (see the module docstring).

    Every other attribute is the wrapped stand's, so the firmware aims and configures it as usual."""

    def __init__(self, stand: Any, plan: FaultPlan, rng: np.random.Generator, injected: collections.Counter) -> None:
        self._stand = stand
        self._plan = plan
        self._rng = rng
        self._injected = injected

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stand, name)

    def set_channels(self, channels: Any) -> None:
        self._stand.set_channels(channels)

    def strike(self, fs_hz: float, n_samples: int, pretrigger: int) -> Any:
        plan, rng = self._plan, self._rng
        override = getattr(self._stand, "next_strike", None)
        double = rng.random() < plan.rate("double_hit")
        over = rng.random() < plan.rate("overload")
        miss = rng.random() < plan.rate("no_trigger")
        if override is not None and (double or over):
            override(double_hit=True if double else None, amplitude_scale=OVERLOAD_SCALE if over else None)
            self._injected.update([k for k, on in (("double_hit", double), ("overload", over)) if on])
        event = self._stand.strike(fs_hz, n_samples, pretrigger)
        if not miss:
            return event
        self._injected["no_trigger"] += 1
        volts = np.zeros_like(np.asarray(event.volts, dtype=float))
        info = dict(getattr(event, "info", None) or {})
        info.pop("cache_key", None)
        info["fault"] = "no_trigger"
        return _StandEvent(volts, info)
