"""The bulk-only envelope: command block wrapper (CBW) and command status wrapper (CSW), and the
in-band reset of byte streams (see :mod:`acquisition.protocol`)."""
from __future__ import annotations

import enum
import struct
from dataclasses import dataclass

from acquisition.errors import ProtocolError

__all__ = [
    "PROTOCOL_VERSION",
    "MAX_TRANSFER",
    "CBW",
    "CSW",
    "CBW_SIGNATURE",
    "CSW_SIGNATURE",
    "CBW_FLAG_DATA_IN",
    "STREAM_RESET",
    "CswStatus",
    "Direction",
    "Cbw",
    "Csw",
    "encode_cbw",
    "decode_cbw",
    "encode_csw",
    "decode_csw",
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
