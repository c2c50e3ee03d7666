"""Wire formats: byte layouts checked against hand-written bytes from the specs, round trips, errors."""
from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from acquisition import protocol as P
from acquisition.errors import ProtocolError


def test_struct_sizes_are_the_spec_sizes():
    assert P.CBW.size == 31 and P.CSW.size == 13
    assert P.SENSE.size == 18 and P.INQUIRY.size == 36
    assert P.CDB_TEST_UNIT_READY.size == 6 and P.CDB_REQUEST_SENSE.size == 6 and P.CDB_INQUIRY.size == 6
    assert P.CDB_VENDOR.size == 10 and P.CDB_READ_BLOCK.size == 16
    assert len(P.STREAM_RESET) == 31 and P.STREAM_RESET.startswith(b"USBR")


def test_cbw_bytes_match_the_bulk_only_layout():
    # INQUIRY, tag 7, 36 bytes in: "USBC", tag LE, length LE, flags 0x80, LUN 0, CB length 6, CDB 12 00 00 00 24 00
    raw = P.encode_cbw(7, 36, True, bytes.fromhex("120000002400"))
    assert raw == bytes.fromhex("55534243" "07000000" "24000000" "80" "00" "06" "120000002400" + "00" * 10)
    cbw = P.decode_cbw(raw)
    assert (cbw.tag, cbw.data_length, cbw.data_in, cbw.lun, cbw.cdb, cbw.opcode) == (
        7, 36, True, 0, bytes.fromhex("120000002400"), 0x12)


def test_csw_bytes_and_checks():
    raw = P.encode_csw(0x01020304, 5, 1)
    assert raw == bytes.fromhex("55534253" "04030201" "05000000" "01")
    assert P.decode_csw(raw) == P.Csw(0x01020304, 5, 1)
    with pytest.raises(ProtocolError, match="signature"):
        P.decode_csw(b"USBX" + raw[4:])
    with pytest.raises(ProtocolError, match="13 bytes, got 12"):
        P.decode_csw(raw[:12])
    with pytest.raises(ProtocolError, match="status 3"):
        P.decode_csw(raw[:12] + b"\x03")


@pytest.mark.parametrize("raw, message", [
    (b"USBC" + bytes(26), "31 bytes, got 30"),
    (b"UXBC" + bytes(27), "signature"),
    (P.encode_cbw(1, 0, False, b"\x00")[:12] + b"\x01" + P.encode_cbw(1, 0, False, b"\x00")[13:], "reserved"),
    (P.encode_cbw(1, 0, False, b"\x00")[:14] + b"\x00" + P.encode_cbw(1, 0, False, b"\x00")[15:], "1..16"),
])
def test_bad_cbw_is_refused(raw, message):
    with pytest.raises(ProtocolError, match=message):
        P.decode_cbw(raw)


def test_cdbs_are_big_endian_and_validated():
    assert P.build_cdb(P.Op.TEST_UNIT_READY) == bytes(6)
    assert P.build_cdb(P.Op.REQUEST_SENSE, length=18) == bytes.fromhex("030000001200")
    assert P.build_cdb(P.Op.INQUIRY, evpd=1, page=0x80, length=0x0140) == bytes.fromhex("120180014000")
    assert P.build_cdb(P.Op.GET_STATUS, length=0x0102) == bytes.fromhex("c4010102" + "00" * 6)
    assert P.build_cdb(P.Op.READ_BLOCK, sequence=0x0A0B0C0D, offset=0x10000, count=0x8000) == bytes.fromhex(
        "c501" "0a0b0c0d" "00010000" "00008000" "0000")
    with pytest.raises(ValueError, match="count 65537 is outside 1..65536"):
        P.build_cdb(P.Op.READ_BLOCK, count=65537)
    with pytest.raises(ValueError, match="allocation length 256 is outside 0..255"):
        P.build_cdb(P.Op.REQUEST_SENSE, length=256)
    with pytest.raises(ValueError, match="VPD page 0x83 is not supported"):
        P.build_cdb(P.Op.INQUIRY, evpd=1, page=0x83, length=10)
    with pytest.raises(ValueError, match="no field"):
        P.build_cdb(P.Op.ARM, offset=3)
    spec, fields = P.parse_cdb(bytes.fromhex("c501" "00000001" "00000002" "00000003" "0000"))
    assert spec.name == "READ BLOCK" and (fields["sequence"], fields["offset"], fields["count"]) == (1, 2, 3)


def test_command_table_is_complete_and_consistent():
    assert {op.value for op in P.Op} == set(P.COMMANDS)
    for op, spec in P.COMMANDS.items():
        assert spec.opcode == op and spec.fields[0] == "opcode"
        cdb = P.build_cdb(op, **({"count": 1} if op == P.Op.READ_BLOCK else {}))
        assert len(cdb) == spec.cdb.size and cdb[0] == op
        assert P.command_spec(spec.name) is spec
    assert all(op >= 0xC0 for op in P.COMMANDS if P.COMMANDS[op].cdb in (P.CDB_VENDOR, P.CDB_READ_BLOCK))
    assert not P.command_spec("ARM").idempotent and P.command_spec("READ BLOCK").idempotent


def test_sense_fixed_format():
    raw = P.encode_sense(P.Sense(P.SenseKey.ILLEGAL_REQUEST, 0x24, 0x00))
    assert len(raw) == 18 and raw[0] == 0x70 and raw[2] == 0x05 and raw[7] == 10 and raw[12:14] == b"\x24\x00"
    assert P.decode_sense(raw) == P.Sense(5, 0x24, 0)
    assert "ILLEGAL REQUEST" in P.Sense(5, 0x24, 0).describe() and "invalid field in CDB" in P.Sense(5, 0x24, 0).describe()
    with pytest.raises(ProtocolError, match="fixed format"):
        P.decode_sense(b"\x72" + raw[1:])
    with pytest.raises(ProtocolError, match="too short"):
        P.decode_sense(raw[:10])


def test_inquiry_and_serial_vpd():
    inq = P.Inquiry(0x03, "IMPACTLB", "SIGLAB-SIM 2042", "0100")
    raw = P.encode_inquiry(inq)
    assert len(raw) == 36 and raw[0] == 0x03 and raw[4] == 31
    assert raw[8:16] == b"IMPACTLB" and raw[16:32] == b"SIGLAB-SIM 2042 " and raw[32:36] == b"0100"
    assert P.decode_inquiry(raw) == inq
    vpd = P.encode_serial_vpd("SN42")
    assert vpd == b"\x03\x80\x00\x04SN42" and P.decode_serial_vpd(vpd) == "SN42"
    with pytest.raises(ProtocolError, match="longer than 8"):
        P.encode_inquiry(P.Inquiry(3, "TOOLONGVENDOR", "x", "1"))


def test_capabilities_round_trip_and_version_check():
    raw = P.encode_capabilities(P.SIGLAB_2042)
    assert raw[0] == P.PROTOCOL_VERSION and raw[1] == 4
    assert P.decode_capabilities(raw) == P.SIGLAB_2042
    assert 51200 in P.SIGLAB_2042.sample_rates_hz and max(P.SIGLAB_2042.sample_rates_hz) == 51200
    assert {256, 16384, 65536} <= set(P.SIGLAB_2042.block_sizes)
    assert P.SIGLAB_2042.ranges_mv == (100, 200, 500, 1000, 2000, 5000, 10000)
    with pytest.raises(ProtocolError, match="protocol version 9"):
        P.decode_capabilities(b"\x09" + raw[1:])
    with pytest.raises(ProtocolError, match="announces"):
        P.decode_capabilities(raw[:-4])


def _setup(n: int = 2) -> P.SetupData:
    chans = tuple(P.ChannelRecord(i, "AC", True, "force" if i == 0 else "acceleration", 5000, 0.00225 + i,
                                  f"left:{i}:Y") for i in range(n))
    return P.SetupData(6400, 8192, 128, 0, "falling", -0.045, chans)


def test_setup_layout_and_round_trip():
    s = _setup(2)
    raw = P.encode_setup(s)
    assert len(raw) == P.setup_size(2) == 24 + 2 * 40
    # header by hand: version 1, 2 channels, trigger ch 0, slope 1 (falling), 6400 Hz, 8192, 128, -0.045 V
    assert raw[:24] == struct.pack("<BBBBIIId", 1, 2, 0, 1, 6400, 8192, 128, -0.045)
    # second record: input 1, AC (0), IEPE 1, acceleration (1), 5000 mV, 1.00225 V/unit, point
    assert raw[64:] == struct.pack("<BBBBId", 1, 0, 1, 1, 5000, 1.00225) + b"left:1:Y".ljust(24, b"\0")
    assert P.decode_setup(raw) == s
    with pytest.raises(ProtocolError, match="2 channels need 104"):
        P.decode_setup(raw[:-1])
    with pytest.raises(ProtocolError, match="protocol version 2"):
        P.decode_setup(b"\x02" + raw[1:])


def test_status_and_block_header():
    st = P.StatusData(P.State.BLOCK_READY, 0b0101, True, False, 42, 8192, 1)
    raw = P.encode_status(st)
    assert raw == struct.pack("<BBBBIII", 1, 3, 5, 1, 42, 8192, 1)
    assert P.decode_status(raw) == st and st.overload(4) == [True, False, True, False]
    with pytest.raises(ProtocolError, match="unknown state 7"):
        P.decode_status(raw[:1] + b"\x07" + raw[2:])
    h = P.BlockHeader(4, 2, 9, 256, 16, 51200.0, 1.5)
    assert P.decode_block_header(P.encode_block_header(h)) == h
    assert P.block_image_size(4, 256) == P.BLOCK_HEADER.size + 32 + 2048


@settings(max_examples=60, deadline=None, derandomize=True)
@given(tag=st.integers(0, 2**32 - 1), length=st.integers(0, 2**32 - 1), data_in=st.booleans(),
       cdb=st.binary(min_size=1, max_size=16))
def test_cbw_round_trip_property(tag, length, data_in, cdb):
    c = P.decode_cbw(P.encode_cbw(tag, length, data_in, cdb))
    assert (c.tag, c.data_length, c.data_in, c.cdb) == (tag, length, data_in, cdb)


def test_stream_reset_cannot_be_a_cbw():
    with pytest.raises(ProtocolError):
        P.decode_cbw(P.STREAM_RESET)


DECODERS = [P.decode_cbw, P.decode_csw, P.decode_sense, P.decode_inquiry, P.decode_serial_vpd,
            P.decode_capabilities, P.decode_setup, P.decode_status, P.decode_block_header, P.decode_block_image]


@settings(max_examples=200, deadline=None, derandomize=True)
@given(raw=st.binary(max_size=140), which=st.integers(0, len(DECODERS) - 1))
def test_decoders_fail_only_with_protocol_error(raw, which):
    """Arbitrary bytes either decode or raise ProtocolError (never struct.error, IndexError...)."""
    try:
        DECODERS[which](raw)
    except ProtocolError:
        pass


@settings(max_examples=100, deadline=None, derandomize=True)
@given(raw=st.binary(min_size=24, max_size=24 + 4 * 40))
def test_setup_decoder_on_versioned_garbage(raw):
    raw = b"\x01" + raw[1:]  # right version, random rest: still only ProtocolError or a valid set-up
    try:
        s = P.decode_setup(raw)
    except ProtocolError:
        return
    assert P.decode_setup(P.encode_setup(s)) == s
