"""The bulk-only link of the simulated analyser: CBW / data / CSW framing, both link flavours.

:class:`BulkOnlyLink` is the byte-level state machine described in :mod:`simulator.firmware`
(USB bulk endpoints when ``packetized``, else a byte stream with in-band reset frames). It knows
nothing of what the commands do: a subclass supplies :meth:`BulkOnlyLink._decode` (CBW -> table
row, CDB fields, an early failure) and :meth:`BulkOnlyLink._run` (execute one command -> a
:class:`Reply`). The link decides the bulk-only cases (phase errors, residues, stalls) and keeps
the sense data of the last command.
"""

from __future__ import annotations

import collections
import logging
from dataclasses import dataclass

from acquisition import protocol as P

__all__ = ["BulkOnlyLink", "Reply", "fail", "GOOD_SENSE", "UA_RESET_SENSE"]

_log = logging.getLogger("simulator.firmware")


@dataclass
class Reply:
    """What a command handler produced: CSW status, data-in payload, sense."""

    status: int = P.CswStatus.PASSED
    data: bytes | memoryview = b""
    sense: P.Sense = P.Sense(P.SenseKey.NO_SENSE, 0, 0)


GOOD_SENSE = P.Sense(P.SenseKey.NO_SENSE, 0, 0)
UA_RESET_SENSE = P.Sense(P.SenseKey.UNIT_ATTENTION, *P.ASC_POWER_ON_RESET)
_GOOD = GOOD_SENSE


def fail(key: int, asc: tuple[int, int]) -> Reply:
    """A failed command's reply with sense ``key`` / ``asc`` (ASC, ASCQ)."""
    return Reply(P.CswStatus.FAILED, b"", P.Sense(key, *asc))


class BulkOnlyLink:
    """The link state machine; subclasses provide ``_decode`` and ``_run`` (see the module docstring).

    Subclass ``__init__`` sets :attr:`packetized` and calls :meth:`_power_on`; counters
    ``commands_executed`` and ``resets`` count for tests and benchmarks.
    """

    packetized: bool = False
    commands_executed: int = 0
    resets: int = 0

    def _decode(self, cbw: P.Cbw) -> tuple[P.CommandSpec | None, dict[str, int], Reply | None]:
        """(table row or None, CDB fields, a failure Reply or None when the command may run)."""
        raise NotImplementedError

    def _run(self, spec: P.CommandSpec, fields: dict[str, int], data: bytes) -> Reply:
        """Execute one decoded command with its data-out bytes."""
        raise NotImplementedError

    def _on_reset(self) -> None:
        """Hook: what a bulk-only reset does beyond the link (the device's own state)."""

    # ------------------------------------------------------------------ link-level state
    def _power_on(self) -> None:
        self._inbuf = bytearray()
        self._tail = b""
        self._out: collections.deque[memoryview] = collections.deque()
        self._phase = "cbw"  # cbw | data_out | discard (stream, bad CBW) | invalid (packetized, bad CBW)
        self._cbw: P.Cbw | None = None
        self._need_out = 0
        self._halted_in = False
        self._halted_out = False
        self._sense = _GOOD
        self._unit_attention = True

    @property
    def halted_in(self) -> bool:
        """The bulk IN endpoint answers STALL (packetized mode)."""
        return self._halted_in

    @property
    def halted_out(self) -> bool:
        """The bulk OUT endpoint answers STALL (packetized mode)."""
        return self._halted_out

    def pending(self) -> int:
        """Bytes waiting to be read (0 while the IN endpoint is halted)."""
        return 0 if self._halted_in else sum(len(m) for m in self._out)

    def bulk_only_reset(self) -> None:
        """Bulk-only mass storage reset: abandon the command in progress and all queued bytes, leave
        the invalid-CBW state, abandon an armed capture, raise UNIT ATTENTION. The set-up and a
        ready block are kept. Endpoint halts stay until :meth:`clear_halt` (as on USB)."""
        self.resets += 1
        self._inbuf = bytearray()
        self._tail = b""
        self._out.clear()
        self._phase = "cbw"
        self._cbw = None
        self._need_out = 0
        self._on_reset()
        self._sense = _GOOD
        self._unit_attention = True
        _log.debug("bulk-only reset")

    def clear_halt(self, direction_in: bool) -> None:
        """CLEAR_FEATURE(ENDPOINT_HALT). Ignored while an invalid CBW awaits reset recovery."""
        if self._phase == "invalid":
            return
        if direction_in:
            self._halted_in = False
        else:
            self._halted_out = False

    # ------------------------------------------------------------------ bytes in
    def write(self, data: bytes | bytearray | memoryview) -> None:
        """Accept host-to-device bytes (any chunking in stream mode; one OUT transfer when packetized)."""
        data = bytes(data)
        if not data:
            return
        if self.packetized:
            if self._halted_out:
                _log.debug("OUT endpoint halted: %d bytes dropped", len(data))
                return
            self._write_packet(data)
            return
        joined = self._tail + data
        idx = joined.rfind(P.STREAM_RESET)
        if idx >= 0:  # the last reset frame wins: everything before it is abandoned
            self.bulk_only_reset()
            data = joined[idx + len(P.STREAM_RESET):]
        self._tail = (self._tail + data)[-(len(P.STREAM_RESET) - 1):]
        if self._phase == "discard" or not data:
            return
        self._inbuf += data
        self._consume_stream()

    def _consume_stream(self) -> None:
        buf = self._inbuf
        pos = 0
        while True:
            if self._phase == "cbw":
                if len(buf) - pos < P.CBW.size:
                    break
                raw = bytes(buf[pos:pos + P.CBW.size])
                pos += P.CBW.size
                if not self._accept_cbw(raw):
                    pos = len(buf)
                    break
            elif self._phase == "data_out":
                take = min(self._need_out, len(buf) - pos)
                if take == 0:
                    break
                self._out_data += buf[pos:pos + take]
                pos += take
                self._need_out -= take
                if self._need_out == 0:
                    self._finish_data_out()
            else:  # discard
                pos = len(buf)
                break
        del buf[:pos]

    def _write_packet(self, data: bytes) -> None:
        if self._phase == "cbw":
            if len(data) != P.CBW.size:
                self._invalid_cbw(f"an OUT transfer of {len(data)} bytes where a 31-byte CBW was due")
                return
            self._accept_cbw(data)
        elif self._phase == "data_out":
            if len(data) > self._need_out:
                self._invalid_cbw(f"{len(data)} bytes of data-out where {self._need_out} were due")
                return
            self._out_data += data
            self._need_out -= len(data)
            if self._need_out == 0:
                self._finish_data_out()

    def _invalid_cbw(self, why: str) -> None:
        _log.debug("invalid CBW: %s", why)
        if self.packetized:
            self._phase = "invalid"
            self._halted_in = self._halted_out = True
        else:
            self._phase = "discard"

    def _accept_cbw(self, raw: bytes) -> bool:
        try:
            cbw = P.decode_cbw(raw)
        except P.ProtocolError as exc:
            self._invalid_cbw(str(exc))
            return False
        self._cbw = cbw
        if cbw.data_length and not cbw.data_in:
            self._phase = "data_out"
            self._need_out = cbw.data_length
            self._out_data = bytearray()
        else:
            self._execute(cbw, b"")
        return True

    def _finish_data_out(self) -> None:
        cbw = self._cbw
        data = bytes(self._out_data)
        self._out_data = bytearray()
        self._phase = "cbw"
        assert cbw is not None
        self._execute(cbw, data)

    # ------------------------------------------------------------------ command execution
    def _execute(self, cbw: P.Cbw, out_data: bytes) -> None:
        self._phase = "cbw"
        self.commands_executed += 1
        spec, fields, reply = self._decode(cbw)
        H = cbw.data_length
        # device intent for data-out: the parameter list length
        d_out = spec.data_length(fields) if spec is not None and spec.direction is P.Direction.OUT else 0
        # phase errors decided before execution (the command is not run): Hn < Do, Hi <> Do, Ho <> Di, Ho < Do
        if spec is not None and ((H == 0 and d_out > 0)
                                 or (H > 0 and cbw.data_in and spec.direction is P.Direction.OUT)
                                 or (H > 0 and not cbw.data_in and spec.direction is P.Direction.IN)
                                 or (H > 0 and not cbw.data_in and H < d_out)):
            self._respond_phase_error(cbw)
            return
        if reply is None:
            assert spec is not None
            reply = self._run(spec, fields, out_data[:d_out])
        if spec is None or spec.opcode != P.Op.REQUEST_SENSE:
            self._sense = reply.sense
        d_in = len(reply.data)
        if cbw.data_in and H > 0:
            if d_in > H:  # case 7: the host expects less than the device has
                self._queue(memoryview(reply.data)[:H])
                self._queue_csw(cbw.tag, 0, P.CswStatus.PHASE_ERROR)
                return
            self._send_in(reply.data, H, stall=(d_in == 0))  # cases 4, 5, 6
            self._queue_csw(cbw.tag, H - d_in, reply.status)
        elif H == 0 and d_in > 0:  # case 2: host expects no data, device has some
            self._queue_csw(cbw.tag, 0, P.CswStatus.PHASE_ERROR)
        else:  # case 1 (Hn = Dn) or data-out consumed (cases 9, 11, 12)
            residue = H - d_out if (reply.status == P.CswStatus.PASSED and H) else H
            self._queue_csw(cbw.tag, residue, reply.status)

    def _respond_phase_error(self, cbw: P.Cbw) -> None:
        self._sense = _GOOD
        if cbw.data_in and cbw.data_length:
            self._send_in(b"", cbw.data_length, stall=True)
        self._queue_csw(cbw.tag, cbw.data_length, P.CswStatus.PHASE_ERROR)

    def _send_in(self, data: bytes | memoryview, H: int, stall: bool) -> None:
        """Data-in phase of at most H bytes (case 4/5/6)."""
        if self.packetized:
            if len(data):
                self._queue(memoryview(data))  # a short one ends the transfer (short packet)
            elif stall:
                self._halted_in = True
        else:
            if len(data):
                self._queue(memoryview(data))
            if H > len(data):
                self._queue(memoryview(bytes(H - len(data))))

    def _queue(self, mv: memoryview) -> None:
        if len(mv):
            self._out.append(mv)

    def _queue_csw(self, tag: int, residue: int, status: int) -> None:
        self._out.append(memoryview(P.encode_csw(tag, residue, status)))

    # ------------------------------------------------------------------ bytes out
    def read(self, max_len: int) -> bytes:
        """Pending device-to-host bytes, at most ``max_len`` (``b""`` when none or IN halted).

        Packetized: at most one transfer (data phase or CSW). Stream: as much as is queued.
        """
        if self._halted_in or not self._out or max_len <= 0:
            return b""
        out = self._out
        if self.packetized or len(out[0]) >= max_len:
            head = out[0]
            if len(head) <= max_len:
                out.popleft()
                return bytes(head)
            out[0] = head[max_len:]
            return bytes(head[:max_len])
        parts = []
        left = max_len
        while out and left > 0:
            head = out[0]
            if len(head) <= left:
                parts.append(head)
                out.popleft()
                left -= len(head)
            else:
                parts.append(head[:left])
                out[0] = head[left:]
                left = 0
        return b"".join(parts)
