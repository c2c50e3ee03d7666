"""Host side of the bulk-only envelope (CBW, data phase, CSW) over any :class:`Transport`.

One :meth:`BulkOnly.command` call is one SCSI command:

1. the CDB is built and validated from the command table (``acquisition.protocol``) before
   anything is written; the CBW carries a fresh tag (incrementing, 32-bit wrap);
2. data-out is written, or the data-in phase read: a packetised link ends it early with a short
   transfer; a stream link always delivers the full announced length (zero padded); a stalled IN
   endpoint is cleared and the status read next;
3. the CSW is read and checked: signature, tag, residue <= announced length, and that the bytes
   that arrived cover the ``length - residue`` the device claims to have sent.

Status handling:

* **1 (failed)**: REQUEST SENSE, then :class:`CommandFailed` with the sense key, ASC and ASCQ and
  a message naming them and what to do. A UNIT ATTENTION (the device was reset or powered on;
  the command was *not* executed) is retried once, as SCSI hosts do; so is an idempotent command
  that met a transient condition (ABORTED COMMAND, NOT READY "becoming ready" 0x04/0x01).
* **2 (phase error)**, bad signature, wrong tag, impossible residue: reset recovery
  (``transport.reset_recovery()``), then one retry when the command is *idempotent*
  (``CommandSpec.idempotent``: TEST UNIT READY, INQUIRY, GET CAPABILITIES, SET UP, GET SET-UP,
  GET STATUS, READ BLOCK, ABORT: running them twice leaves the analyser as running them once;
  ARM and REQUEST SENSE are not), else :class:`ProtocolError`.
* a stalled OUT endpoint (the device met an invalid CBW): reset recovery, then as for a phase error;
* a timeout mid-command: reset recovery (best effort), then :class:`TransportTimeout`;
  the device gone: :class:`DeviceGone` naming the command.

Every wait is bounded: each command has a deadline (``timeout_s``), each transport call gets
the time left, and the data phase loop ends after at most ``length`` bytes.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass

from acquisition import protocol as P
from acquisition.errors import CommandFailed, DeviceGone, EndpointStalled, ProtocolError, TransportError, TransportTimeout
from acquisition.transport import Transport

__all__ = ["BulkOnly", "Response"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Response:
    """Result of a passed command: the valid data-in bytes (``length - residue``) and the residue."""

    data: bytes
    residue: int


class _Retry(Exception):
    """Internal: the attempt ended in reset recovery and may be retried."""

    def __init__(self, error: Exception) -> None:
        super().__init__(str(error))
        self.error = error


def _transient(exc: CommandFailed) -> bool:
    """A CHECK CONDITION that says "not run this time, try again": ABORTED COMMAND (any ASC) or
    NOT READY with ASC/ASCQ 0x04/0x01 (becoming ready)."""
    return exc.sense_key == P.SenseKey.ABORTED_COMMAND or (
        exc.sense_key == P.SenseKey.NOT_READY and (exc.asc, exc.ascq) == (0x04, 0x01))


class BulkOnly:
    """The bulk-only protocol over ``transport``; ``timeout_s`` bounds each command."""

    def __init__(self, transport: Transport, timeout_s: float = 2.0, *, first_tag: int = 1,
                 retry_unit_attention: bool = True) -> None:
        if timeout_s <= 0:
            raise ValueError(f"timeout_s must be positive, got {timeout_s}")
        self.transport = transport
        self.timeout_s = float(timeout_s)
        self.retry_unit_attention = retry_unit_attention
        self._tag = int(first_tag) & 0xFFFFFFFF
        self.recoveries = 0

    @property
    def url(self) -> str:
        return getattr(self.transport, "url", "") or "the analyser"

    def next_tag(self) -> int:
        tag = self._tag
        self._tag = (self._tag + 1) & 0xFFFFFFFF
        return tag

    # ------------------------------------------------------------------ public
    def command(self, opcode: int | str, *, data_out: bytes = b"", length: int = 0,
                timeout_s: float | None = None, **fields: int) -> Response:
        """Run one command. ``length``: data-in bytes asked for (IN commands; also put in the CDB's
        allocation-length field unless given); ``data_out``: parameter data (OUT commands; its
        length goes in the CDB). Returns :class:`Response`; raises as described in the module docstring."""
        spec = P.command_spec(opcode)
        if spec.direction is P.Direction.OUT:
            fields.setdefault("length", len(data_out))
            host_len = len(data_out)
        elif spec.direction is P.Direction.IN:
            if "length" in spec.fields:
                fields.setdefault("length", length)
            host_len = length
        else:
            host_len = 0
        if data_out and spec.direction is not P.Direction.OUT:
            raise ValueError(f"{spec.name} takes no data-out")
        cdb = P.build_cdb(spec.opcode, **fields)  # validates every field before writing
        budget = self.timeout_s if timeout_s is None else float(timeout_s)
        retries_phase = 1 if spec.idempotent else 0
        retries_ua = 1 if self.retry_unit_attention else 0
        retries_transient = 1
        while True:
            try:
                return self._attempt(spec, cdb, host_len, data_out, budget)
            except _Retry as r:
                if retries_phase <= 0:
                    raise r.error from None
                retries_phase -= 1
                retries_ua = 1 if self.retry_unit_attention else 0  # the reset raises a fresh unit attention
                _log.info("%s: retrying %s once after reset recovery (%s)", self.url, spec.name, r.error)
            except CommandFailed as exc:
                if exc.sense_key == P.SenseKey.UNIT_ATTENTION and retries_ua > 0:
                    retries_ua -= 1
                    _log.info("%s: %s met a unit attention (device reset); retrying once", self.url, spec.name)
                    continue
                if spec.idempotent and retries_transient > 0 and _transient(exc):
                    retries_transient -= 1
                    _log.info("%s: %s was not run (%s); retrying once", self.url, spec.name, exc)
                    continue
                raise

    def request_sense(self, timeout_s: float | None = None) -> P.Sense:
        """REQUEST SENSE (18 bytes); a failure of REQUEST SENSE itself is a ProtocolError."""
        budget = self.timeout_s if timeout_s is None else timeout_s
        spec = P.command_spec(P.Op.REQUEST_SENSE)
        cdb = P.build_cdb(P.Op.REQUEST_SENSE, length=18)
        try:
            data, csw = self._transaction(spec, cdb, 18, b"", time.monotonic() + budget)
        except _Retry as r:
            raise r.error from None
        if csw.status != P.CswStatus.PASSED:
            self._recover(f"REQUEST SENSE ended with status {csw.status}")
            raise ProtocolError(f"{self.url}: REQUEST SENSE itself failed (status {csw.status}); the link was reset, "
                                "try the command again")
        return P.decode_sense(data[:18 - csw.residue])

    # ------------------------------------------------------------------ one attempt
    def _attempt(self, spec: P.CommandSpec, cdb: bytes, host_len: int, data_out: bytes, budget: float) -> Response:
        deadline = time.monotonic() + budget
        data, csw = self._transaction(spec, cdb, host_len, data_out, deadline)
        if csw.status == P.CswStatus.PHASE_ERROR:
            raise _Retry(self._recover(f"{spec.name} ended with a phase error (status 2)"))
        if csw.status == P.CswStatus.FAILED:
            sense = self.request_sense(max(deadline - time.monotonic(), 0.1 * budget))
            raise CommandFailed(f"{self.url}: {spec.name} failed: {sense.describe()}", opcode=spec.opcode,
                                sense_key=sense.key, asc=sense.asc, ascq=sense.ascq)
        valid = host_len - csw.residue if spec.direction is P.Direction.IN else 0
        return Response(bytes(data[:valid]), csw.residue)

    def _transaction(self, spec: P.CommandSpec, cdb: bytes, host_len: int, data_out: bytes,
                     deadline: float) -> tuple[bytes, P.Csw]:
        """CBW, data phase, CSW; raises _Retry after reset recovery for an envelope fault."""
        tag = self.next_tag()
        data_in = spec.direction is P.Direction.IN
        cbw = P.encode_cbw(tag, host_len, data_in, cdb)
        _log.debug("%s: %s tag %d length %d", self.url, spec.name, tag, host_len)
        t = self.transport
        try:
            try:
                t.write(cbw, self._left(deadline, spec))
                if data_out:
                    t.write(data_out, self._left(deadline, spec))
            except EndpointStalled as exc:  # the device refuses commands until reset recovery
                raise _Retry(self._recover(f"{spec.name}: the OUT endpoint is stalled ({exc})")) from None
            data = self._read_data(host_len, deadline, spec) if data_in and host_len else b""
            raw = self._read_csw(deadline, spec)
        except DeviceGone as exc:
            raise DeviceGone(f"{self.url}: the analyser went away during {spec.name} ({exc}); check the cable or "
                             "server, then open the device again") from exc
        except TransportTimeout as exc:
            self._recover_quietly(f"timeout in {spec.name}")
            raise TransportTimeout(f"{self.url}: no answer to {spec.name} within its time limit ({exc}); the link "
                                   "was reset; check that the analyser is on and the URL is right") from exc
        try:
            csw = P.decode_csw(raw)
        except ProtocolError as exc:
            raise _Retry(self._recover(f"{spec.name}: {exc}")) from None
        if csw.tag != tag:
            raise _Retry(self._recover(f"{spec.name}: status carries tag {csw.tag}, the command was sent with tag {tag}"))
        if csw.residue > host_len:
            raise _Retry(self._recover(f"{spec.name}: residue {csw.residue} exceeds the {host_len} bytes announced"))
        if data_in and csw.status == P.CswStatus.PASSED and host_len - csw.residue > len(data):
            raise _Retry(self._recover(
                f"{spec.name}: short transfer: {len(data)} bytes arrived, the device reports sending "
                f"{host_len - csw.residue}"))
        return data, csw

    def _left(self, deadline: float, spec: P.CommandSpec) -> float:
        left = deadline - time.monotonic()
        if left <= 0:
            raise TransportTimeout(f"{spec.name} ran out of time")
        return left

    def _read_data(self, n: int, deadline: float, spec: P.CommandSpec) -> bytes:
        t = self.transport
        if not t.packetized:
            return t.read(n, self._left(deadline, spec))
        buf = bytearray()
        while len(buf) < n:
            want = n - len(buf)
            try:
                chunk = t.read(want, self._left(deadline, spec))
            except EndpointStalled:
                t.clear_halt(True)
                break
            if not chunk:
                break
            buf += chunk
            if len(chunk) < want:  # short transfer: the data phase ended
                break
        return bytes(buf)

    def _read_csw(self, deadline: float, spec: P.CommandSpec) -> bytes:
        t = self.transport
        try:
            return t.read(P.CSW.size, self._left(deadline, spec))
        except EndpointStalled:
            t.clear_halt(True)  # BOT: a stalled status stage is cleared and read once more
            return t.read(P.CSW.size, self._left(deadline, spec))

    # ------------------------------------------------------------------ recovery
    def _recover(self, why: str) -> ProtocolError:
        """Reset recovery; returns the ProtocolError to raise."""
        self.recoveries += 1
        _log.warning("%s: %s; reset recovery", self.url, why)
        try:
            self.transport.reset_recovery(min(self.timeout_s, 2.0))
        except TransportError as exc:
            return ProtocolError(f"{self.url}: {why}; reset recovery failed too ({exc}); close and reopen the device")
        return ProtocolError(f"{self.url}: {why}; the link was reset (reset recovery), repeat the operation")

    def _recover_quietly(self, why: str) -> None:
        try:
            self.transport.reset_recovery(min(self.timeout_s, 1.0))
            self.recoveries += 1
        except TransportError as exc:
            _log.warning("%s: reset recovery after %s failed: %s", self.url, why, exc)
