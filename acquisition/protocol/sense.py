"""SCSI sense data (18-byte fixed format), sense keys and the analyser's additional sense codes."""
from __future__ import annotations

import enum
import struct
from collections.abc import Mapping
from dataclasses import dataclass

from acquisition.errors import ProtocolError

__all__ = [
    "SenseKey",
    "ASC_INVALID_OPCODE",
    "ASC_INVALID_FIELD_CDB",
    "ASC_INVALID_FIELD_PARAM",
    "ASC_LUN_NOT_SUPPORTED",
    "ASC_PARAMETER_LENGTH",
    "ASC_POWER_ON_RESET",
    "ASC_INTERNAL_FAILURE",
    "ASC_NOT_READY_SETUP_REQUIRED",
    "ASC_NOT_READY_NO_BLOCK",
    "ASC_NOT_READY_ARMED",
    "sense_key_name",
    "asc_meaning",
    "SENSE",
    "SENSE_RESPONSE_CODE",
    "Sense",
    "encode_sense",
    "decode_sense",
]


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
