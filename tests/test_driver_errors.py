"""Every error path of the host side: envelope faults, sense errors, timeouts, stalls, device gone."""
from __future__ import annotations

import dataclasses
import struct

import pytest
from scripted_transport import CLEAR_IN, RESET, ScriptedTransport
from test_driver import INQUIRY_DATA, cbw, csw

from acquisition import protocol as P
from acquisition.bot import BulkOnly
from acquisition.driver import Analyser
from acquisition.errors import CommandFailed, DeviceGone, EndpointStalled, ProtocolError, SetupError, TransportTimeout
from acquisition.loopback import LoopbackTransport
from acquisition.setup import (
    AcquisitionSetup,
    Capabilities,
    TriggerSetup,
    default_setup,
    load_setup,
    setup_from_wire,
    setup_to_wire,
    validate_setup,
)
from simulator.firmware import Firmware

TUR = "000000000000"
SENSE_CDB = "030000001200"
ARM = "c3010000000000000000"
STATUS = "c4010010000000000000"
STATUS_IDLE = struct.pack("<BBBBIII", 1, 0, 0, 1, 0, 0, 0)


def sense_bytes(key: int, asc: int, ascq: int) -> bytes:
    return bytes([0x70, 0, key, 0, 0, 0, 0, 10, 0, 0, 0, 0, asc, ascq, 0, 0, 0, 0])


def failing(tag: int, cdb_hex: str, key: int, asc: int, ascq: int = 0) -> list:
    """A command answered with status 1, then REQUEST SENSE with the given sense."""
    return [(cbw(tag, 0, False, cdb_hex), csw(tag, 0, 1)),
            (cbw(tag + 1, 18, True, SENSE_CDB), sense_bytes(key, asc, ascq) + csw(tag + 1))]


# ---------------------------------------------------------------------- envelope faults
def test_bad_csw_signature_resets_and_retries_an_idempotent_command():
    t = ScriptedTransport([
        (cbw(1, 36, True, "120000002400"), INQUIRY_DATA + b"USBX" + csw(1)[4:]),
        RESET,
        (cbw(2, 36, True, "120000002400"), INQUIRY_DATA + csw(2)),
    ])
    bot = BulkOnly(t)
    assert bot.command(P.Op.INQUIRY, length=36).data == INQUIRY_DATA
    t.check_done()
    assert bot.recoveries == 1


def test_bad_csw_signature_on_a_non_idempotent_command_raises():
    t = ScriptedTransport([(cbw(1, 0, False, ARM), b"XXXX" + csw(1)[4:]), RESET])
    with pytest.raises(ProtocolError, match=r"bad CSW signature 0x58585858.*reset recovery"):
        BulkOnly(t).command(P.Op.ARM)
    t.check_done()


def test_wrong_tag_resets_and_raises():
    t = ScriptedTransport([(cbw(1, 0, False, ARM), csw(7)), RESET])
    with pytest.raises(ProtocolError, match="status carries tag 7, the command was sent with tag 1"):
        BulkOnly(t).command(P.Op.ARM)
    t.check_done()


def test_phase_error_resets_then_raises_for_arm():
    t = ScriptedTransport([(cbw(1, 0, False, ARM), csw(1, 0, 2)), RESET])
    with pytest.raises(ProtocolError, match="phase error"):
        BulkOnly(t).command(P.Op.ARM)
    t.check_done()


def test_phase_error_on_get_status_is_retried_once_then_raised():
    t = ScriptedTransport([
        (cbw(1, 16, True, STATUS), bytes(16) + csw(1, 0, 2)), RESET,
        (cbw(2, 16, True, STATUS), bytes(16) + csw(2, 0, 2)), RESET,
    ])
    with pytest.raises(ProtocolError, match="GET STATUS ended with a phase error"):
        BulkOnly(t).command(P.Op.GET_STATUS, length=16)
    t.check_done()


def test_short_transfer_that_contradicts_the_residue_is_a_protocol_fault():
    # USB: 10 bytes arrive but the status claims all 16 were sent -> reset recovery, retry succeeds
    t = ScriptedTransport([
        (cbw(1, 16, True, STATUS), [STATUS_IDLE[:10], csw(1)]), RESET,
        (cbw(2, 16, True, STATUS), [STATUS_IDLE, csw(2)]),
    ], packetized=True)
    assert BulkOnly(t).command(P.Op.GET_STATUS, length=16).data == STATUS_IDLE
    t.check_done()


def test_residue_larger_than_the_request_is_a_protocol_fault():
    t = ScriptedTransport([(cbw(1, 0, False, ARM), csw(1, residue=4)), RESET])
    with pytest.raises(ProtocolError, match="residue 4 exceeds"):
        BulkOnly(t).command(P.Op.ARM)
    t.check_done()


def test_timeout_resets_the_link_and_says_what_to_check():
    t = ScriptedTransport([(cbw(1, 36, True, "120000002400"), INQUIRY_DATA[:20]), RESET])
    with pytest.raises(TransportTimeout, match="no answer to INQUIRY.*check that the analyser is on"):
        BulkOnly(t, timeout_s=0.5).command(P.Op.INQUIRY, length=36)
    t.check_done()


def test_device_gone_mid_read_is_surfaced_with_the_command_name():
    t = ScriptedTransport([(cbw(1, 16, True, STATUS), [DeviceGone("USB device disconnected")])], packetized=True)
    with pytest.raises(DeviceGone, match="went away during GET STATUS.*open the device again"):
        Analyser(t).status()
    t.check_done()


def test_device_gone_between_block_chunks_names_read_block():
    from test_driver import SETUP, SETUP_WIRE, caps_script

    ready = struct.pack("<BBBBIII", 1, 3, 0, 1, 4, 256, 1)
    t = ScriptedTransport(caps_script() + [
        (cbw(3, 64, False, "c1010040000000000000") + SETUP_WIRE, csw(3)),
        (cbw(4, 64, True, "c2010040000000000000"), SETUP_WIRE + csw(4)),
        (cbw(5, 16, True, STATUS), ready + csw(5)),
        (cbw(6, 256, True, "c501" "00000004" "00000000" "00000100" "0000"), bytes(256) + csw(6)),
        (cbw(7, 256, True, "c501" "00000004" "00000100" "00000100" "0000"),
         [DeviceGone("read from socket://127.0.0.1:5025: connection closed by the server")]),
    ])
    an = Analyser(t)
    an.configure(SETUP)
    with pytest.raises(DeviceGone, match=r"went away during READ BLOCK \(read from socket.*connection closed"):
        an.read_block()
    t.check_done()


def test_a_closed_loopback_is_a_gone_device():
    t = LoopbackTransport(Firmware(None))
    an = Analyser(t)
    an.close()
    an.close()  # idempotent
    with pytest.raises(DeviceGone, match="loopback transport is closed"):
        an.identify()


def test_stalled_data_phase_is_cleared_then_the_status_read():
    # the device stalls IN on a failing data-in command; the CSW comes after the halt is cleared
    t = ScriptedTransport([
        (cbw(1, 16, True, STATUS), [EndpointStalled("stall"), csw(1, 16, 1)]), CLEAR_IN,
        (cbw(2, 18, True, SENSE_CDB), [sense_bytes(0x05, 0x24, 0), csw(2)]),
    ], packetized=True)
    with pytest.raises(CommandFailed) as err:
        BulkOnly(t).command(P.Op.GET_STATUS, length=16)
    t.check_done()
    assert (err.value.sense_key, err.value.asc) == (0x05, 0x24)


# ---------------------------------------------------------------------- sense errors
@pytest.mark.parametrize("key, asc, ascq, words", [
    (0x05, 0x20, 0x00, r"ILLEGAL REQUEST \(ASC 0x20/0x00: invalid command operation code\); the analyser does not"),
    (0x05, 0x24, 0x00, r"ILLEGAL REQUEST \(ASC 0x24/0x00: invalid field in CDB\)"),
    (0x02, 0x04, 0x80, r"NOT READY \(ASC 0x04/0x80: not ready: set-up required\); send a set-up"),
    (0x02, 0x04, 0x81, r"NOT READY \(ASC 0x04/0x81: not ready: no block available\)"),
])
def test_sense_errors_raise_command_failed_with_readable_text(key, asc, ascq, words):
    t = ScriptedTransport(failing(1, ARM, key, asc, ascq))
    with pytest.raises(CommandFailed, match=words) as err:
        BulkOnly(t).command(P.Op.ARM)
    t.check_done()
    assert (err.value.opcode, err.value.sense_key, err.value.asc, err.value.ascq) == (0xC3, key, asc, ascq)
    assert "ARM failed" in str(err.value)


def test_unit_attention_is_retried_once():
    t = ScriptedTransport(failing(1, TUR, 0x06, 0x29) + [(cbw(3, 0, False, TUR), csw(3))])
    BulkOnly(t).command(P.Op.TEST_UNIT_READY)
    t.check_done()


def test_repeated_unit_attention_is_raised():
    t = ScriptedTransport(failing(1, TUR, 0x06, 0x29) + failing(3, TUR, 0x06, 0x29))
    with pytest.raises(CommandFailed, match="UNIT ATTENTION.*power on, reset.*configure it again if it was powered on"):
        BulkOnly(t).command(P.Op.TEST_UNIT_READY)
    t.check_done()


def test_failing_request_sense_is_a_protocol_error():
    t = ScriptedTransport([(cbw(1, 0, False, ARM), csw(1, 0, 1)),
                           (cbw(2, 18, True, SENSE_CDB), bytes(18) + csw(2, 18, 1)), RESET])
    with pytest.raises(ProtocolError, match="REQUEST SENSE itself failed"):
        BulkOnly(t).command(P.Op.ARM)
    t.check_done()


def test_fields_are_validated_before_anything_is_written():
    t = ScriptedTransport([])
    with pytest.raises(ValueError, match="READ BLOCK: count 70000 is outside 1..65536"):
        BulkOnly(t).command(P.Op.READ_BLOCK, length=70000, count=70000)
    t.check_done()


def test_tags_increment_and_wrap():
    t = ScriptedTransport([(cbw(0xFFFFFFFF, 0, False, TUR), csw(0xFFFFFFFF)), (cbw(0, 0, False, TUR), csw(0))])
    bot = BulkOnly(t, first_tag=0xFFFFFFFF)
    bot.command(P.Op.TEST_UNIT_READY)
    bot.command(P.Op.TEST_UNIT_READY)
    t.check_done()


# ---------------------------------------------------------------------- set-up validation


CAPS = Capabilities.from_wire(P.SIGLAB_2042)


def _with_channel(i: int, **changes) -> AcquisitionSetup:
    s = default_setup()
    chans = list(s.channels)
    chans[i] = dataclasses.replace(chans[i], **changes)
    return dataclasses.replace(s, channels=tuple(chans))


@pytest.mark.parametrize("setup, message", [
    (dataclasses.replace(default_setup(), sample_rate_hz=48000.0), r"sample rate 48000 Hz is not offered; choose one of 400, "),
    (dataclasses.replace(default_setup(), block_size=1000), r"block size 1000 is not offered; choose one of 256, 512, "),
    (_with_channel(1, range_v=3.0), r"channel 1 \('acc1'\): input range 3 V is not offered; choose one of 0.1, 0.2, 0.5, 1, 2, 5, 10 V"),
    (_with_channel(1, sensitivity_unit="mV/N"), r"acceleration sensor's sensitivity is given in mV/g"),
    (_with_channel(2, coupling="DC"), r"IEPE sensors need AC coupling"),
    (_with_channel(3, point="roof"), r"channel 3 \('acc3'\): bad point label|component:node:direction"),
    (_with_channel(0, sensitivity=-1.0), r"must be positive"),
    (dataclasses.replace(default_setup(), trigger=TriggerSetup(0, 500.0, "rising", 128)),
     r"trigger level 500 N is 1.125 V at the input, outside the 1 V range"),
    (dataclasses.replace(default_setup(), trigger=TriggerSetup(4, 20.0, "rising", 128)), r"trigger channel 4 does not exist"),
    (dataclasses.replace(default_setup(), trigger=TriggerSetup(0, 20.0, "up", 128)), r"slope 'up' must be one of rising, falling"),
    (dataclasses.replace(default_setup(), block_size=8192, trigger=TriggerSetup(0, 20.0, "rising", 8192)),
     r"pre-trigger of 8192 samples is outside 0..8191"),
    (dataclasses.replace(default_setup(), channels=default_setup().channels * 2), r"8 channels set up; the analyser has 1..4 inputs"),
])
def test_setup_validation_names_the_value_and_the_allowed_ones(setup, message):
    with pytest.raises(SetupError, match=message):
        validate_setup(setup, CAPS)


def test_default_setup_is_valid_and_round_trips():
    s = default_setup()
    validate_setup(s, CAPS)
    assert [c.point for c in s.channels] == ["right:6:-X", "left:9:Y", "top:4:X", "right:4:-Z"]
    assert s.bandwidth_hz == pytest.approx(2500.0)
    assert AcquisitionSetup.from_dict(s.to_dict()) == s
    back = setup_from_wire(P.decode_setup(P.encode_setup(setup_to_wire(s))), [c.name for c in s.channels])
    assert back == s


def test_setup_files_json_and_toml(tmp_path):
    import json

    s = default_setup()
    (tmp_path / "s.json").write_text(json.dumps(s.to_dict()))
    assert load_setup(tmp_path / "s.json") == s
    toml = ['sample_rate_hz = 6400', f'block_size = {s.block_size}', '[trigger]', 'channel = 0', 'level = 20.0',
            'slope = "rising"', 'pretrigger_samples = 128']
    for ch in s.channels:
        toml += ['[[channels]]'] + [f'{k} = {json.dumps(v)}' for k, v in dataclasses.asdict(ch).items()]
    (tmp_path / "s.toml").write_text("\n".join(toml))
    assert load_setup(tmp_path / "s.toml") == s
    (tmp_path / "bad.json").write_text('{"sample_rate_hz": 6400, "block_size": 8192, "channels": [], "colour": 1}')
    with pytest.raises(SetupError, match=r"unknown key\(s\) \['colour'\]"):
        load_setup(tmp_path / "bad.json")
    with pytest.raises(SetupError, match="cannot read set-up file"):
        load_setup(tmp_path / "missing.json")


# ---------------------------------------------------------------------- resynchronisation with the real firmware
def test_stream_resync_after_line_noise():
    fw = Firmware(None, packetized=False)
    an = Analyser(LoopbackTransport(fw), timeout_s=0.5)
    assert an.identify().vendor == "IMPACTLB"
    fw.write(b"\xff" * 40)  # line noise: the firmware now ignores everything until a reset frame
    with pytest.raises(TransportTimeout, match="no answer to INQUIRY.*the link was reset"):
        an.identify()
    assert fw.resets == 1
    assert an.identify().serial == "SL2042-0000001"  # back in step after the in-band reset frame
    an.test_unit_ready()  # the unit attention of the reset was retried transparently


def test_packetized_invalid_cbw_is_recovered_and_an_idempotent_command_retried():
    fw = Firmware(None, packetized=True)
    an = Analyser(LoopbackTransport(fw), timeout_s=0.5)
    fw.write(b"\x00" * 30)  # a transfer that is not a CBW: both endpoints stall
    assert fw.halted_in and fw.halted_out
    assert an.capabilities().n_inputs == 4  # OUT stall -> reset recovery -> retry (-> unit attention -> retry)
    assert an.bot.recoveries == 1 and fw.resets == 1 and not fw.halted_out
