"""The data-phase payloads: INQUIRY data and VPD pages, capabilities, set-up, status and the block
image (little-endian, each starting with the protocol version byte)."""
from __future__ import annotations

import enum
import struct
from dataclasses import dataclass, field

import numpy as np

from acquisition.errors import ProtocolError, SetupError

from .envelope import MAX_TRANSFER, PROTOCOL_VERSION

__all__ = [
    "SIGLAB_2042",
    "INQUIRY",
    "DEVICE_TYPE_PROCESSOR",
    "VPD_SUPPORTED_PAGES",
    "VPD_SERIAL_NUMBER",
    "VPD_HEADER",
    "Inquiry",
    "encode_inquiry",
    "decode_inquiry",
    "encode_serial_vpd",
    "decode_serial_vpd",
    "CAPS_HEADER",
    "CAPS_FLAG_AC",
    "CAPS_FLAG_DC",
    "CAPS_FLAG_IEPE",
    "CAPS_FLAG_TRIGGER_ANY_CHANNEL",
    "CapabilitiesData",
    "encode_capabilities",
    "decode_capabilities",
    "capabilities_size",
    "SETUP_HEADER",
    "CHANNEL_RECORD",
    "QUANTITIES",
    "COUPLINGS",
    "SLOPES",
    "ChannelRecord",
    "SetupData",
    "setup_size",
    "encode_setup",
    "decode_setup",
    "State",
    "STATUS",
    "STATUS_FLAG_CONFIGURED",
    "STATUS_FLAG_NO_TRIGGER",
    "StatusData",
    "encode_status",
    "decode_status",
    "BLOCK_HEADER",
    "BlockHeader",
    "block_image_size",
    "encode_block_header",
    "decode_block_header",
    "decode_block_image",
]


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
