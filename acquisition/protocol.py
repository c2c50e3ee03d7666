"""Every wire format of the analyser link, in one module: the single source of truth for bytes.

Layers
------
1. **Bulk-only envelope** (USB Mass Storage Bulk-Only Transport framing, little-endian):
   command block wrapper ``CBW`` (31 bytes, ``<IIIBBB16s``: signature ``USBC``, tag, data
   transfer length, flags (bit 7 = data in), LUN, CDB length, CDB) and command status wrapper
   ``CSW`` (13 bytes, ``<IIIB``: signature ``USBS``, tag, residue, status 0/1/2).
2. **SCSI command descriptor blocks** (big-endian, as in SPC): TEST UNIT READY 0x00,
   REQUEST SENSE 0x03, INQUIRY 0x12, and the analyser's vendor commands 0xC0..0xC6.
3. **Data-phase payloads** (little-endian, as a USB device lays out its memory): sense data
   (18-byte fixed format, big-endian per SPC), INQUIRY data (36 bytes), capabilities,
   set-up, status, and the block image (header + per-channel volts/count + int16 counts).
   Every analyser payload starts with a version byte equal to :data:`PROTOCOL_VERSION`.

Vendor CDBs (10 bytes, ``>BBH5xB``: opcode, protocol version, parameter/allocation length,
reserved, control) except READ BLOCK (16 bytes, ``>BBIII xB``: opcode, version, block sequence,
byte offset into the block image, byte count). A block image larger than
:data:`MAX_TRANSFER` bytes is read by several READ BLOCK commands with increasing offsets.

Commands (``COMMANDS`` is the table the host validates against and the firmware dispatches on):

======  ================  =====  ===========================================================
opcode  name              data   CDB fields (big-endian) -> data phase
======  ================  =====  ===========================================================
0x00    TEST UNIT READY   none   -
0x03    REQUEST SENSE     in     allocation length (<= 255) -> 18-byte fixed-format sense
0x12    INQUIRY           in     EVPD, page (0x00, 0x80), allocation length -> 36 bytes / VPD
0xC0    GET CAPABILITIES  in     version, allocation length -> capabilities
0xC1    SET UP            out    version, parameter list length <- set-up (header + records)
0xC2    GET SET-UP        in     version, allocation length -> the set-up as stored
0xC3    ARM               none   version
0xC4    GET STATUS        in     version, allocation length -> 16-byte status
0xC5    READ BLOCK        in     version, sequence, offset, count (<= MAX_TRANSFER) -> image bytes
0xC6    ABORT             none   version
======  ================  =====  ===========================================================

Sense codes the analyser reports: ILLEGAL REQUEST (5) with ASC 0x20 (unsupported opcode),
0x24 (invalid CDB field), 0x25 (LUN), 0x26 (set-up value outside the capabilities), 0x1A
(set-up length); NOT READY (2) with ASC 0x04 and ASCQ 0x80 (set-up required), 0x81 (no block),
0x82 (capture in progress); UNIT ATTENTION (6) 0x29 (power-on or reset); HARDWARE ERROR (4) 0x44.

Stream links (serial, TCP, pty) have no out-of-band reset: the host sends
:data:`STREAM_RESET` (31 bytes starting with ``b"USBR"``), which the firmware recognises
anywhere in its input and treats like the bulk-only mass storage reset.

All ``encode_*`` / ``decode_*`` functions are pure and raise
:class:`acquisition.errors.ProtocolError` (decoding) or :class:`ValueError`-derived
:class:`acquisition.errors.SetupError` (encoding a value that does not fit) with a message
naming the field and the allowed values.
"""
from __future__ import annotations

import enum
import struct
from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from acquisition.errors import ProtocolError, SetupError

__all__ = [
    "PROTOCOL_VERSION", "MAX_TRANSFER", "CBW", "CSW", "CBW_SIGNATURE", "CSW_SIGNATURE",
    "CBW_FLAG_DATA_IN", "STREAM_RESET", "CswStatus", "Direction", "Op", "SenseKey",
    "Cbw", "Csw", "Sense", "Inquiry", "CapabilitiesData", "ChannelRecord", "SetupData",
    "StatusData", "State", "BlockHeader", "CommandSpec", "COMMANDS", "command_spec",
    "encode_cbw", "decode_cbw", "encode_csw", "decode_csw", "build_cdb", "parse_cdb",
    "encode_sense", "decode_sense", "encode_inquiry", "decode_inquiry",
    "encode_serial_vpd", "decode_serial_vpd",
    "encode_capabilities", "decode_capabilities", "encode_setup", "decode_setup",
    "encode_status", "decode_status", "encode_block_header", "decode_block_header",
    "block_image_size", "sense_key_name", "asc_meaning",
]

#: version of every analyser payload and of the vendor CDBs (byte 1); bump on any layout change
PROTOCOL_VERSION = 1
#: largest data phase of one READ BLOCK command, bytes (the driver loops over offsets)
MAX_TRANSFER = 64 * 1024

# --------------------------------------------------------------------------- envelope
CBW = struct.Struct("<IIIBBB16s")
CSW = struct.Struct("<IIIB")
CBW_SIGNATURE = 0x43425355  # b"USBC" little-endian
CSW_SIGNATURE = 0x53425355  # b"USBS"
CBW_FLAG_DATA_IN = 0x80

#: in-band reset for byte streams: b"USBR" + a fixed 27-byte pattern that no CBW can contain
#: (a CBW starts with b"USBC", and set-up payloads are far shorter than this run of 0xA5/0x5A).
STREAM_RESET = b"USBR" + bytes([0xA5, 0x5A] * 13) + b"\xa5"
assert len(STREAM_RESET) == CBW.size


class CswStatus(enum.IntEnum):
    """bCSWStatus values."""

    PASSED = 0
    FAILED = 1
    PHASE_ERROR = 2


class Direction(enum.Enum):
    """Data phase direction of a command."""

    NONE = "none"
    IN = "in"    # device to host
    OUT = "out"  # host to device


@dataclass(frozen=True)
class Cbw:
    """A decoded command block wrapper."""

    tag: int
    data_length: int
    data_in: bool
    lun: int
    cdb: bytes  # exactly cb_length bytes

    @property
    def opcode(self) -> int:
        return self.cdb[0]


@dataclass(frozen=True)
class Csw:
    """A decoded command status wrapper."""

    tag: int
    residue: int
    status: int


def encode_cbw(tag: int, data_length: int, data_in: bool, cdb: bytes, lun: int = 0) -> bytes:
    """The 31-byte CBW for one command; ``cdb`` is 1..16 bytes (zero padded on the wire)."""
    if not 1 <= len(cdb) <= 16:
        raise ProtocolError(f"CDB length {len(cdb)} is outside 1..16 bytes; build it with build_cdb()")
    if not 0 <= tag <= 0xFFFFFFFF or not 0 <= data_length <= 0xFFFFFFFF:
        raise ProtocolError(f"tag {tag} or data length {data_length} does not fit 32 bits")
    if not 0 <= lun <= 15:
        raise ProtocolError(f"LUN {lun} is outside 0..15")
    flags = CBW_FLAG_DATA_IN if data_in else 0
    return CBW.pack(CBW_SIGNATURE, tag, data_length, flags, lun, len(cdb), bytes(cdb))


def decode_cbw(raw: bytes) -> Cbw:
    """Parse and check a CBW: 31 bytes, signature ``USBC``, reserved bits zero, CDB length 1..16."""
    if len(raw) != CBW.size:
        raise ProtocolError(f"a command block wrapper is {CBW.size} bytes, got {len(raw)}")
    sig, tag, length, flags, lun, cblen, cdb = CBW.unpack(raw)
    if sig != CBW_SIGNATURE:
        raise ProtocolError(f"bad CBW signature 0x{sig:08X} (expected 0x{CBW_SIGNATURE:08X} 'USBC')")
    if flags & 0x7F or lun & 0xF0 or cblen & 0xE0:
        raise ProtocolError("CBW has reserved bits set (flags, LUN or CDB length); the host is out of step")
    if not 1 <= cblen <= 16:
        raise ProtocolError(f"CBW announces a CDB length of {cblen}; it must be 1..16")
    return Cbw(tag, length, bool(flags & CBW_FLAG_DATA_IN), lun, bytes(cdb[:cblen]))


def encode_csw(tag: int, residue: int, status: int) -> bytes:
    """The 13-byte CSW."""
    return CSW.pack(CSW_SIGNATURE, tag & 0xFFFFFFFF, residue, int(status))


def decode_csw(raw: bytes) -> Csw:
    """Parse and check a CSW: 13 bytes, signature ``USBS``, status 0, 1 or 2."""
    if len(raw) != CSW.size:
        raise ProtocolError(
            f"a command status wrapper is {CSW.size} bytes, got {len(raw)}: the device and host are out of "
            "step; reset recovery is needed")
    sig, tag, residue, status = CSW.unpack(raw)
    if sig != CSW_SIGNATURE:
        raise ProtocolError(
            f"bad CSW signature 0x{sig:08X} (expected 0x{CSW_SIGNATURE:08X} 'USBS'): the link is out of step; "
            "reset recovery is needed")
    if status > 2:
        raise ProtocolError(f"CSW status {status} is not 0, 1 or 2 (reserved by the bulk-only spec)")
    return Csw(tag, residue, status)


# --------------------------------------------------------------------------- sense data
class SenseKey(enum.IntEnum):
    """SCSI sense keys used by the analyser."""

    NO_SENSE = 0x0
    NOT_READY = 0x2
    HARDWARE_ERROR = 0x4
    ILLEGAL_REQUEST = 0x5
    UNIT_ATTENTION = 0x6
    ABORTED_COMMAND = 0xB


# (ASC, ASCQ) used by the analyser and what they mean / what to do
ASC_INVALID_OPCODE = (0x20, 0x00)
ASC_INVALID_FIELD_CDB = (0x24, 0x00)
ASC_INVALID_FIELD_PARAM = (0x26, 0x00)
ASC_LUN_NOT_SUPPORTED = (0x25, 0x00)
ASC_PARAMETER_LENGTH = (0x1A, 0x00)
ASC_POWER_ON_RESET = (0x29, 0x00)
#: HARDWARE ERROR, internal target failure: the (simulated) analyser has no input stage / test stand
ASC_INTERNAL_FAILURE = (0x44, 0x00)
#: NOT READY, set-up required: ARM or GET SET-UP before any SET UP (vendor-specific ASCQ of 0x04 "not ready")
ASC_NOT_READY_SETUP_REQUIRED = (0x04, 0x80)
#: NOT READY, no block: READ BLOCK before the armed capture produced a block
ASC_NOT_READY_NO_BLOCK = (0x04, 0x81)
#: NOT READY, capture in progress: SET UP while armed (ABORT first)
ASC_NOT_READY_ARMED = (0x04, 0x82)

_ASC_TEXT: Mapping[tuple[int, int], tuple[str, str]] = {
    (0x00, 0x00): ("no additional sense information", ""),
    ASC_INVALID_OPCODE: ("invalid command operation code",
                         "the analyser does not support this command; check the firmware revision (identify)"),
    ASC_INVALID_FIELD_CDB: ("invalid field in CDB",
                            "a command field is out of range (offset/count/sequence/version); check the driver"),
    ASC_INVALID_FIELD_PARAM: ("invalid field in parameter list",
                              "the set-up holds a value outside the capabilities; validate it against capabilities()"),
    ASC_PARAMETER_LENGTH: ("parameter list length error", "the set-up data length does not match its channel count"),
    ASC_POWER_ON_RESET: ("power on, reset, or bus device reset occurred",
                         "the analyser was powered on or reset and abandoned any armed capture; configure it "
                         "again if it was powered on, then arm"),
    ASC_INTERNAL_FAILURE: ("internal target failure",
                           "the analyser cannot acquire (a simulator built without a test stand?); power-cycle it"),
    ASC_LUN_NOT_SUPPORTED: ("logical unit not supported", "the analyser has one logical unit: address LUN 0"),
    ASC_NOT_READY_SETUP_REQUIRED: ("not ready: set-up required", "send a set-up (configure) before arming"),
    ASC_NOT_READY_NO_BLOCK: ("not ready: no block available", "arm and wait for the trigger before reading a block"),
    ASC_NOT_READY_ARMED: ("not ready: capture in progress", "abort the armed capture before changing the set-up"),
}


def sense_key_name(key: int) -> str:
    """``"ILLEGAL REQUEST"`` for 5, etc."""
    try:
        return SenseKey(key).name.replace("_", " ")
    except ValueError:
        return f"sense key 0x{key:X}"


def asc_meaning(asc: int, ascq: int) -> tuple[str, str]:
    """(meaning, what to do) of an additional sense code pair."""
    return _ASC_TEXT.get((asc, ascq), (f"ASC 0x{asc:02X}/ASCQ 0x{ascq:02X}", "see the analyser manual"))


SENSE = struct.Struct(">BBBIBIBBB3s")  # fixed format, 18 bytes
assert SENSE.size == 18
SENSE_RESPONSE_CODE = 0x70


@dataclass(frozen=True)
class Sense:
    """Fixed-format sense data (response code 0x70)."""

    key: int
    asc: int
    ascq: int

    def describe(self) -> str:
        meaning, todo = asc_meaning(self.asc, self.ascq)
        text = f"{sense_key_name(self.key)} (ASC 0x{self.asc:02X}/0x{self.ascq:02X}: {meaning})"
        return f"{text}; {todo}" if todo else text


def encode_sense(sense: Sense) -> bytes:
    """18 bytes of fixed-format sense data; additional sense length 10."""
    return SENSE.pack(SENSE_RESPONSE_CODE, 0, sense.key & 0x0F, 0, 10, 0, sense.asc, sense.ascq, 0, b"\0\0\0")


def decode_sense(raw: bytes) -> Sense:
    """Parse fixed-format sense data (at least the first 14 bytes are needed)."""
    if len(raw) < 14:
        raise ProtocolError(f"sense data of {len(raw)} bytes is too short (need 14 of the 18)")
    code, _, key, _, _, _, asc, ascq, _, _ = SENSE.unpack(bytes(raw[:18]).ljust(18, b"\0"))
    if code & 0x7F not in (0x70, 0x71):
        raise ProtocolError(f"sense response code 0x{code:02X} is not fixed format (0x70/0x71)")
    return Sense(key & 0x0F, asc, ascq)


# --------------------------------------------------------------------------- INQUIRY
INQUIRY = struct.Struct(">BBBBBBBB8s16s4s")
assert INQUIRY.size == 36
DEVICE_TYPE_PROCESSOR = 0x03
VPD_SUPPORTED_PAGES = 0x00
VPD_SERIAL_NUMBER = 0x80
VPD_HEADER = struct.Struct(">BBBB")


@dataclass(frozen=True)
class Inquiry:
    """Standard INQUIRY data."""

    device_type: int
    vendor: str
    product: str
    revision: str


def encode_inquiry(inq: Inquiry) -> bytes:
    """36-byte standard INQUIRY data (SPC-3 version 0x05, response format 2, additional length 31)."""
    def field_(text: str, n: int) -> bytes:
        raw = text.encode("ascii")
        if len(raw) > n:
            raise ProtocolError(f"INQUIRY field {text!r} is longer than {n} bytes")
        return raw.ljust(n, b" ")
    return INQUIRY.pack(inq.device_type & 0x1F, 0, 0x05, 0x02, 31, 0, 0, 0,
                        field_(inq.vendor, 8), field_(inq.product, 16), field_(inq.revision, 4))


def decode_inquiry(raw: bytes) -> Inquiry:
    """Parse 36-byte standard INQUIRY data (trailing spaces stripped)."""
    if len(raw) < INQUIRY.size:
        raise ProtocolError(f"INQUIRY data of {len(raw)} bytes is too short (need {INQUIRY.size})")
    fields = INQUIRY.unpack(bytes(raw[:INQUIRY.size]))
    def text(b: bytes) -> str:
        return b.decode("ascii", errors="replace").rstrip(" \0")
    return Inquiry(fields[0] & 0x1F, text(fields[8]), text(fields[9]), text(fields[10]))


def encode_serial_vpd(serial: str) -> bytes:
    """VPD page 0x80 (unit serial number): 4-byte header + ASCII serial."""
    raw = serial.encode("ascii")
    return VPD_HEADER.pack(DEVICE_TYPE_PROCESSOR, VPD_SERIAL_NUMBER, 0, len(raw)) + raw


def decode_serial_vpd(raw: bytes) -> str:
    """The serial number from VPD page 0x80."""
    if len(raw) < VPD_HEADER.size:
        raise ProtocolError(f"VPD page of {len(raw)} bytes is too short")
    _, page, _, n = VPD_HEADER.unpack(bytes(raw[:4]))
    if page != VPD_SERIAL_NUMBER or len(raw) < 4 + n:
        raise ProtocolError(f"expected VPD page 0x80 with {n} serial bytes, got page 0x{page:02X}, {len(raw)} bytes")
    return bytes(raw[4:4 + n]).decode("ascii", errors="replace").strip()


# --------------------------------------------------------------------------- capabilities
#: version, n_inputs, n_rates, n_ranges, n_block_sizes, flags, adc_bits, pad, max_transfer, max_pretrigger
CAPS_HEADER = struct.Struct("<BBBBBBBxII")
CAPS_FLAG_AC = 0x01
CAPS_FLAG_DC = 0x02
CAPS_FLAG_IEPE = 0x04
CAPS_FLAG_TRIGGER_ANY_CHANNEL = 0x08


@dataclass(frozen=True)
class CapabilitiesData:
    """What the analyser can do (wire-level view; the operator view is ``acquisition.setup.Capabilities``).

    ``sample_rates_hz``: allowed rates, Hz (integers); ``ranges_mv``: input ranges, peak mV;
    ``block_sizes``: samples per channel; ``max_transfer``: bytes per READ BLOCK;
    ``max_pretrigger``: most pre-trigger samples (never more than block size - 1).
    """

    n_inputs: int
    sample_rates_hz: tuple[int, ...]
    ranges_mv: tuple[int, ...]
    block_sizes: tuple[int, ...]
    ac: bool = True
    dc: bool = True
    iepe: bool = True
    trigger_any_channel: bool = True
    adc_bits: int = 16
    max_transfer: int = MAX_TRANSFER
    max_pretrigger: int = 8192
    version: int = PROTOCOL_VERSION


def encode_capabilities(caps: CapabilitiesData) -> bytes:
    """Header + uint32 rates (Hz) + uint32 ranges (mV) + uint32 block sizes, little-endian."""
    flags = ((CAPS_FLAG_AC if caps.ac else 0) | (CAPS_FLAG_DC if caps.dc else 0)
             | (CAPS_FLAG_IEPE if caps.iepe else 0) | (CAPS_FLAG_TRIGGER_ANY_CHANNEL if caps.trigger_any_channel else 0))
    head = CAPS_HEADER.pack(caps.version, caps.n_inputs, len(caps.sample_rates_hz), len(caps.ranges_mv),
                            len(caps.block_sizes), flags, caps.adc_bits, caps.max_transfer, caps.max_pretrigger)
    body = np.array(list(caps.sample_rates_hz) + list(caps.ranges_mv) + list(caps.block_sizes), dtype="<u4")
    return head + body.tobytes()


def decode_capabilities(raw: bytes) -> CapabilitiesData:
    """Inverse of :func:`encode_capabilities`; checks the version and the length."""
    if len(raw) < CAPS_HEADER.size:
        raise ProtocolError(f"capabilities data of {len(raw)} bytes is shorter than its {CAPS_HEADER.size}-byte header")
    ver, n_in, n_r, n_g, n_b, flags, bits, max_tr, max_pre = CAPS_HEADER.unpack(bytes(raw[:CAPS_HEADER.size]))
    _check_version("capabilities", ver)
    need = CAPS_HEADER.size + 4 * (n_r + n_g + n_b)
    if len(raw) < need:
        raise ProtocolError(f"capabilities data is {len(raw)} bytes, its header announces {need}")
    body = np.frombuffer(bytes(raw[CAPS_HEADER.size:need]), dtype="<u4").tolist()
    return CapabilitiesData(n_in, tuple(body[:n_r]), tuple(body[n_r:n_r + n_g]), tuple(body[n_r + n_g:]),
                            bool(flags & CAPS_FLAG_AC), bool(flags & CAPS_FLAG_DC), bool(flags & CAPS_FLAG_IEPE),
                            bool(flags & CAPS_FLAG_TRIGGER_ANY_CHANNEL), bits, max_tr, max_pre, ver)


def capabilities_size(caps: CapabilitiesData) -> int:
    """Bytes of the encoded capabilities."""
    return CAPS_HEADER.size + 4 * (len(caps.sample_rates_hz) + len(caps.ranges_mv) + len(caps.block_sizes))


def _check_version(what: str, ver: int) -> None:
    if ver != PROTOCOL_VERSION:
        raise ProtocolError(f"{what} data has protocol version {ver}, this driver speaks version {PROTOCOL_VERSION}; "
                            "update the driver or the analyser firmware")


# --------------------------------------------------------------------------- set-up
#: version, n_channels, trigger channel (index into the channel records), slope (0 rising, 1 falling),
#: sample rate Hz, block size, pre-trigger samples, trigger level (volts at the input, float64)
SETUP_HEADER = struct.Struct("<BBBBIIId")
#: input index, coupling (0 AC, 1 DC), IEPE (0/1), quantity (0 force, 1 acceleration), range mV,
#: sensitivity (volts per engineering unit: V/N or V/(m/s^2), float64), point label (ASCII, 24 bytes)
CHANNEL_RECORD = struct.Struct("<BBBBId24s")
QUANTITIES = ("force", "acceleration")
COUPLINGS = ("AC", "DC")
SLOPES = ("rising", "falling")


@dataclass(frozen=True)
class ChannelRecord:
    """One channel of the wire set-up.

    ``sensitivity`` is in volts per SI engineering unit (V/N for force, V/(m/s^2) for acceleration);
    ``range_mv`` the peak input range in millivolts; ``point`` the measurement point label.
    """

    input: int
    coupling: str  # "AC" | "DC"
    iepe: bool
    quantity: str  # "force" | "acceleration"
    range_mv: int
    sensitivity: float
    point: str


@dataclass(frozen=True)
class SetupData:
    """The wire set-up: acquisition parameters and per-channel records."""

    sample_rate_hz: int
    block_size: int
    pretrigger: int
    trigger_channel: int  # index into ``channels``
    trigger_slope: str    # "rising" | "falling"
    trigger_level_v: float
    channels: tuple[ChannelRecord, ...] = field(default_factory=tuple)
    version: int = PROTOCOL_VERSION


def setup_size(n_channels: int) -> int:
    """Bytes of an encoded set-up with ``n_channels`` records."""
    return SETUP_HEADER.size + n_channels * CHANNEL_RECORD.size


def _index(name: str, value: str, allowed: tuple[str, ...]) -> int:
    if value not in allowed:
        raise SetupError(f"{name} {value!r} is not one of {', '.join(allowed)}")
    return allowed.index(value)


def encode_setup(setup: SetupData) -> bytes:
    """Header + one record per channel, little-endian."""
    parts = [SETUP_HEADER.pack(setup.version, len(setup.channels), setup.trigger_channel,
                               _index("trigger slope", setup.trigger_slope, SLOPES), setup.sample_rate_hz,
                               setup.block_size, setup.pretrigger, float(setup.trigger_level_v))]
    for ch in setup.channels:
        point = ch.point.encode("ascii")
        if len(point) > 24:
            raise SetupError(f"point label {ch.point!r} is longer than 24 characters; shorten it")
        parts.append(CHANNEL_RECORD.pack(ch.input, _index("coupling", ch.coupling, COUPLINGS), int(bool(ch.iepe)),
                                         _index("quantity", ch.quantity, QUANTITIES), ch.range_mv,
                                         float(ch.sensitivity), point))
    return b"".join(parts)


def decode_setup(raw: bytes) -> SetupData:
    """Inverse of :func:`encode_setup`; raises ProtocolError on a bad version, length or code."""
    if len(raw) < SETUP_HEADER.size:
        raise ProtocolError(f"set-up data of {len(raw)} bytes is shorter than its {SETUP_HEADER.size}-byte header")
    ver, n, trig_ch, slope, fs, bs, pre, level = SETUP_HEADER.unpack(bytes(raw[:SETUP_HEADER.size]))
    _check_version("set-up", ver)
    if len(raw) != setup_size(n):
        raise ProtocolError(f"set-up data is {len(raw)} bytes; {n} channels need {setup_size(n)}")
    if slope > 1:
        raise ProtocolError(f"set-up trigger slope code {slope} is not 0 (rising) or 1 (falling)")
    chans = []
    for i in range(n):
        off = SETUP_HEADER.size + i * CHANNEL_RECORD.size
        inp, coup, iepe, qty, rng, sens, point = CHANNEL_RECORD.unpack(bytes(raw[off:off + CHANNEL_RECORD.size]))
        if coup > 1 or iepe > 1 or qty > 1:
            raise ProtocolError(f"set-up channel record {i} has an invalid coupling/IEPE/quantity code")
        chans.append(ChannelRecord(inp, COUPLINGS[coup], bool(iepe), QUANTITIES[qty], rng, sens,
                                   point.rstrip(b"\0").decode("ascii", errors="replace")))
    return SetupData(fs, bs, pre, trig_ch, SLOPES[slope], level, tuple(chans), ver)


# --------------------------------------------------------------------------- status
class State(enum.IntEnum):
    """Acquisition state reported by GET STATUS."""

    IDLE = 0
    ARMED = 1       # waiting for the trigger
    TRIGGERED = 2   # trigger seen, post-trigger samples being acquired
    BLOCK_READY = 3


#: version, state, overload mask (bit i = channel i), flags, block sequence, samples available, strikes since arm
STATUS = struct.Struct("<BBBBIII")
STATUS_FLAG_CONFIGURED = 0x01
STATUS_FLAG_NO_TRIGGER = 0x02  # the last strike did not cross the trigger level


@dataclass(frozen=True)
class StatusData:
    """GET STATUS reply. ``overload`` per channel; ``samples_available`` per channel."""

    state: State
    overload_mask: int
    configured: bool
    no_trigger: bool
    sequence: int
    samples_available: int
    strikes: int
    version: int = PROTOCOL_VERSION

    def overload(self, n_channels: int) -> list[bool]:
        return [bool(self.overload_mask >> i & 1) for i in range(n_channels)]


def encode_status(st: StatusData) -> bytes:
    flags = (STATUS_FLAG_CONFIGURED if st.configured else 0) | (STATUS_FLAG_NO_TRIGGER if st.no_trigger else 0)
    return STATUS.pack(st.version, int(st.state), st.overload_mask, flags, st.sequence, st.samples_available,
                       st.strikes)


def decode_status(raw: bytes) -> StatusData:
    if len(raw) != STATUS.size:
        raise ProtocolError(f"status data is {len(raw)} bytes, expected {STATUS.size}")
    ver, state, ovl, flags, seq, avail, strikes = STATUS.unpack(bytes(raw))
    _check_version("status", ver)
    try:
        st = State(state)
    except ValueError:
        raise ProtocolError(f"status reports unknown state {state}; expected 0..3") from None
    return StatusData(st, ovl, bool(flags & STATUS_FLAG_CONFIGURED), bool(flags & STATUS_FLAG_NO_TRIGGER),
                      seq, avail, strikes, ver)


# --------------------------------------------------------------------------- block image
#: version, n_channels, overload mask, reserved, sequence, samples per channel, trigger index,
#: sample rate Hz (float64), device timestamp of the first sample s (float64)
BLOCK_HEADER = struct.Struct("<BBBxIIIdd")


@dataclass(frozen=True)
class BlockHeader:
    """Header of a block image. After it: ``n_channels`` float64 volts-per-count values, then
    ``n_channels * n_samples`` int16 little-endian counts, channel-major (``counts[ch, i]``)."""

    n_channels: int
    overload_mask: int
    sequence: int
    n_samples: int
    trigger_index: int
    sample_rate_hz: float
    timestamp_s: float
    version: int = PROTOCOL_VERSION


def block_image_size(n_channels: int, n_samples: int) -> int:
    """Bytes of a block image: header + 8 bytes/channel + 2 bytes/sample/channel."""
    return BLOCK_HEADER.size + 8 * n_channels + 2 * n_channels * n_samples


def encode_block_header(h: BlockHeader) -> bytes:
    return BLOCK_HEADER.pack(h.version, h.n_channels, h.overload_mask, h.sequence, h.n_samples, h.trigger_index,
                             h.sample_rate_hz, h.timestamp_s)


def decode_block_header(raw: bytes) -> BlockHeader:
    if len(raw) < BLOCK_HEADER.size:
        raise ProtocolError(f"block image of {len(raw)} bytes is shorter than its {BLOCK_HEADER.size}-byte header")
    ver, n_ch, ovl, seq, n, trig, fs, ts = BLOCK_HEADER.unpack(bytes(raw[:BLOCK_HEADER.size]))
    _check_version("block", ver)
    return BlockHeader(n_ch, ovl, seq, n, trig, fs, ts, ver)


def decode_block_image(raw: bytes) -> tuple[BlockHeader, np.ndarray, np.ndarray]:
    """(header, volts_per_count[n_ch] float64, counts[n_ch, n] int16) from a whole block image (copies)."""
    h = decode_block_header(raw)
    need = block_image_size(h.n_channels, h.n_samples)
    if len(raw) != need:
        raise ProtocolError(f"block image is {len(raw)} bytes; its header announces {need}")
    off = BLOCK_HEADER.size
    vpc = np.frombuffer(raw, dtype="<f8", count=h.n_channels, offset=off).astype(float)
    counts = np.frombuffer(raw, dtype="<i2", offset=off + 8 * h.n_channels).reshape(h.n_channels, h.n_samples)
    return h, vpc, counts.astype(np.int16)


# --------------------------------------------------------------------------- CDBs and command table
class Op(enum.IntEnum):
    """Operation codes."""

    TEST_UNIT_READY = 0x00
    REQUEST_SENSE = 0x03
    INQUIRY = 0x12
    GET_CAPABILITIES = 0xC0
    SET_UP = 0xC1
    GET_SET_UP = 0xC2
    ARM = 0xC3
    GET_STATUS = 0xC4
    READ_BLOCK = 0xC5
    ABORT = 0xC6


CDB_TEST_UNIT_READY = struct.Struct(">B4xB")       # opcode, reserved, control
CDB_REQUEST_SENSE = struct.Struct(">BB2xBB")       # opcode, DESC bit, reserved, allocation length, control
CDB_INQUIRY = struct.Struct(">BBBHB")              # opcode, EVPD bit, page code, allocation length, control
CDB_VENDOR = struct.Struct(">BBH5xB")              # opcode, version, parameter/allocation length, control
CDB_READ_BLOCK = struct.Struct(">BBIIIxB")         # opcode, version, sequence, offset, count, control


def _fields_none(f: Mapping[str, int]) -> int:
    return 0


def _length_field(f: Mapping[str, int]) -> int:
    return int(f["length"])


def _count_field(f: Mapping[str, int]) -> int:
    return int(f["count"])


def _check_range(name: str, value: int, lo: int, hi: int) -> str | None:
    if not lo <= value <= hi:
        return f"{name} {value} is outside {lo}..{hi}"
    return None


def _val_none(f: Mapping[str, int]) -> str | None:
    return _check_range("control", f.get("control", 0), 0, 0)


def _val_sense(f: Mapping[str, int]) -> str | None:
    return (_check_range("DESC", f["desc"], 0, 0)
            or _check_range("allocation length", f["length"], 0, 255) or _val_none(f))


def _val_inquiry(f: Mapping[str, int]) -> str | None:
    err = _check_range("EVPD", f["evpd"], 0, 1) or _check_range("allocation length", f["length"], 0, 0xFFFF)
    if err:
        return err
    if not f["evpd"] and f["page"] != 0:
        return f"page code 0x{f['page']:02X} requires EVPD=1"
    if f["evpd"] and f["page"] not in (VPD_SUPPORTED_PAGES, VPD_SERIAL_NUMBER):
        return f"VPD page 0x{f['page']:02X} is not supported (0x00, 0x80)"
    return _val_none(f)


def _val_vendor(f: Mapping[str, int]) -> str | None:
    return (_check_range("protocol version", f["version"], PROTOCOL_VERSION, PROTOCOL_VERSION)
            or _check_range("length", f["length"], 0, 0xFFFF) or _val_none(f))


def _val_vendor_nodata(f: Mapping[str, int]) -> str | None:
    return _val_vendor(f) or _check_range("length", f["length"], 0, 0)


def _val_read_block(f: Mapping[str, int]) -> str | None:
    return (_check_range("protocol version", f["version"], PROTOCOL_VERSION, PROTOCOL_VERSION)
            or _check_range("count", f["count"], 1, MAX_TRANSFER)
            or _check_range("offset", f["offset"], 0, 0xFFFFFFFF) or _val_none(f))


@dataclass(frozen=True)
class CommandSpec:
    """One row of the command table.

    ``data_length(fields)`` is the data phase length the command asks for (allocation length for
    IN, parameter list length for OUT, 0 for NONE); ``validate(fields)`` returns an error text for
    a CDB field out of range, else None. ``idempotent`` commands may be retried once after reset
    recovery (they do not change the analyser state).
    """

    opcode: int
    name: str
    direction: Direction
    cdb: struct.Struct
    fields: tuple[str, ...]
    data_length: Callable[[Mapping[str, int]], int]
    validate: Callable[[Mapping[str, int]], str | None]
    idempotent: bool


_V = ("opcode", "version", "length", "control")
COMMANDS: Mapping[int, CommandSpec] = {spec.opcode: spec for spec in (
    CommandSpec(Op.TEST_UNIT_READY, "TEST UNIT READY", Direction.NONE, CDB_TEST_UNIT_READY,
                ("opcode", "control"), _fields_none, _val_none, True),
    CommandSpec(Op.REQUEST_SENSE, "REQUEST SENSE", Direction.IN, CDB_REQUEST_SENSE,
                ("opcode", "desc", "length", "control"), _length_field, _val_sense, False),
    CommandSpec(Op.INQUIRY, "INQUIRY", Direction.IN, CDB_INQUIRY,
                ("opcode", "evpd", "page", "length", "control"), _length_field, _val_inquiry, True),
    CommandSpec(Op.GET_CAPABILITIES, "GET CAPABILITIES", Direction.IN, CDB_VENDOR, _V, _length_field,
                _val_vendor, True),
    CommandSpec(Op.SET_UP, "SET UP", Direction.OUT, CDB_VENDOR, _V, _length_field, _val_vendor, True),
    CommandSpec(Op.GET_SET_UP, "GET SET-UP", Direction.IN, CDB_VENDOR, _V, _length_field, _val_vendor, True),
    CommandSpec(Op.ARM, "ARM", Direction.NONE, CDB_VENDOR, _V, _fields_none, _val_vendor_nodata, False),
    CommandSpec(Op.GET_STATUS, "GET STATUS", Direction.IN, CDB_VENDOR, _V, _length_field, _val_vendor, True),
    CommandSpec(Op.READ_BLOCK, "READ BLOCK", Direction.IN, CDB_READ_BLOCK,
                ("opcode", "version", "sequence", "offset", "count", "control"), _count_field, _val_read_block,
                True),
    CommandSpec(Op.ABORT, "ABORT", Direction.NONE, CDB_VENDOR, _V, _fields_none, _val_vendor_nodata, True),
)}
_BY_NAME = {spec.name: spec for spec in COMMANDS.values()}


def command_spec(opcode_or_name: "int | str") -> CommandSpec:
    """The table row of an opcode (int) or a command name (``"READ BLOCK"``)."""
    spec = _BY_NAME.get(opcode_or_name) if isinstance(opcode_or_name, str) else COMMANDS.get(opcode_or_name)
    if spec is None:
        raise KeyError(f"unknown command {opcode_or_name!r}; known: {', '.join(_BY_NAME)}")
    return spec


_VENDOR_OPS = {Op.GET_CAPABILITIES, Op.SET_UP, Op.GET_SET_UP, Op.ARM, Op.GET_STATUS, Op.READ_BLOCK, Op.ABORT}


def build_cdb(opcode: int, **fields: int) -> bytes:
    """Encode a CDB from the command table, validating every field before anything is written.

    Omitted fields default to 0, except ``version`` which defaults to :data:`PROTOCOL_VERSION`.
    Raises :class:`ValueError` naming the field and its allowed range.
    """
    spec = command_spec(opcode)
    values = {name: 0 for name in spec.fields}
    values["opcode"] = spec.opcode
    if "version" in values:
        values["version"] = PROTOCOL_VERSION
    unknown = set(fields) - set(spec.fields)
    if unknown:
        raise ValueError(f"{spec.name} has no field(s) {sorted(unknown)}; fields: {', '.join(spec.fields[1:])}")
    values.update(fields)
    err = spec.validate(values)
    if err:
        raise ValueError(f"{spec.name}: {err}")
    return spec.cdb.pack(*(values[name] for name in spec.fields))


def parse_cdb(cdb: bytes) -> tuple[CommandSpec, dict[str, int]]:
    """Decode a CDB by its opcode. Raises KeyError for an unknown opcode, ValueError for a bad length."""
    spec = command_spec(cdb[0])
    if len(cdb) < spec.cdb.size:
        raise ValueError(f"{spec.name} CDB is {len(cdb)} bytes, needs {spec.cdb.size}")
    return spec, dict(zip(spec.fields, spec.cdb.unpack(bytes(cdb[:spec.cdb.size]))))


#: the simulated SigLab 20-42-like analyser: 4 inputs; sample rates 51200/2^k (k = 0..7) and the
#: decimal series 1, 2, 5, 10, 20, 50 kHz (bandwidth fs/2.56); ranges 0.1..10 V peak in a 1-2-5
#: series; AC/DC, IEPE; trigger on any channel; blocks of 2^8..2^16 samples per channel.
SIGLAB_2042 = CapabilitiesData(
    n_inputs=4,
    sample_rates_hz=(400, 800, 1000, 1600, 2000, 3200, 5000, 6400, 10000, 12800, 20000, 25600, 50000, 51200),
    ranges_mv=(100, 200, 500, 1000, 2000, 5000, 10000),
    block_sizes=tuple(2 ** k for k in range(8, 17)),
    max_pretrigger=32768,
)
__all__ += ["SIGLAB_2042", "decode_block_image", "capabilities_size", "setup_size",
            "ASC_INVALID_OPCODE", "ASC_INVALID_FIELD_CDB", "ASC_INVALID_FIELD_PARAM", "ASC_PARAMETER_LENGTH",
            "ASC_LUN_NOT_SUPPORTED", "ASC_POWER_ON_RESET", "ASC_INTERNAL_FAILURE", "ASC_NOT_READY_SETUP_REQUIRED",
            "ASC_NOT_READY_NO_BLOCK", "ASC_NOT_READY_ARMED"]
