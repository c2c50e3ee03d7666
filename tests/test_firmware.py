"""The simulated firmware at the byte level: bulk-only cases, SCSI sense, stream and packet modes, capture."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_driver import PulseStand

from acquisition import protocol as P
from acquisition.setup import default_setup, setup_to_wire
from simulator.analyser import create_analyser
from simulator.capture import find_trigger as _find_trigger
from simulator.firmware import Firmware, PrecomputedStand

INQ_CDB = bytes.fromhex("120000002400")  # INQUIRY, allocation length 36


def cbw(tag: int, length: int, data_in: bool, cdb: bytes) -> bytes:
    """A CBW written out by hand (independent of the protocol module)."""
    return (b"USBC" + tag.to_bytes(4, "little") + length.to_bytes(4, "little") + bytes([0x80 if data_in else 0, 0,
            len(cdb)]) + cdb.ljust(16, b"\0"))


def csw(tag: int, residue: int, status: int) -> bytes:
    return b"USBS" + tag.to_bytes(4, "little") + residue.to_bytes(4, "little") + bytes([status])


def drain(fw: Firmware) -> bytes:
    out = bytearray()
    while chunk := fw.read(1 << 20):
        out += chunk
    return bytes(out)


def transfers(fw: Firmware) -> list[bytes]:
    out = []
    while chunk := fw.read(1 << 20):
        out.append(chunk)
    return out


def send(fw: Firmware, cbw_bytes: bytes, data: bytes = b"") -> None:
    """CBW then data-out: one write on a stream, two OUT transfers when packetized."""
    if fw.packetized:
        fw.write(cbw_bytes)
        if data:
            fw.write(data)
    else:
        fw.write(cbw_bytes + data)


def clear_ua(fw: Firmware) -> None:
    fw.write(cbw(1, 0, False, bytes(6)))
    drain(fw)
    fw.write(cbw(2, 18, True, bytes.fromhex("030000001200")))
    drain(fw)


def sense(fw: Firmware, tag: int = 99) -> tuple[int, int, int]:
    fw.write(cbw(tag, 18, True, bytes.fromhex("030000001200")))
    out = drain(fw) if not fw.packetized else b"".join(transfers(fw))
    assert out[18:] == csw(tag, 0, 0)
    return out[2] & 0x0F, out[12], out[13]


@pytest.fixture(params=[False, True], ids=["stream", "packetized"])
def fw(request) -> Firmware:
    return Firmware(None, packetized=request.param)


# ---------------------------------------------------------------------- standard commands
def test_inquiry_is_answered_at_power_on(fw):
    fw.write(cbw(5, 36, True, INQ_CDB))
    out = transfers(fw)
    data, status = (out[0], out[1]) if fw.packetized else (out[0][:36], out[0][36:])
    assert data[0] == 0x03 and data[8:16] == b"IMPACTLB" and data[16:32] == b"SIGLAB-SIM 2042 " and data[32:] == b"0100"
    assert status == csw(5, 0, 0)


def test_serial_number_vpd(fw):
    fw.write(cbw(6, 64, True, bytes.fromhex("120180004000")))
    raw = b"".join(transfers(fw))
    n = raw[3]
    assert raw[:4] == bytes([0x03, 0x80, 0, n]) and raw[4:4 + n] == b"SL2042-0000001"
    assert raw[-13:] == csw(6, 64 - 4 - n, 0)


def test_unit_attention_after_power_on_then_cleared(fw):
    fw.write(cbw(1, 0, False, bytes(6)))  # TEST UNIT READY
    assert b"".join(transfers(fw)) == csw(1, 0, 1)
    assert sense(fw) == (0x06, 0x29, 0x00)
    fw.write(cbw(3, 0, False, bytes(6)))
    assert b"".join(transfers(fw)) == csw(3, 0, 0)
    assert sense(fw) == (0, 0, 0)


def test_request_sense_reports_unit_attention_directly(fw):
    assert sense(fw) == (0x06, 0x29, 0x00)
    fw.write(cbw(3, 0, False, bytes(6)))
    assert b"".join(transfers(fw)) == csw(3, 0, 0)


def test_unsupported_opcode_is_illegal_request_0x20(fw):
    clear_ua(fw)
    fw.write(cbw(7, 0, False, bytes([0xD7, 0, 0, 0, 0, 0])))
    assert b"".join(transfers(fw)) == csw(7, 0, 1)
    assert sense(fw) == (0x05, 0x20, 0x00)


def test_invalid_cdb_field_is_illegal_request_0x24(fw):
    clear_ua(fw)
    # GET STATUS with protocol version 9 in byte 1
    fw.write(cbw(8, 0, False, bytes.fromhex("c4090000000000000000")))
    assert b"".join(transfers(fw)) == csw(8, 0, 1)
    assert sense(fw) == (0x05, 0x24, 0x00)


def test_not_ready_before_set_up(fw):
    clear_ua(fw)
    fw.write(cbw(9, 0, False, bytes.fromhex("c3010000000000000000")))  # ARM
    assert b"".join(transfers(fw)) == csw(9, 0, 1)
    assert sense(fw) == (0x02, 0x04, 0x80)


def test_passing_command_clears_the_sense(fw):
    clear_ua(fw)
    fw.write(cbw(9, 0, False, bytes.fromhex("c3010000000000000000")))  # ARM fails
    drain(fw)
    fw.write(cbw(10, 0, False, bytes(6)))
    drain(fw)
    assert sense(fw) == (0, 0, 0)


# ---------------------------------------------------------------------- bulk-only cases
def test_host_expects_more_stream_pads_packet_is_short():
    for packetized in (False, True):
        fw = Firmware(None, packetized=packetized)
        fw.write(cbw(4, 64, True, INQ_CDB))  # case 5: Hi (64) > Di (36)
        out = transfers(fw)
        if packetized:
            assert [len(t) for t in out] == [36, 13]  # a short transfer ends the data phase
        else:
            assert len(out[0]) == 64 + 13 and out[0][36:64] == bytes(28)
        assert out[-1][-13:] == csw(4, 28, 0)


def test_host_expects_less_than_device_has_is_phase_error(fw):
    fw.write(cbw(4, 18, True, INQ_CDB))  # case 7: Hi (18) < Di (36)
    raw = b"".join(transfers(fw))
    assert len(raw) == 18 + 13 and raw[8:16] == b"IMPACTLB"[:8] and raw[18:] == csw(4, 0, 2)


def test_host_expects_no_data_but_device_has_some_is_phase_error(fw):
    fw.write(cbw(4, 0, False, INQ_CDB))  # case 2: Hn < Di
    assert b"".join(transfers(fw)) == csw(4, 0, 2)


def test_data_out_shorter_than_the_parameter_list_is_phase_error(fw):
    clear_ua(fw)
    raw = P.encode_setup(setup_to_wire(default_setup()))
    cdb = bytes.fromhex("c101") + len(raw).to_bytes(2, "big") + bytes(6)
    send(fw, cbw(11, len(raw) - 4, False, cdb), raw[:-4])  # case 13: Ho < Do
    assert drain(fw) == csw(11, len(raw) - 4, 2)
    send(fw, cbw(12, 0, False, bytes.fromhex("c2010000000000000000")))  # GET SET-UP: not configured
    assert drain(fw) == csw(12, 0, 1)  # the command was not executed


def test_direction_mismatch_is_phase_error(fw):
    send(fw, cbw(13, 8, False, INQ_CDB), bytes(8))  # case 10: Ho but the device would send
    assert b"".join(transfers(fw)) == csw(13, 8, 2)


def test_failing_data_in_stalls_in_endpoint_when_packetized():
    fw = Firmware(None, packetized=True)
    clear_ua(fw)
    cdb = bytes.fromhex("c501" "00000001" "00000000" "00000100" "0000")  # READ BLOCK, nothing ready
    fw.write(cbw(20, 256, True, cdb))
    assert fw.halted_in and fw.read(512) == b""
    fw.clear_halt(True)
    assert transfers(fw) == [csw(20, 256, 1)]
    assert sense(fw) == (0x02, 0x04, 0x81)


def test_failing_data_in_is_zero_filled_on_a_stream():
    fw = Firmware(None, packetized=False)
    clear_ua(fw)
    cdb = bytes.fromhex("c501" "00000001" "00000000" "00000100" "0000")
    fw.write(cbw(20, 256, True, cdb))
    assert drain(fw) == bytes(256) + csw(20, 256, 1)


def test_invalid_cbw_stalls_both_endpoints_until_reset_recovery():
    fw = Firmware(None, packetized=True)
    fw.write(cbw(1, 0, False, bytes(6))[:30])  # a 30-byte transfer is not a CBW
    assert fw.halted_in and fw.halted_out
    fw.clear_halt(True), fw.clear_halt(False)
    assert fw.halted_in and fw.halted_out  # halts persist until reset recovery
    fw.bulk_only_reset()
    fw.clear_halt(True), fw.clear_halt(False)
    assert not fw.halted_in and not fw.halted_out
    fw.write(cbw(2, 0, False, bytes(6)))
    assert transfers(fw) == [csw(2, 0, 1)]  # unit attention after the reset
    assert sense(fw) == (0x06, 0x29, 0x00)


def test_stream_invalid_cbw_discards_until_stream_reset():
    fw = Firmware(None, packetized=False)
    clear_ua(fw)
    fw.write(b"garbage!" * 4)  # 32 bytes: the first 31 are an invalid CBW
    fw.write(cbw(3, 0, False, bytes(6)))  # ignored: the firmware waits for a reset frame
    assert drain(fw) == b""
    # the reset frame split over two writes, followed in the same write by a command
    fw.write(b"\x00\x11" + P.STREAM_RESET[:10])
    fw.write(P.STREAM_RESET[10:] + cbw(4, 36, True, INQ_CDB))
    out = drain(fw)
    assert out[8:16] == b"IMPACTLB" and out[36:] == csw(4, 0, 0)
    assert fw.resets == 1


def test_stream_reset_mid_command_abandons_it():
    fw = Firmware(None, packetized=False)
    clear_ua(fw)
    raw = P.encode_setup(setup_to_wire(default_setup()))
    cdb = bytes.fromhex("c101") + len(raw).to_bytes(2, "big") + bytes(6)
    fw.write(cbw(5, len(raw), False, cdb) + raw[:10])  # data-out phase half done
    fw.write(P.STREAM_RESET + cbw(6, 0, False, bytes(6)))
    assert drain(fw) == csw(6, 0, 1)  # the abandoned SET UP never answered; the reset raised UNIT ATTENTION


def test_any_chunking_gives_the_same_bytes():
    whole, bytewise = Firmware(None), Firmware(None)
    stream = cbw(1, 36, True, INQ_CDB) + cbw(2, 0, False, bytes(6)) + cbw(3, 18, True, bytes.fromhex("030000001200"))
    whole.write(stream)
    for i in range(len(stream)):
        bytewise.write(stream[i:i + 1])
    assert drain(whole) == drain(bytewise) and whole.commands_executed == 3


def test_set_up_round_trip_and_rejections(fw):
    clear_ua(fw)
    raw = P.encode_setup(setup_to_wire(default_setup()))
    cdb = bytes.fromhex("c101") + len(raw).to_bytes(2, "big") + bytes(6)
    send(fw, cbw(30, len(raw), False, cdb), raw)
    assert b"".join(transfers(fw)) == csw(30, 0, 0)
    fw.write(cbw(31, len(raw), True, bytes.fromhex("c201") + len(raw).to_bytes(2, "big") + bytes(6)))
    assert b"".join(transfers(fw)) == raw + csw(31, 0, 0)
    # an input range outside the capabilities: 3 V (3000 mV)
    bad = bytearray(raw)
    bad[24 + 4:24 + 8] = (3000).to_bytes(4, "little")
    for tag, payload, asc in ((32, bytes(bad), 0x26), (33, raw[:-40], 0x1A)):
        c = bytes.fromhex("c101") + len(payload).to_bytes(2, "big") + bytes(6)
        send(fw, cbw(tag, len(payload), False, c), payload)
        assert b"".join(transfers(fw)) == csw(tag, len(payload), 1)
        assert sense(fw) == (0x05, asc, 0x00)


# ---------------------------------------------------------------------- trigger search (pure)
def test_find_trigger_rising_and_falling():
    x = np.array([0, 1, 2, 5, 9, 4, -3, -8, 0, 0], dtype=float)
    assert _find_trigger(x, 4.5, "rising", 1, 5) == 3
    assert _find_trigger(x, 4.5, "rising", 4, 5) is None  # the crossing is before the pre-trigger
    assert _find_trigger(x, -2.0, "falling", 2, 4) == 6
    assert _find_trigger(x, -2.0, "falling", 2, 6) == 6  # block [4, 10) just fits
    assert _find_trigger(x, -2.0, "falling", 2, 7) is None  # no room for the block after it


# ---------------------------------------------------------------------- capture state machine

STATUS_CDB = bytes.fromhex("c4010010000000000000")


def configured(polls: int = 1, packetized: bool = False, stand=None) -> tuple[Firmware, bytes]:
    fw = Firmware(stand or PulseStand(), packetized=packetized, strike_after_polls=polls)
    clear_ua(fw)
    # an 8192-sample block: the chunk layout of the READ BLOCK tests below is written for it
    raw = P.encode_setup(setup_to_wire(dataclasses.replace(default_setup(), block_size=8192)))
    send(fw, cbw(40, len(raw), False, bytes.fromhex("c101") + len(raw).to_bytes(2, "big") + bytes(6)), raw)
    assert b"".join(transfers(fw)) == csw(40, 0, 0)
    return fw, raw


def status(fw: Firmware, tag: int) -> P.StatusData:
    fw.write(cbw(tag, 16, True, STATUS_CDB))
    raw = b"".join(transfers(fw))
    assert raw[16:] == csw(tag, 0, 0)
    return P.decode_status(raw[:16])


def command(fw: Firmware, tag: int, cdb_hex: str, length: int = 0) -> bytes:
    fw.write(cbw(tag, length, length > 0, bytes.fromhex(cdb_hex)))
    return b"".join(transfers(fw))


def test_strike_after_polls_makes_armed_observable():
    fw, _ = configured(polls=2)
    assert command(fw, 41, "c3010000000000000000") == csw(41, 0, 0)  # ARM
    assert [status(fw, 42 + i).state for i in range(3)] == [P.State.ARMED, P.State.ARMED, P.State.BLOCK_READY]
    st = status(fw, 50)
    assert (st.sequence, st.samples_available, st.strikes, st.configured) == (1, 8192, 1, True)


def test_polls_zero_strikes_at_arm():
    fw, _ = configured(polls=0)
    command(fw, 41, "c3010000000000000000")
    assert status(fw, 42).state == P.State.BLOCK_READY


def test_read_block_chunks_and_field_checks():
    fw, _ = configured(polls=0)
    command(fw, 41, "c3010000000000000000")
    size = P.block_image_size(4, 8192)
    assert size == 32 + 32 + 4 * 8192 * 2
    image = b""
    for i, off in enumerate(range(0, size, 65536)):
        count = min(65536, size - off)
        cdb = "c501" "00000001" + off.to_bytes(4, "big").hex() + count.to_bytes(4, "big").hex() + "0000"
        out = command(fw, 60 + i, cdb, count)
        assert out[count:] == csw(60 + i, 0, 0)
        image += out[:count]
    header, vpc, counts = P.decode_block_image(image)
    assert (header.sequence, header.n_samples, header.trigger_index, header.sample_rate_hz) == (1, 8192, 128, 6400.0)
    assert np.allclose(vpc, [1.0 / 32767, 5.0 / 32767, 5.0 / 32767, 5.0 / 32767], rtol=1e-15)  # full scale 32767
    # wrong sequence number, offset past the end: invalid field in CDB
    for tag, cdb in ((70, "c501" "00000002" "00000000" "00000100" "0000"),
                     (72, "c501" "00000001" + size.to_bytes(4, "big").hex() + "00000100" "0000")):
        assert command(fw, tag, cdb, 256) == bytes(256) + csw(tag, 256, 1)
        assert sense(fw) == (0x05, 0x24, 0x00)


def test_set_up_while_armed_is_not_ready_and_abort_returns_to_idle():
    fw, raw = configured(polls=5)
    command(fw, 41, "c3010000000000000000")
    c = bytes.fromhex("c101") + len(raw).to_bytes(2, "big") + bytes(6)
    fw.write(cbw(42, len(raw), False, c) + raw)
    assert drain(fw) == csw(42, len(raw), 1)
    assert sense(fw) == (0x02, 0x04, 0x82)
    assert command(fw, 43, "c6010000000000000000") == csw(43, 0, 0)  # ABORT
    assert status(fw, 44).state == P.State.IDLE


def test_reset_abandons_an_armed_capture_but_keeps_a_ready_block():
    fw, _ = configured(polls=0)
    command(fw, 41, "c3010000000000000000")
    fw.write(P.STREAM_RESET)
    clear_ua(fw)
    assert status(fw, 42).state == P.State.BLOCK_READY  # an idempotent READ BLOCK retry still works
    fw2, _ = configured(polls=3)
    command(fw2, 41, "c3010000000000000000")
    fw2.write(P.STREAM_RESET)
    clear_ua(fw2)
    assert status(fw2, 42).state == P.State.IDLE


def test_precomputed_stand_returns_the_same_block_every_time():
    setup = default_setup()
    n = setup.block_size + 1024
    live = PulseStand()
    live.set_channels(setup_to_wire(setup).channels)
    volts = live.strike(setup.sample_rate_hz, n, setup.trigger.pretrigger_samples).volts
    fw, _ = configured(polls=0, stand=PrecomputedStand(volts, setup.sample_rate_hz))
    images = []
    for k in range(2):
        command(fw, 41 + 10 * k, "c3010000000000000000")
        cdb = "c501" + (k + 1).to_bytes(4, "big").hex() + "00000000" "00010000" "0000"
        images.append(command(fw, 42 + 10 * k, cdb, 65536)[:65536])
    h0, h1 = P.decode_block_header(images[0]), P.decode_block_header(images[1])
    assert (h0.sequence, h1.sequence) == (1, 2) and images[0][32:] == images[1][32:]
    with pytest.raises(ValueError, match="precomputed for 6400 Hz"):
        PrecomputedStand(volts, 6400.0).strike(6400.0, n + 1, 128)


def test_create_analyser_options():
    fw = create_analyser({"packetized": True, "polls": "0", "serial": "X1"}, stand=PulseStand())
    assert fw.packetized and fw.strike_after_polls == 0 and fw.serial == "X1"
    with pytest.raises(ValueError, match=r"unknown simulator option\(s\) \['colour'\]"):
        create_analyser({"colour": "red"}, stand=PulseStand())


def test_short_cdb_and_other_lun_are_illegal_requests(fw):
    clear_ua(fw)
    fw.write(cbw(80, 0, False, bytes.fromhex("c5010000000100000000")))  # READ BLOCK cut to 10 bytes
    assert b"".join(transfers(fw)) == csw(80, 0, 1)
    assert sense(fw) == (0x05, 0x24, 0x00)
    raw = bytearray(cbw(81, 0, False, bytes(6)))
    raw[13] = 1  # LUN 1
    fw.write(bytes(raw))
    assert b"".join(transfers(fw)) == csw(81, 0, 1)
    assert sense(fw) == (0x05, 0x25, 0x00)


# ---------------------------------------------------------------------- robustness


@settings(max_examples=60, deadline=None, derandomize=True)
@given(chunks=st.lists(st.binary(min_size=1, max_size=80), max_size=8))
def test_stream_firmware_survives_any_input_and_resyncs(chunks):
    fw = Firmware(None, packetized=False)
    for c in chunks:
        fw.write(c)
        fw.read(1 << 16)
    fw.write(P.STREAM_RESET + cbw(77, 36, True, INQ_CDB))
    out = drain(fw)
    assert out[8:16] == b"IMPACTLB" and out[36:] == csw(77, 0, 0)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(transfers_=st.lists(st.binary(min_size=1, max_size=40), max_size=8))
def test_packetized_firmware_survives_any_transfers_and_recovers(transfers_):
    fw = Firmware(None, packetized=True)
    for t in transfers_:
        fw.write(t)
        fw.read(512)
    fw.bulk_only_reset()
    fw.clear_halt(True), fw.clear_halt(False)
    fw.write(cbw(78, 36, True, INQ_CDB))
    assert transfers(fw) == [P.encode_inquiry(P.Inquiry(3, "IMPACTLB", "SIGLAB-SIM 2042", "0100")), csw(78, 0, 0)]


def test_create_analyser_builds_the_test_stand_with_noise_switch():
    quiet = create_analyser({"seed": 4, "noise": "off"})
    assert quiet.stand.config.noise.enabled is False and quiet.stand.seed == 4 and not quiet.packetized
    noisy = create_analyser({"seed": 4, "noise": True, "packetized": "on"})
    assert noisy.stand.config.noise.enabled is True and noisy.packetized
    with pytest.raises(ValueError, match=r"noise='maybe': use on or off"):
        create_analyser({"noise": "maybe"})
