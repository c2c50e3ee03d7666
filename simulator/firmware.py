"""The simulated analyser's firmware: a byte-level state machine (bytes in, bytes out).

The host writes bulk-only command block wrappers (CBW), optional data-out, and reads data-in
and command status wrappers (CSW), all laid out by :mod:`acquisition.protocol`. Commands run
synchronously inside :meth:`Firmware.write`; their replies wait in an output queue that
:meth:`Firmware.read` drains.

Two link flavours
-----------------
* ``packetized=True`` (USB bulk endpoints): each ``write`` is one OUT transfer, each ``read``
  returns at most one IN transfer (a data phase or a CSW; never both), so a data phase shorter
  than the host asked for ends with a short packet. A command that fails while the host expects
  data-in stalls the IN endpoint (the CSW follows after ``clear_halt(True)``); an invalid CBW
  stalls both endpoints until :meth:`bulk_only_reset` (then the host clears both halts).
  The transport checks :attr:`halted_in` / :attr:`halted_out` before each transfer (a halted
  endpoint answers STALL): ``read`` returns ``b""`` and ``write`` drops data while halted.
* ``packetized=False`` (serial, TCP, pty): the firmware always sends exactly the host's
  announced data-in length (zero padded) and reports the residue in the CSW. An invalid CBW makes
  the firmware discard all input until :data:`acquisition.protocol.STREAM_RESET` arrives; that
  frame is recognised anywhere in the input and acts as the bulk-only mass storage reset.

Bulk-only cases (host expectation H vs device intent D, USB MSC BOT 1.0 section 6.7):
Hn with Di/Do -> phase error (2); Hi with Do, Ho with Di -> phase error; Hi < Di -> the first
Hi bytes, then phase error; Ho < Do -> phase error (command not executed); Hi > Di, Ho > Do ->
residue H - D.

SCSI behaviour
--------------
Sense data of the last command is kept for REQUEST SENSE (a passing command clears it). After
power-on and after every reset a UNIT ATTENTION (0x06, ASC 0x29) is pending: the next command
other than INQUIRY and REQUEST SENSE fails with it (and is not executed); REQUEST SENSE reports
and clears it. Unsupported opcode -> ILLEGAL REQUEST/0x20; a CDB field out of range ->
ILLEGAL REQUEST/0x24; a set-up outside the capabilities -> ILLEGAL REQUEST/0x26 (0x1A for a bad
length, or a channel point the test stand refuses); LUN other than 0 -> ILLEGAL REQUEST/0x25;
ARM or GET SET-UP before SET UP -> NOT READY/0x04/0x80; READ BLOCK with no block ready ->
NOT READY/0x04/0x81; SET UP while armed -> NOT READY/0x04/0x82; a stand that fails to strike (or
no stand) -> HARDWARE ERROR/0x44. A reset abandons an armed capture but keeps the set-up and a
ready block, so an idempotent READ BLOCK can be repeated after reset recovery.

Capture
-------
ARM moves to ``ARMED``. The simulated operator strikes the frame when the host polls: GET STATUS
number ``strike_after_polls + 1`` after ARM (default 1, so one poll sees "armed"; 0 strikes at
ARM) calls ``stand.strike(fs, n + margin, pretrigger)``, filters every channel with the
front end's anti-alias filter, digitises it (``simulator.frontend.quantize``), searches the
trigger channel for the first crossing of the trigger level with the set slope at or after
sample ``pretrigger``, and keeps ``n`` samples starting ``pretrigger`` samples before the
crossing. A strike whose record never crosses the level leaves the state ``ARMED`` with the
``no trigger`` flag; the operator strikes again after as many polls, at most
``max_strikes`` times per ARM (then the host's wait times out). The ``TRIGGERED`` state is never
observed: a simulated capture is instantaneous.

SET UP hands the stand its channels (:class:`StandChannel` dicts: point, quantity, sensitivity in
V per SI unit with unit ``"V/EU"``, IEPE, coupling, range) and aims the operator's hammer at the
force channel's point (``stand.set_hammer_point``), so a roving-hammer test moves the hammer by
changing the set-up. The stand models everything up to the analyser's anti-alias filter (sensors,
IEPE, input AC coupling).

Speed: block images are built once per strike with ``numpy.tobytes`` and served as
``memoryview`` slices (no per-byte Python work); a stand whose event carries
``info["cache_key"]`` (:class:`PrecomputedStand`) has its digitised block reused.
"""
from __future__ import annotations

import collections
import logging
from dataclasses import dataclass
from typing import Any, Mapping, Protocol, Sequence

import numpy as np

from acquisition import protocol as P

__all__ = ["Firmware", "Reply", "StandLike", "StandChannel", "PrecomputedStand", "IDENTITY"]

_log = logging.getLogger(__name__)

#: vendor, product, revision reported by INQUIRY (and the default serial number, VPD page 0x80)
IDENTITY = P.Inquiry(P.DEVICE_TYPE_PROCESSOR, "IMPACTLB", "SIGLAB-SIM 2042", "0100")
DEFAULT_SERIAL = "SL2042-0000001"


class StandLike(Protocol):
    """What the firmware needs from a test stand (``simulator.stand.TestStand``)."""

    def set_channels(self, channels: Sequence[Any]) -> None: ...

    def strike(self, fs_hz: float, n_samples: int, pretrigger: int) -> Any: ...


@dataclass
class Reply:
    """What a command handler produced: CSW status, data-in payload, sense."""

    status: int = P.CswStatus.PASSED
    data: "bytes | memoryview" = b""
    sense: P.Sense = P.Sense(P.SenseKey.NO_SENSE, 0, 0)


_GOOD = P.Sense(P.SenseKey.NO_SENSE, 0, 0)
_UA_RESET = P.Sense(P.SenseKey.UNIT_ATTENTION, *P.ASC_POWER_ON_RESET)


def _fail(key: int, asc: "tuple[int, int]") -> Reply:
    return Reply(P.CswStatus.FAILED, b"", P.Sense(key, *asc))


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
    def from_record(cls, rec: P.ChannelRecord) -> "StandChannel":
        return cls(point=rec.point, quantity=rec.quantity, sensitivity=rec.sensitivity, sensitivity_unit="V/EU",
                   iepe=rec.iepe, coupling=rec.coupling, range_v=rec.range_mv / 1000.0, input=rec.input)


@dataclass(frozen=True)
class _Event:
    volts: np.ndarray
    info: dict


class Firmware:
    """The analyser's firmware (see the module docstring for the behaviour).

    ``stand``: the simulated operator + frame (``set_channels``, ``strike``); ``packetized``: USB
    bulk behaviour (True) or byte stream (False); ``strike_after_polls``: GET STATUS polls
    answered "armed" before the operator strikes; ``max_strikes``: strikes per ARM when the
    trigger level is never crossed; ``margin``: extra samples requested from the stand beyond the
    block (room for the trigger to land late).
    """

    def __init__(self, stand: "StandLike | None" = None, *, packetized: bool = False,
                 serial: str = DEFAULT_SERIAL, capabilities: P.CapabilitiesData = P.SIGLAB_2042,
                 strike_after_polls: int = 1, max_strikes: int = 3, margin: int = 1024,
                 identity: P.Inquiry = IDENTITY) -> None:
        if strike_after_polls < 0 or max_strikes < 1 or margin < 0:
            raise ValueError("strike_after_polls and margin must be >= 0 and max_strikes >= 1")
        self.stand = stand
        self.packetized = bool(packetized)
        self.serial = serial
        self.capabilities = capabilities
        self.identity = identity
        self.strike_after_polls = int(strike_after_polls)
        self.max_strikes = int(max_strikes)
        self.margin = int(margin)
        self._caps_bytes = P.encode_capabilities(capabilities)
        self._inquiry_bytes = P.encode_inquiry(identity)
        self._handlers = {
            P.Op.TEST_UNIT_READY: self._test_unit_ready, P.Op.REQUEST_SENSE: self._request_sense,
            P.Op.INQUIRY: self._inquiry, P.Op.GET_CAPABILITIES: self._get_capabilities,
            P.Op.SET_UP: self._set_up, P.Op.GET_SET_UP: self._get_set_up, P.Op.ARM: self._arm,
            P.Op.GET_STATUS: self._get_status, P.Op.READ_BLOCK: self._read_block, P.Op.ABORT: self._abort,
        }
        # acquisition state (survives a bulk-only reset, except an armed capture)
        self._setup: "P.SetupData | None" = None
        self._setup_bytes = b""
        self._state = P.State.IDLE
        self._sequence = 0
        self._block: "bytes | None" = None
        self._overload_mask = 0
        self._polls = 0
        self._strikes = 0
        self._no_trigger = False
        self._clock_s = 0.0
        self._cache: "tuple[Any, bytes, int] | None" = None
        self._fe_cfg: Any = None
        # counters for tests and benchmarks
        self.commands_executed = 0
        self.resets = 0
        self._power_on()

    # ------------------------------------------------------------------ link-level state
    def _power_on(self) -> None:
        self._inbuf = bytearray()
        self._tail = b""
        self._out: collections.deque[memoryview] = collections.deque()
        self._phase = "cbw"  # cbw | data_out | discard (stream, bad CBW) | invalid (packetized, bad CBW)
        self._cbw: "P.Cbw | None" = None
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

    @property
    def state(self) -> P.State:
        """The acquisition state (for tests and servers)."""
        return self._state

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
        if self._state == P.State.ARMED:
            self._state = P.State.IDLE
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
    def write(self, data: "bytes | bytearray | memoryview") -> None:
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
            reply = self._handlers[spec.opcode](fields, out_data[:d_out])
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

    def _decode(self, cbw: P.Cbw) -> "tuple[P.CommandSpec | None, dict[str, int], Reply | None]":
        """(table row or None, CDB fields, a failure Reply or None when the command may run).

        Order of checks: unsupported opcode (0x20), CDB too short (0x24), LUN other than 0 (0x25),
        pending UNIT ATTENTION (except INQUIRY and REQUEST SENSE), CDB field validation (0x24)."""
        spec = P.COMMANDS.get(cbw.opcode)
        if spec is None:
            return None, {}, _fail(P.SenseKey.ILLEGAL_REQUEST, P.ASC_INVALID_OPCODE)
        try:
            spec, fields = P.parse_cdb(cbw.cdb)
        except ValueError:
            return None, {}, _fail(P.SenseKey.ILLEGAL_REQUEST, P.ASC_INVALID_FIELD_CDB)
        if cbw.lun != 0:
            return spec, fields, _fail(P.SenseKey.ILLEGAL_REQUEST, P.ASC_LUN_NOT_SUPPORTED)
        if self._unit_attention and spec.opcode not in (P.Op.INQUIRY, P.Op.REQUEST_SENSE):
            self._unit_attention = False
            return spec, fields, Reply(P.CswStatus.FAILED, b"", _UA_RESET)
        err = spec.validate(fields)
        if err:
            _log.debug("%s: %s", spec.name, err)
            return spec, fields, _fail(P.SenseKey.ILLEGAL_REQUEST, P.ASC_INVALID_FIELD_CDB)
        return spec, fields, None

    def _respond_phase_error(self, cbw: P.Cbw) -> None:
        self._sense = _GOOD
        if cbw.data_in and cbw.data_length:
            self._send_in(b"", cbw.data_length, stall=True)
        self._queue_csw(cbw.tag, cbw.data_length, P.CswStatus.PHASE_ERROR)

    def _send_in(self, data: "bytes | memoryview", H: int, stall: bool) -> None:
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

    # ------------------------------------------------------------------ commands
    def _test_unit_ready(self, f: Mapping[str, int], data: bytes) -> Reply:
        return Reply()

    def _request_sense(self, f: Mapping[str, int], data: bytes) -> Reply:
        sense = self._sense
        if self._unit_attention:
            sense = _UA_RESET
            self._unit_attention = False
        self._sense = _GOOD
        return Reply(data=P.encode_sense(sense)[:f["length"]])

    def _inquiry(self, f: Mapping[str, int], data: bytes) -> Reply:
        if not f["evpd"]:
            payload = self._inquiry_bytes
        elif f["page"] == P.VPD_SERIAL_NUMBER:
            payload = P.encode_serial_vpd(self.serial)
        else:
            payload = P.VPD_HEADER.pack(P.DEVICE_TYPE_PROCESSOR, P.VPD_SUPPORTED_PAGES, 0, 2) + bytes(
                [P.VPD_SUPPORTED_PAGES, P.VPD_SERIAL_NUMBER])
        return Reply(data=payload[:f["length"]])

    def _get_capabilities(self, f: Mapping[str, int], data: bytes) -> Reply:
        return Reply(data=self._caps_bytes[:f["length"]])

    def _set_up(self, f: Mapping[str, int], data: bytes) -> Reply:
        if self._state == P.State.ARMED:
            return _fail(P.SenseKey.NOT_READY, P.ASC_NOT_READY_ARMED)
        try:
            setup = P.decode_setup(data)
        except P.ProtocolError as exc:
            _log.debug("SET UP rejected: %s", exc)
            n_declared = data[1] if len(data) >= 2 else -1
            bad_len = len(data) < P.SETUP_HEADER.size or len(data) != P.setup_size(n_declared)
            return _fail(P.SenseKey.ILLEGAL_REQUEST,
                         P.ASC_PARAMETER_LENGTH if bad_len else P.ASC_INVALID_FIELD_PARAM)
        problem = self._check_setup(setup)
        if problem:
            _log.debug("SET UP rejected: %s", problem)
            return _fail(P.SenseKey.ILLEGAL_REQUEST, P.ASC_INVALID_FIELD_PARAM)
        if self.stand is not None:
            try:
                self._give_stand(setup)
            except ValueError as exc:  # e.g. a point that is not on the simulated frame
                _log.info("SET UP rejected by the test stand: %s", exc)
                return _fail(P.SenseKey.ILLEGAL_REQUEST, P.ASC_INVALID_FIELD_PARAM)
        if self.stand is not None:
            from simulator import frontend

            frontend.anti_alias_sos(float(setup.sample_rate_hz), self._frontend_config())  # design once, cached
        self._setup = setup
        self._setup_bytes = P.encode_setup(setup)
        self._state = P.State.IDLE
        self._block = None
        self._cache = None
        return Reply()

    def _give_stand(self, setup: P.SetupData) -> None:
        """Tell the stand the channels; the operator strikes where the force channel's point is."""
        assert self.stand is not None
        self.stand.set_channels([StandChannel.from_record(c) for c in setup.channels])
        force = [c.point for c in setup.channels if c.quantity == "force"]
        aim = getattr(self.stand, "set_hammer_point", None)
        if force and aim is not None:
            aim(force[0])

    def _check_setup(self, s: P.SetupData) -> "str | None":
        caps = self.capabilities
        n = len(s.channels)
        if s.sample_rate_hz not in caps.sample_rates_hz:
            return f"sample rate {s.sample_rate_hz}"
        if s.block_size not in caps.block_sizes:
            return f"block size {s.block_size}"
        if not 1 <= n <= caps.n_inputs:
            return f"{n} channels"
        if not 0 <= s.trigger_channel < n:
            return f"trigger channel {s.trigger_channel}"
        if not 0 <= s.pretrigger < min(s.block_size, caps.max_pretrigger + 1):
            return f"pre-trigger {s.pretrigger}"
        if not np.isfinite(s.trigger_level_v):
            return "trigger level"
        inputs = [c.input for c in s.channels]
        if len(set(inputs)) != n or not all(0 <= i < caps.n_inputs for i in inputs):
            return f"inputs {inputs}"
        for c in s.channels:
            if c.range_mv not in caps.ranges_mv:
                return f"range {c.range_mv} mV"
            if (c.coupling == "AC" and not caps.ac) or (c.coupling == "DC" and not caps.dc):
                return f"coupling {c.coupling}"
            if c.iepe and (not caps.iepe or c.coupling != "AC"):
                return "IEPE needs AC coupling"
            if not (np.isfinite(c.sensitivity) and c.sensitivity > 0):
                return f"sensitivity {c.sensitivity}"
        return None

    def _get_set_up(self, f: Mapping[str, int], data: bytes) -> Reply:
        if self._setup is None:
            return _fail(P.SenseKey.NOT_READY, P.ASC_NOT_READY_SETUP_REQUIRED)
        return Reply(data=self._setup_bytes[:f["length"]])

    def _arm(self, f: Mapping[str, int], data: bytes) -> Reply:
        if self._setup is None:
            return _fail(P.SenseKey.NOT_READY, P.ASC_NOT_READY_SETUP_REQUIRED)
        if self.stand is None:
            return _fail(P.SenseKey.HARDWARE_ERROR, P.ASC_INTERNAL_FAILURE)
        self._state = P.State.ARMED
        self._block = None
        self._polls = 0
        self._strikes = 0
        self._no_trigger = False
        self._overload_mask = 0
        if self.strike_after_polls == 0:
            return self._strike_safely() or Reply()
        return Reply()

    def _strike_safely(self) -> "Reply | None":
        """Strike; a stand that cannot (bad request, broken chain) ends the capture with HARDWARE ERROR."""
        try:
            self._strike()
        except (ValueError, RuntimeError) as exc:
            _log.error("the test stand failed to strike: %s", exc)
            self._state = P.State.IDLE
            return _fail(P.SenseKey.HARDWARE_ERROR, P.ASC_INTERNAL_FAILURE)
        return None

    def _get_status(self, f: Mapping[str, int], data: bytes) -> Reply:
        if self._state == P.State.ARMED:
            self._polls += 1
            if self._polls > self.strike_after_polls and self._strikes < self.max_strikes:
                failed = self._strike_safely()
                if failed is not None:
                    return failed
        n = self.block_samples
        st = P.StatusData(self._state, self._overload_mask, self._setup is not None, self._no_trigger,
                          self._sequence, n if self._state == P.State.BLOCK_READY else 0, self._strikes)
        return Reply(data=P.encode_status(st)[:f["length"]])

    @property
    def block_samples(self) -> int:
        """Samples per channel of the current set-up (0 before SET UP)."""
        return self._setup.block_size if self._setup is not None else 0

    def _read_block(self, f: Mapping[str, int], data: bytes) -> Reply:
        if self._state != P.State.BLOCK_READY or self._block is None:
            return _fail(P.SenseKey.NOT_READY, P.ASC_NOT_READY_NO_BLOCK)
        if f["sequence"] != self._sequence or f["offset"] >= len(self._block):
            return _fail(P.SenseKey.ILLEGAL_REQUEST, P.ASC_INVALID_FIELD_CDB)
        start = f["offset"]
        return Reply(data=memoryview(self._block)[start:start + f["count"]])

    def _abort(self, f: Mapping[str, int], data: bytes) -> Reply:
        if self._state in (P.State.ARMED, P.State.TRIGGERED):
            self._state = P.State.IDLE
        return Reply()

    # ------------------------------------------------------------------ capture
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
            digitised = self._digitise(np.asarray(event.volts, dtype=float), s)
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

    def _digitise(self, volts: np.ndarray, s: P.SetupData) -> "tuple[bytes, int] | None":
        """(volts-per-count + counts bytes, overload mask) of the block around the trigger, or None."""
        from simulator import frontend  # the physics of the input stage

        n, pre, fs = s.block_size, s.pretrigger, float(s.sample_rate_hz)
        n_ch = len(s.channels)
        if volts.ndim != 2 or volts.shape[0] != n_ch or volts.shape[1] < n:
            raise RuntimeError(f"the stand returned volts of shape {volts.shape}; expected ({n_ch}, >= {n})")
        filtered = frontend.apply_anti_alias(volts, fs, self._frontend_config())
        ranges = np.array([ch.range_mv / 1000.0 for ch in s.channels])
        t = s.trigger_channel
        counts_t, _ = frontend.quantize(filtered[t], ranges[t])
        level_counts = s.trigger_level_v / frontend.volts_per_count(ranges[t])
        k = _find_trigger(counts_t, level_counts, s.trigger_slope, pre, n)
        if k is None:
            return None
        counts, overload = frontend.quantize(filtered[:, k - pre:k - pre + n], ranges)
        vpc = np.asarray(frontend.volts_per_count(ranges), dtype="<f8")
        mask = sum(1 << i for i, o in enumerate(np.asarray(overload).ravel()) if o)
        return vpc.tobytes() + np.ascontiguousarray(counts, dtype="<i2").tobytes(), mask


def _find_trigger(x: np.ndarray, level: float, slope: str, pre: int, n: int) -> "int | None":
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


# ---------------------------------------------------------------------- factory
