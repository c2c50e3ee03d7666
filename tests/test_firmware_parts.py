"""The firmware's three parts apart: the SCSI handlers without the link, the link without the
capture physics, the capture physics without SCSI or link."""
from __future__ import annotations

import numpy as np
from test_driver import PulseStand

from acquisition import protocol as P
from acquisition.setup import default_setup, setup_to_wire
from simulator.capture import CaptureEngine
from simulator.commands import IDENTITY, ScsiCommands
from simulator.link import GOOD_SENSE, BulkOnlyLink, Reply, fail


class BareDevice(ScsiCommands, CaptureEngine):
    """Command handlers + capture state, no link: commands are called as functions."""

    def __init__(self, stand=None) -> None:
        self.stand = stand
        self.serial = "X-42"
        self.capabilities = P.SIGLAB_2042
        self.strike_after_polls, self.max_strikes, self.margin = 0, 3, 1024
        self._caps_bytes = P.encode_capabilities(self.capabilities)
        self._inquiry_bytes = P.encode_inquiry(IDENTITY)
        self._handlers = self._command_table()
        self._init_capture()
        self._sense, self._unit_attention = GOOD_SENSE, True

    def call(self, op: int, data: bytes = b"", **fields: int) -> Reply:
        spec, parsed = P.parse_cdb(P.build_cdb(op, **fields))
        return self._run(spec, parsed, data)


def test_handlers_answer_without_a_link():
    dev = BareDevice(PulseStand())
    assert P.decode_serial_vpd(bytes(dev.call(P.Op.INQUIRY, evpd=1, page=P.VPD_SERIAL_NUMBER, length=255).data)) == "X-42"
    # REQUEST SENSE reports the power-on UNIT ATTENTION once, then good sense
    first = P.decode_sense(bytes(dev.call(P.Op.REQUEST_SENSE, length=18).data))
    assert (first.key, first.asc) == (P.SenseKey.UNIT_ATTENTION, P.ASC_POWER_ON_RESET[0])
    assert P.decode_sense(bytes(dev.call(P.Op.REQUEST_SENSE, length=18).data)).key == P.SenseKey.NO_SENSE
    # ARM before SET UP is refused with NOT READY, and nothing is armed
    armed = dev.call(P.Op.ARM)
    assert armed.status == P.CswStatus.FAILED and armed.sense.key == P.SenseKey.NOT_READY
    assert dev._state == P.State.IDLE
    wire = P.encode_setup(setup_to_wire(default_setup()))
    assert dev.call(P.Op.SET_UP, wire, length=len(wire)).status == P.CswStatus.PASSED
    assert dev.call(P.Op.ARM).status == P.CswStatus.PASSED  # strike_after_polls=0: struck at ARM
    assert dev._state == P.State.BLOCK_READY


def test_decode_holds_a_command_back_behind_unit_attention():
    dev = BareDevice()
    raw = P.encode_cbw(7, 0, False, P.build_cdb(P.Op.TEST_UNIT_READY))
    spec, _, reply = dev._decode(P.decode_cbw(raw))
    assert spec is not None and reply is not None and reply.sense.key == P.SenseKey.UNIT_ATTENTION
    assert dev._decode(P.decode_cbw(raw))[2] is None  # reported once


class EchoLink(BulkOnlyLink):
    """The link over a fake command set: every command passes and returns ``payload``."""

    def __init__(self, payload: bytes, packetized: bool) -> None:
        self.payload = payload
        self.packetized = packetized
        self.ran: list[int] = []
        self._power_on()
        self._unit_attention = False

    def _decode(self, cbw):
        spec, fields = P.parse_cdb(cbw.cdb)
        return spec, fields, None

    def _run(self, spec, fields, data):
        self.ran.append(spec.opcode)
        return Reply(data=self.payload)


def _inquiry_cbw(tag: int, host_len: int) -> bytes:
    return P.encode_cbw(tag, host_len, True, P.build_cdb(P.Op.INQUIRY, length=36))


def test_link_pads_the_stream_and_reports_the_residue():
    link = EchoLink(b"abc", packetized=False)
    link.write(_inquiry_cbw(5, 8))
    out = link.read(1 << 16)
    assert out[:8] == b"abc" + bytes(5)
    assert P.decode_csw(out[8:]) == P.Csw(5, 5, P.CswStatus.PASSED)


def test_link_reports_a_phase_error_when_the_host_expects_less():
    link = EchoLink(b"0123456789", packetized=True)
    link.write(_inquiry_cbw(6, 4))
    assert link.read(1 << 16) == b"0123"
    assert P.decode_csw(link.read(1 << 16)).status == P.CswStatus.PHASE_ERROR


def test_link_invalid_cbw_stalls_until_reset():
    link = EchoLink(b"x", packetized=True)
    link.write(b"not a cbw")
    assert link.halted_in and link.halted_out
    link.clear_halt(True)
    assert link.halted_in  # ignored before the reset
    link.bulk_only_reset()
    link.clear_halt(True)
    link.clear_halt(False)
    link.write(_inquiry_cbw(8, 1))
    assert link.read(64) == b"x" and link.ran == [P.Op.INQUIRY]


def test_link_stream_reset_frame_discards_a_bad_cbw_state():
    link = EchoLink(b"ok", packetized=False)
    link.write(b"X" * 31)  # invalid CBW: everything discarded
    link.write(_inquiry_cbw(9, 2))
    assert link.read(64) == b"" and link.ran == []
    link.write(P.STREAM_RESET + _inquiry_cbw(10, 2))
    assert link.read(64)[:2] == b"ok" and link.resets == 1


def test_fail_builds_a_failed_reply():
    r = fail(P.SenseKey.NOT_READY, P.ASC_NOT_READY_NO_BLOCK)
    assert r.status == P.CswStatus.FAILED and r.sense.key == P.SenseKey.NOT_READY and r.data == b""


def _struck_engine(stand) -> tuple[CaptureEngine, P.SetupData]:
    """A capture engine with the default set-up, after one strike of ``stand``."""
    eng = CaptureEngine()
    eng.stand, eng.margin = stand, 1024
    eng._init_capture()
    setup = setup_to_wire(default_setup())
    eng._setup = setup
    eng._give_stand(setup)
    eng._start_arm()
    eng._strike()
    return eng, setup


def test_capture_engine_builds_a_block_without_scsi_or_link():
    eng, setup = _struck_engine(PulseStand())
    assert eng._state == P.State.BLOCK_READY and eng._sequence == 1
    header, volts_per_count, counts = P.decode_block_image(eng._block)
    assert header.n_samples == setup.block_size and counts.shape == (len(setup.channels), setup.block_size)
    # the trigger sample sits exactly pretrigger samples into the block
    t = setup.trigger_channel
    level = setup.trigger_level_v / volts_per_count[t]
    k = int(np.flatnonzero(counts[t] >= level)[0])
    assert k == setup.pretrigger


class _WeakStand(PulseStand):
    """The pulse stand with its responses replaced by a constant 0.3 count (a signal below one
    count) and the stand's noise switch given by ``noisy``."""

    def __init__(self, noisy: bool) -> None:
        super().__init__()
        self.noisy = noisy
        self.volts_per_count: np.ndarray | None = None

    def strike(self, fs_hz: float, n_samples: int, pretrigger: int):
        ev = super().strike(fs_hz, n_samples, pretrigger)
        for i, ch in enumerate(self.channels):
            if ch.quantity != "force":
                ev.volts[i] = 0.3 * ch.range_v / 32767
        ev.info["noise"] = self.noisy
        return ev


def _weak_counts(noisy: bool) -> np.ndarray:
    eng, setup = _struck_engine(_WeakStand(noisy))
    _, _, counts = P.decode_block_image(eng._block)
    return counts[[i for i, ch in enumerate(setup.channels) if ch.quantity != "force"]].astype(float)


def test_adc_noise_dithers_the_quantizer_only_while_the_stand_is_noisy():
    # an ideal quantizer rounds a 0.3-count signal to 0 in every sample (the error is a function of
    # the signal: weak responses turn into coherent distortion); the converter's own noise makes
    # the quantized record's mean the signal's
    quiet, noisy = _weak_counts(False), _weak_counts(True)
    assert np.all(quiet == 0)
    assert abs(float(noisy.mean()) - 0.3) < 0.05
    assert 0.3 < float(noisy.std()) < 0.8  # 0.5 count rms plus the quantization's own
