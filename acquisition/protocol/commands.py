"""The command descriptor blocks and the command table (``COMMANDS``) that the host validates
against and the firmware dispatches on."""
from __future__ import annotations

import enum
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from .envelope import MAX_TRANSFER, PROTOCOL_VERSION, Direction
from .payloads import VPD_SERIAL_NUMBER, VPD_SUPPORTED_PAGES

__all__ = [
    "Op",
    "CDB_TEST_UNIT_READY",
    "CDB_REQUEST_SENSE",
    "CDB_INQUIRY",
    "CDB_VENDOR",
    "CDB_READ_BLOCK",
    "CommandSpec",
    "COMMANDS",
    "command_spec",
    "build_cdb",
    "parse_cdb",
]


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


def command_spec(opcode_or_name: int | str) -> CommandSpec:
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

