"""Fault injection for the simulated analyser: a :class:`FaultyFirmware` wrapper and a faulty stand
(the fault plan and the stand live in :mod:`simulator.fault_plan`).

The wrapper has the interface of :class:`simulator.firmware.Firmware` (``write``, ``read``,
``bulk_only_reset``, ``clear_halt``, ``halted_in``, ``halted_out``, ``pending``, ``packetized``;
every other attribute is the wrapped firmware's) and disturbs the byte flow with a seeded random
generator, one probability per fault kind. The firmware itself is untouched.

Fault kinds (``FAULT_KINDS``) and what the host sees
------------------------------------------------------
Rolled once per command (a CBW arriving while the device is idle at a command boundary):

* ``check_condition``: the command is *not executed*; the status is 1 (CHECK CONDITION) and the
  next REQUEST SENSE returns one of :data:`TRANSIENT_SENSES` (ABORTED COMMAND, NOT READY
  "becoming ready", UNIT ATTENTION). A data-in command stalls IN (packetized) or gets zero
  padding (stream), as the firmware does for a real failure.
* ``phase_error``: the command is *not executed*; the status is 2 (phase error).
* ``stall``: packetized: the command runs, then the bulk IN endpoint answers STALL once (the
  host clears the halt; a stalled data stage leaves the data in place of the status, a stalled
  status stage is read again). Stream links have no endpoints: the device swallows the command
  and ignores input until the in-band reset frame (the host times out and resets the link).

Rolled once per ``read`` that returns bytes:

* ``short_transfer``: the transfer is cut after a random number of bytes and the rest is lost.
* ``garbage``: 1..64 random bytes arrive before the real ones (nothing is lost, the stream is
  shifted, so the CSW framing check fails).
* ``disconnect``: the device vanishes for ``gone_calls`` link calls (reads return nothing, writes
  are dropped, resets ignored), then comes back as after a re-enumeration (a bulk-only reset:
  UNIT ATTENTION pending, an armed capture abandoned, set-up and a ready block kept).
* ``slow``: the read is delayed by ``slow_s`` seconds (bounded).

Rolled once per strike of the simulated operator (``FaultyStand``):

* ``no_trigger``: the strike misses (zero volts, the trigger level is never crossed);
* ``double_hit``, ``overload``: the stand's one-shot overrides (``next_strike(double_hit=True)``,
  ``amplitude_scale``), when the stand has them.

Payload bytes are never flipped in place: a real link protects its packets with a CRC (USB CRC16,
TCP checksum), so what reaches the host is lost, shifted, duplicated or out of step, which the
bulk-only envelope detects; an in-place bit flip inside a block would go unnoticed by design.

URL form: ``sim://?seed=1&faults=short_transfer:0.05,garbage:0.02&fault_seed=7`` (any simulator
door: ``sim://``, ``usbsim://``, ``python -m simulator serve --option faults=...``).
``faults=all:P`` sets every kind to P. :func:`simulator.analyser.create_analyser` reads the options ``faults``,
``fault_seed``, ``fault_gone_calls``, ``fault_slow_s`` and hands the rest to
builds the firmware from the rest.

Ground truth for tests: :attr:`FaultyFirmware.block_crc` maps each block sequence number the
firmware produced to the CRC-32 of its counts (the same checksum a recording stores), and
:attr:`FaultyFirmware.injected` counts the faults injected by kind.
"""
from __future__ import annotations

import collections
import logging
import time
import zlib
from collections.abc import Mapping
from typing import Any

import numpy as np

from acquisition import protocol as P

from .fault_plan import _STAND_FAULTS, FAULT_KINDS, FAULT_OPTION_KEYS, TRANSIENT_SENSES, FaultPlan, FaultyStand, parse_faults

__all__ = ["FAULT_KINDS", "TRANSIENT_SENSES", "FaultPlan", "parse_faults", "FaultyFirmware", "FaultyStand",
           "cbw_bytes", "FAULT_OPTION_KEYS"]

_log = logging.getLogger(__name__)


class FaultyFirmware:
    """A :class:`simulator.firmware.Firmware` with faults injected into its byte flow.

    ``firmware``: the real firmware (its stand is wrapped in :class:`FaultyStand` when a stand
    fault has a non-zero rate); ``plan``: :class:`FaultPlan`. ``injected`` counts the faults by
    kind; ``block_crc`` maps block sequence -> CRC-32 of the counts the firmware produced.
    The wrapper owns ``firmware`` from then on (its stand is replaced by a :class:`FaultyStand`).
    """

    def __init__(self, firmware: Any, plan: FaultPlan | Mapping[str, float] | str) -> None:
        if not isinstance(plan, FaultPlan):
            plan = FaultPlan(parse_faults(plan))
        self._fw = firmware
        self.plan = plan
        self.injected: collections.Counter = collections.Counter()
        self._rng = np.random.default_rng(plan.seed)
        self.block_crc: dict[int, int] = {}
        if any(plan.rate(k) > 0 for k in _STAND_FAULTS) and getattr(firmware, "stand", None) is not None:
            firmware.stand = FaultyStand(firmware.stand, plan, np.random.default_rng([plan.seed, 1]), self.injected)
        self._fake: collections.deque[bytes] = collections.deque()  # replies of faked commands
        self._front = b""  # bytes pushed back ahead of the firmware's output
        self._stall_in = False
        self._deaf = False  # stream "stall": ignore input until the reset frame
        self._deaf_tail = b""
        self._swallow = 0
        self._fake_sense: P.Sense | None = None
        self._gone = 0
        self._resets_seen = getattr(firmware, "resets", 0)
        self._last_seq: int | None = None

    # ------------------------------------------------------------------ delegation
    def __getattr__(self, name: str) -> Any:
        return getattr(self._fw, name)

    @property
    def firmware(self) -> Any:
        """The wrapped firmware."""
        return self._fw

    @property
    def packetized(self) -> bool:
        return bool(self._fw.packetized)

    @property
    def present(self) -> bool:
        """False while an injected disconnect lasts."""
        return self._gone == 0

    @property
    def halted_in(self) -> bool:
        return self._gone == 0 and (self._stall_in or self._fw.halted_in)

    @property
    def halted_out(self) -> bool:
        return self._gone == 0 and self._fw.halted_out

    def pending(self) -> int:
        if self._gone or self.halted_in:
            return 0
        return len(self._front) + sum(len(b) for b in self._fake) + self._fw.pending()

    # ------------------------------------------------------------------ control
    def bulk_only_reset(self) -> None:
        if self._tick_gone():
            return
        self._clear_link()
        self._fw.bulk_only_reset()
        self._resets_seen = getattr(self._fw, "resets", 0)

    def clear_halt(self, direction_in: bool) -> None:
        if self._tick_gone():
            return
        if direction_in:
            self._stall_in = False
        self._fw.clear_halt(direction_in)

    def _clear_link(self) -> None:
        self._fake.clear()
        self._front = b""
        self._stall_in = False
        self._deaf = False
        self._deaf_tail = b""
        self._swallow = 0
        self._fake_sense = None

    def _tick_gone(self) -> bool:
        """True while the device is away (this call is lost); brings it back when the time is up."""
        if self._gone == 0:
            return False
        self._gone -= 1
        if self._gone == 0:
            _log.info("injected disconnect over: the device is back (reset)")
            self._clear_link()
            self._fw.bulk_only_reset()
            self._fw.clear_halt(True)
            self._fw.clear_halt(False)
            self._resets_seen = getattr(self._fw, "resets", 0)
        return True

    def _roll(self, kind: str) -> bool:
        p = self.plan.rate(kind)
        if p > 0 and self._rng.random() < p:
            self.injected[kind] += 1
            _log.debug("injecting %s", kind)
            return True
        return False

    # ------------------------------------------------------------------ bytes in
    def write(self, data: bytes | bytearray | memoryview) -> None:
        data = bytes(data)
        if self._tick_gone() or not data:
            return
        if self._deaf:  # stream "stall": only the reset frame is heard
            joined = self._deaf_tail + data
            idx = joined.rfind(P.STREAM_RESET)
            if idx < 0:
                self._deaf_tail = joined[-(len(P.STREAM_RESET) - 1):]
                return
            self._clear_link()
            self._fw.bulk_only_reset()
            self._resets_seen = getattr(self._fw, "resets", 0)
            data = joined[idx + len(P.STREAM_RESET):]
            if not data:
                return
        if self._swallow:  # data-out of a faked command: the device takes it and drops it
            take = min(self._swallow, len(data))
            self._swallow -= take
            data = data[take:]
            if not data:
                return
        cbw = self._as_idle_cbw(data)
        if cbw is not None and self._intercept(cbw):
            return
        if cbw is not None:
            self._fake_sense = None
        self._fw.write(data)
        resets = getattr(self._fw, "resets", 0)
        if resets != self._resets_seen:  # an in-band reset frame went through
            self._resets_seen = resets
            self._clear_link()
        self._note_block()

    def _as_idle_cbw(self, data: bytes) -> P.Cbw | None:
        """The CBW in ``data`` when it is exactly one, arriving at a command boundary, else None."""
        if len(data) != P.CBW.size or getattr(self._fw, "_phase", "cbw") != "cbw" or self.pending():
            return None
        try:
            return P.decode_cbw(data)
        except P.ProtocolError:
            return None

    def _intercept(self, cbw: P.Cbw) -> bool:
        """Fake the command's outcome (True: the firmware never sees it)."""
        if cbw.opcode == P.Op.REQUEST_SENSE and self._fake_sense is not None:
            sense, self._fake_sense = self._fake_sense, None
            self._reply(cbw, P.encode_sense(sense)[:cbw.data_length], P.CswStatus.PASSED)
            return True
        if cbw.opcode == P.Op.REQUEST_SENSE:
            return False
        if self._roll("check_condition"):
            self._fake_sense = TRANSIENT_SENSES[int(self._rng.integers(len(TRANSIENT_SENSES)))]
            self._reply(cbw, b"", P.CswStatus.FAILED)
            return True
        if self._roll("phase_error"):
            self._fake_sense = None
            self._reply(cbw, b"", P.CswStatus.PHASE_ERROR)
            return True
        if self._roll("stall"):
            if self.packetized:
                self._fw.write(cbw_bytes(cbw))
                self._note_block()
                self._stall_in = True  # the first IN transfer (data stage, else status stage) answers STALL
                return True
            self._deaf = True
            return True
        return False

    def _reply(self, cbw: P.Cbw, data: bytes, status: int) -> None:
        """Queue the data phase and CSW of a faked command (firmware conventions for each link)."""
        H = cbw.data_length
        if cbw.data_in and H > 0:
            if self.packetized:
                if data:
                    self._fake.append(bytes(data))
                else:
                    self._stall_in = True
            else:
                self._fake.append(bytes(data) + bytes(H - len(data)))
            residue = H - len(data)
        else:
            residue = H
        if not cbw.data_in and H > 0:
            self._swallow = H  # the host still sends its data-out bytes: take and drop exactly H
        self._fake.append(P.encode_csw(cbw.tag, residue, status))

    # ------------------------------------------------------------------ bytes out
    def read(self, max_len: int) -> bytes:
        if self._tick_gone():
            return b""
        if max_len <= 0 or self.halted_in:
            return b""
        data = self._next(max_len)
        if not data:
            return b""
        if self._roll("disconnect"):
            self._gone = max(1, int(self.plan.gone_calls))
            _log.info("injected disconnect: the device vanishes for %d link calls", self._gone)
            return b""  # the transfer in flight is lost
        if self._roll("slow"):
            time.sleep(self.plan.slow_s)
        if len(data) > 1 and self._roll("short_transfer"):
            data = data[:int(self._rng.integers(1, len(data)))]
        if self._roll("garbage"):
            junk = self._rng.integers(0, 256, int(self._rng.integers(1, 65)), dtype=np.uint8).tobytes()
            if self.packetized:
                self._front = data + self._front
                return junk[:max_len]
            joined = junk + data
            self._front = joined[max_len:] + self._front
            return joined[:max_len]
        return data

    def _next(self, max_len: int) -> bytes:
        """The next device->host bytes: pushed-back bytes, faked replies, then the firmware's."""
        if self._front:
            if self.packetized:
                out, self._front = self._front[:max_len], self._front[max_len:]
                return out
            out = self._front[:max_len]
            self._front = self._front[max_len:]
            if len(out) < max_len:
                out += self._drain(max_len - len(out))
            return out
        return self._drain(max_len)

    def _drain(self, max_len: int) -> bytes:
        if self._fake:
            if self.packetized:
                head = self._fake.popleft()
                if len(head) > max_len:
                    self._fake.appendleft(head[max_len:])
                return head[:max_len]
            parts = []
            left = max_len
            while self._fake and left > 0:
                head = self._fake.popleft()
                if len(head) > left:
                    self._fake.appendleft(head[left:])
                    head = head[:left]
                parts.append(head)
                left -= len(head)
            return b"".join(parts)
        return self._fw.read(max_len)

    # ------------------------------------------------------------------ ground truth
    def _note_block(self) -> None:
        """Remember the CRC-32 of each new block's counts (as a recording would store it)."""
        seq = getattr(self._fw, "_sequence", None)
        block = getattr(self._fw, "_block", None)
        if block is None or seq is None or seq == self._last_seq:
            return
        self._last_seq = seq
        n_ch = block[1]
        off = P.BLOCK_HEADER.size + 8 * n_ch
        self.block_crc[int(seq)] = int(zlib.crc32(bytes(block[off:])) & 0xFFFFFFFF)


def cbw_bytes(cbw: P.Cbw) -> bytes:
    """The wire bytes of a decoded CBW."""
    return P.encode_cbw(cbw.tag, cbw.data_length, cbw.data_in, cbw.cdb, cbw.lun)
