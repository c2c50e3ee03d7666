"""The capture physics of the simulated analyser: the operator's strike, the input stage
(anti-alias filter, 16-bit ADC), the trigger search and the block image (see "Capture" in
:mod:`simulator.firmware`). No link, no SCSI: :class:`CaptureEngine` works on the set-up and the
stand and leaves a block image in ``_block``.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from acquisition import protocol as P

__all__ = ["CaptureEngine", "StandLike", "StandChannel", "PrecomputedStand", "find_trigger"]

_log = logging.getLogger("simulator.firmware")


class StandLike(Protocol):
    """What the firmware needs from a test stand (``simulator.stand.TestStand``)."""

    def set_channels(self, channels: Sequence[Any]) -> None: ...

    def strike(self, fs_hz: float, n_samples: int, pretrigger: int) -> Any: ...



@dataclass(frozen=True)
class _Event:
    volts: np.ndarray
    info: dict



class PrecomputedStand:
    """A stand that returns the same cached input volts on every strike (throughput benchmarks).

    ``volts[n_ch, n_total]`` must hold at least ``n + margin`` samples with a trigger crossing
    after ``pretrigger``; ``strike`` returns views of it (no copy, no computation). The firmware
    recognises the repeated record (``info["cache_key"]``) and reuses its digitised block.
    """

    def __init__(self, volts: np.ndarray, fs_hz: float) -> None:
        self.volts = np.array(volts, dtype=float, copy=True)
        self.volts.setflags(write=False)
        self.fs_hz = float(fs_hz)
        self._key = object()

    def set_channels(self, channels: Sequence[Any]) -> None:
        if len(channels) != self.volts.shape[0]:
            raise ValueError(f"this precomputed stand holds {self.volts.shape[0]} channels, the set-up has "
                             f"{len(channels)}; precompute the volts for the same channel set")

    def strike(self, fs_hz: float, n_samples: int, pretrigger: int) -> Any:
        if abs(fs_hz - self.fs_hz) > 1e-9 * self.fs_hz or n_samples > self.volts.shape[1]:
            raise ValueError(f"precomputed for {self.fs_hz:g} Hz x {self.volts.shape[1]} samples, asked "
                             f"{fs_hz:g} Hz x {n_samples}")
        return _Event(self.volts[:, :n_samples], {"cache_key": (self._key, n_samples)})


class StandChannel(dict):
    """One channel as handed to ``stand.set_channels``: a dict with the keys ``point``, ``quantity``,
    ``sensitivity`` (V per SI unit), ``sensitivity_unit`` (``"V/EU"``), ``iepe``, ``coupling``,
    ``range_v``, ``input``; the keys also read as attributes (``ch.point``)."""

    def __getattr__(self, name: str) -> Any:
        try:
            return self[name]
        except KeyError:
            raise AttributeError(name) from None

    @classmethod
    def from_record(cls, rec: P.ChannelRecord) -> StandChannel:
        return cls(point=rec.point, quantity=rec.quantity, sensitivity=rec.sensitivity, sensitivity_unit="V/EU",
                   iepe=rec.iepe, coupling=rec.coupling, range_v=rec.range_mv / 1000.0, input=rec.input)



class CaptureEngine:
    """Arming, striking, digitising: the acquisition state of the analyser.

    Needs ``stand``, ``margin`` and ``_setup`` (set by SET UP); owns ``_state``, ``_sequence``,
    ``_block``, ``_overload_mask``, ``_polls``, ``_strikes``, ``_no_trigger``, ``_clock_s``,
    ``_cache``, ``_fe_cfg``, ``_adc_rng``.
    """

    stand: StandLike | None
    margin: int

    def _init_capture(self) -> None:
        self._setup: P.SetupData | None = None
        self._setup_bytes = b""
        self._state = P.State.IDLE
        self._sequence = 0
        self._block: bytes | None = None
        self._overload_mask = 0
        self._polls = 0
        self._strikes = 0
        self._no_trigger = False
        self._clock_s = 0.0
        self._cache: tuple[Any, bytes, int] | None = None
        self._fe_cfg: Any = None
        self._adc_rng: np.random.Generator | None = None

    def _start_arm(self) -> None:
        """Enter ARMED with a fresh strike count; no block ready."""
        self._state = P.State.ARMED
        self._block = None
        self._polls = 0
        self._strikes = 0
        self._no_trigger = False
        self._overload_mask = 0

    def _give_stand(self, setup: P.SetupData) -> None:
        """Tell the stand the channels; the operator strikes where the force channel's point is."""
        assert self.stand is not None
        self.stand.set_channels([StandChannel.from_record(c) for c in setup.channels])
        force = [c.point for c in setup.channels if c.quantity == "force"]
        aim = getattr(self.stand, "set_hammer_point", None)
        if force and aim is not None:
            aim(force[0])

    @property
    def block_samples(self) -> int:
        """Samples per channel of the current set-up (0 before SET UP)."""
        return self._setup.block_size if self._setup is not None else 0

    def prepare(self) -> None:
        """Load the input stage (filter design code and settings) now rather than at the first strike,
        as a powered-up analyser has its DSP ready; ``create_analyser`` calls it."""
        from simulator import frontend  # noqa: F401  (imports scipy.signal once)

        self._frontend_config()

    def _frontend_config(self) -> Any:
        """The input stage's settings: the stand's own configuration, else the default frame file."""
        if self._fe_cfg is None:
            cfg = getattr(self.stand, "config", None)
            fe = getattr(cfg, "frontend", None)
            if fe is None:
                from simulator.config import FrameConfig

                fe = FrameConfig.load().frontend
            self._fe_cfg = fe
        return self._fe_cfg

    def _strike(self) -> None:
        """One hit of the simulated operator; on a trigger the block image is ready.

        The stand delivers the volts at the analyser inputs (sensor, IEPE and input AC coupling
        included); the firmware applies the anti-alias filter (identical on all channels) and the
        16-bit ADC at each channel's range, then searches the trigger on the digitised trigger channel.
        """
        s = self._setup
        assert s is not None and self.stand is not None
        self._strikes += 1
        self._polls = 0
        n, pre = s.block_size, s.pretrigger
        n_total = n + self.margin
        fs = float(s.sample_rate_hz)
        event = self.stand.strike(fs, n_total, pre)
        info = getattr(event, "info", None) or {}
        key = info.get("cache_key")
        if key is not None and self._cache is not None and self._cache[0] == key:
            _, body, mask = self._cache
        else:
            digitised = self._digitise(np.asarray(event.volts, dtype=float), s, bool(info.get("noise", False)))
            if digitised is None:
                self._no_trigger = True
                _log.debug("strike %d: no trigger crossing", self._strikes)
                return
            body, mask = digitised
            self._cache = (key, body, mask) if key is not None else None
        self._sequence = (self._sequence + 1) & 0xFFFFFFFF
        header = P.BlockHeader(len(s.channels), mask, self._sequence, n, pre, fs, self._clock_s)
        self._clock_s += n_total / fs
        self._block = P.encode_block_header(header) + body
        self._overload_mask = mask
        self._no_trigger = False
        self._state = P.State.BLOCK_READY

    def _digitise(self, volts: np.ndarray, s: P.SetupData, noise: bool = False) -> tuple[bytes, int] | None:
        """(volts-per-count + counts bytes, overload mask) of the block around the trigger, or None.

        ``noise``: the stand's signals carry noise (its ``[noise]`` switch); then the converter adds
        its own, ``adc_noise_lsb_rms`` counts rms at each channel's range, before the quantizer.
        """
        from simulator import frontend  # the physics of the input stage

        n, pre, fs = s.block_size, s.pretrigger, float(s.sample_rate_hz)
        n_ch = len(s.channels)
        if volts.ndim != 2 or volts.shape[0] != n_ch or volts.shape[1] < n:
            raise RuntimeError(f"the stand returned volts of shape {volts.shape}; expected ({n_ch}, >= {n})")
        cfg = self._frontend_config()
        filtered = frontend.apply_anti_alias(volts, fs, cfg)
        ranges = np.array([ch.range_mv / 1000.0 for ch in s.channels])
        lsb_rms = float(getattr(cfg, "adc_noise_lsb_rms", 0.0))
        if noise and lsb_rms > 0:
            if self._adc_rng is None:  # seeded from the stand: a capture is reproducible
                self._adc_rng = np.random.default_rng([int(getattr(self.stand, "seed", 0)), 0xADC])
            vpc = np.asarray(frontend.volts_per_count(ranges)).reshape(-1, 1)
            filtered = filtered + lsb_rms * vpc * self._adc_rng.standard_normal(filtered.shape)
        t = s.trigger_channel
        counts_t, _ = frontend.quantize(filtered[t], ranges[t])
        level_counts = float(s.trigger_level_v / frontend.volts_per_count(ranges[t]))
        k = find_trigger(counts_t, level_counts, s.trigger_slope, pre, n)
        if k is None:
            return None
        counts, overload = frontend.quantize(filtered[:, k - pre:k - pre + n], ranges)
        vpc = np.asarray(frontend.volts_per_count(ranges), dtype="<f8")
        mask = sum(1 << i for i, o in enumerate(np.asarray(overload).ravel()) if o)
        return vpc.tobytes() + np.ascontiguousarray(counts, dtype="<i2").tobytes(), mask



def find_trigger(x: np.ndarray, level: float, slope: str, pre: int, n: int) -> int | None:
    """First index k >= max(pre, 1) with a crossing of ``level`` between x[k-1] and x[k]
    (rising: x[k-1] < level <= x[k]; falling: x[k-1] > level >= x[k]) and room for the block
    (k - pre + n <= len(x)); None when there is none."""
    x = np.asarray(x, dtype=float)
    last = len(x) - n + pre  # largest admissible k
    lo = max(pre, 1)
    if last < lo:
        return None
    prev, cur = x[lo - 1:last], x[lo:last + 1]
    hit = (prev < level) & (cur >= level) if slope == "rising" else (prev > level) & (cur <= level)
    idx = np.flatnonzero(hit)
    return int(idx[0]) + lo if idx.size else None



_find_trigger = find_trigger
