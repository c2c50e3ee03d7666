"""Fuzzing the wire-format decoders and the firmware's input path with hypothesis.

Only :class:`acquisition.errors.ProtocolError` (with a message) may come out of a decoder; the
firmware never raises on any input and always keeps its bulk-only invariants. The number of
cases per test is ``IMPACTLAB_FUZZ_EXAMPLES`` (default 200; ``benchmarks/reliability/fuzz_long.py`` runs 10 000).
"""
from __future__ import annotations

import os
import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from acquisition import protocol as P
from acquisition.errors import ProtocolError
from simulator.firmware import Firmware

N = int(os.environ.get("IMPACTLAB_FUZZ_EXAMPLES", "200"))
FUZZ = settings(max_examples=N, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow])

DECODERS = [P.decode_cbw, P.decode_csw, P.decode_sense, P.decode_inquiry, P.decode_serial_vpd,
            P.decode_capabilities, P.decode_setup, P.decode_status, P.decode_block_header, P.decode_block_image]

# valid images to mutate (mutations of valid bytes reach deeper than random bytes)
_VALID = {
    P.decode_cbw: P.encode_cbw(5, 16, True, P.build_cdb(P.Op.GET_STATUS, length=16)),
    P.decode_csw: P.encode_csw(5, 0, 0),
    P.decode_sense: P.encode_sense(P.Sense(P.SenseKey.NOT_READY, 4, 0x81)),
    P.decode_inquiry: P.encode_inquiry(P.Inquiry(P.DEVICE_TYPE_PROCESSOR, "IMPACTLB", "SIGLAB-SIM 2042", "0100")),
    P.decode_serial_vpd: P.encode_serial_vpd("SL2042-0000001"),
    P.decode_capabilities: P.encode_capabilities(P.SIGLAB_2042),
    P.decode_status: P.encode_status(P.StatusData(P.State.BLOCK_READY, 1, True, False, 7, 256, 1)),
    P.decode_block_header: P.encode_block_header(P.BlockHeader(2, 0, 7, 4, 1, 6400.0, 0.0)),
    P.decode_block_image: P.encode_block_header(P.BlockHeader(2, 0, 7, 4, 1, 6400.0, 0.0)) + bytes(16 + 16),
}


def _valid_setup() -> bytes:
    from acquisition.setup import default_setup, setup_to_wire

    return P.encode_setup(setup_to_wire(default_setup()))


def _decode_ok_or_protocol_error(decoder, raw: bytes) -> None:
    try:
        decoder(raw)
    except ProtocolError as exc:
        assert str(exc), f"{decoder.__name__}: ProtocolError without a message"


@st.composite
def mutated(draw, base: bytes) -> bytes:
    """``base`` with a few bytes replaced, inserted, deleted, or truncated/extended."""
    b = bytearray(base)
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(("set", "insert", "delete", "truncate", "extend")))
        pos = draw(st.integers(0, max(len(b), 1) - 1)) if b else 0
        if op == "set" and b:
            b[pos] = draw(st.integers(0, 255))
        elif op == "insert":
            b[pos:pos] = draw(st.binary(min_size=1, max_size=8))
        elif op == "delete" and b:
            del b[pos:pos + draw(st.integers(1, 8))]
        elif op == "truncate":
            del b[draw(st.integers(0, len(b))):]
        else:
            b += draw(st.binary(min_size=1, max_size=16))
    return bytes(b)


@pytest.mark.parametrize("decoder", DECODERS, ids=lambda d: d.__name__)
@FUZZ
@given(raw=st.binary(max_size=300))
def test_decoders_on_random_bytes(decoder, raw):
    _decode_ok_or_protocol_error(decoder, raw)


@pytest.mark.parametrize("decoder", DECODERS, ids=lambda d: d.__name__)
@FUZZ
@given(data=st.data())
def test_decoders_on_mutated_valid_images(decoder, data):
    base = _valid_setup() if decoder is P.decode_setup else _VALID[decoder]
    _decode_ok_or_protocol_error(decoder, data.draw(mutated(base)))


@FUZZ
@given(raw=st.binary(max_size=200), chunks=st.lists(st.integers(1, 64), max_size=8),
       packetized=st.booleans())
def test_firmware_survives_any_input_bytes(raw, chunks, packetized):
    """Any bytes, in any chunking, on either link: no exception, output is whole CSWs/data only."""
    fw = Firmware(None, packetized=packetized)
    pos = 0
    for c in chunks + [len(raw)]:
        if fw.halted_out:
            fw.bulk_only_reset()
            fw.clear_halt(True)
            fw.clear_halt(False)
        fw.write(raw[pos:pos + c])
        pos += c
        while fw.read(1 << 16):
            pass
    # after reset recovery the firmware answers a well-formed command properly
    fw.write(P.STREAM_RESET) if not packetized else fw.bulk_only_reset()
    fw.clear_halt(True)
    fw.clear_halt(False)
    fw.read(1 << 20)
    fw.write(P.encode_cbw(99, 36, True, P.build_cdb(P.Op.INQUIRY, length=36)))
    got = fw.read(36) if packetized else fw.read(36 + 13)
    data, csw = (got, fw.read(13)) if packetized else (got[:36], got[36:])
    assert P.decode_inquiry(data).vendor == "IMPACTLB"
    assert P.decode_csw(csw) == P.Csw(99, 0, 0)


@st.composite
def cbws(draw) -> bytes:
    """Well-framed CBWs with random opcodes, CDB bytes, lengths, directions and LUNs."""
    opcode = draw(st.sampled_from([int(o) for o in P.Op] + [0x01, 0x28, 0xC7, 0xFF]))
    cdb = bytes([opcode]) + draw(st.binary(min_size=0, max_size=15))
    length = draw(st.sampled_from([0, 1, 13, 16, 18, 36, 64, 200, 70000]))
    return P.CBW.pack(P.CBW_SIGNATURE, draw(st.integers(0, 2**32 - 1)), length,
                      P.CBW_FLAG_DATA_IN if draw(st.booleans()) else 0, draw(st.integers(0, 15)), len(cdb),
                      cdb.ljust(16, b"\0"))


@FUZZ
@given(commands=st.lists(st.tuples(cbws(), st.binary(max_size=300)), min_size=1, max_size=6),
       packetized=st.booleans())
def test_firmware_answers_every_framed_command_with_one_csw(commands, packetized):
    """Random commands (valid frame, random content): each gets exactly one CSW with its tag, a
    status 0/1/2 and a residue <= the announced length, and the link stays usable."""
    fw = Firmware(None, packetized=packetized)
    for raw, out_data in commands:
        cbw = P.decode_cbw(raw)
        fw.write(raw)
        if not cbw.data_in and cbw.data_length:
            fw.write(out_data[:cbw.data_length].ljust(cbw.data_length, b"\0"))
        if packetized:
            last = b""
            for _ in range(8):
                if fw.halted_in:
                    fw.clear_halt(True)
                chunk = fw.read(1 << 20)
                if not chunk:
                    break
                last = chunk
            if fw.halted_out:  # an invalid CBW (e.g. data-out of a different length): reset recovery
                fw.bulk_only_reset()
                fw.clear_halt(True)
                fw.clear_halt(False)
                continue
            csw = P.decode_csw(last)
        else:
            out = b""
            while True:
                chunk = fw.read(1 << 20)
                if not chunk:
                    break
                out += chunk
            csw = P.decode_csw(out[-13:])
            assert len(out) == (cbw.data_length if cbw.data_in else 0) + 13 or csw.status == 2
        assert csw.tag == cbw.tag and csw.status in (0, 1, 2) and csw.residue <= cbw.data_length


def test_struct_errors_never_escape_for_short_inputs():
    """Every decoder on every prefix of its valid image: ProtocolError or a value, never struct.error."""
    for decoder in DECODERS:
        base = _valid_setup() if decoder is P.decode_setup else _VALID[decoder]
        for k in range(len(base) + 1):
            try:
                decoder(base[:k])
            except ProtocolError:
                pass
            except struct.error as exc:  # pragma: no cover - the failure this test looks for
                pytest.fail(f"{decoder.__name__} leaked struct.error on {k} bytes: {exc}")
