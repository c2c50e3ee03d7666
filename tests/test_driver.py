"""The driver's exact byte conversation (no device), and the driver end to end over the real firmware."""
from __future__ import annotations

import dataclasses
import struct
from types import SimpleNamespace

import numpy as np
import pytest
from scripted_transport import ScriptedTransport

from acquisition import protocol as P
from acquisition.driver import Analyser, Block
from acquisition.errors import CommandFailed, SetupError, TriggerTimeout
from acquisition.loopback import LoopbackTransport
from acquisition.setup import AcquisitionSetup, ChannelSetup, TriggerSetup, default_setup
from simulator.analyser import create_analyser
from simulator.firmware import Firmware


def cbw(tag: int, length: int, data_in: bool, cdb_hex: str) -> bytes:
    cdb = bytes.fromhex(cdb_hex)
    return (b"USBC" + tag.to_bytes(4, "little") + length.to_bytes(4, "little")
            + bytes([0x80 if data_in else 0x00, 0, len(cdb)]) + cdb.ljust(16, b"\0"))


def csw(tag: int, residue: int = 0, status: int = 0) -> bytes:
    return b"USBS" + tag.to_bytes(4, "little") + residue.to_bytes(4, "little") + bytes([status])


INQUIRY_DATA = bytes([0x03, 0, 0x05, 0x02, 31, 0, 0, 0]) + b"IMPACTLB" + b"SIGLAB-SIM 2042 " + b"0100"
# capabilities: v1, 4 inputs, 2 rates, 1 range, 1 block size, flags AC|DC|IEPE|any-channel, 16 bit,
# max transfer 256 bytes, max pre-trigger 100; rates 1000, 51200 Hz; range 10000 mV; block 256
CAPS_HEAD = struct.pack("<BBBBBBBxII", 1, 4, 2, 1, 1, 0x0F, 16, 256, 100)
CAPS_BODY = struct.pack("<4I", 1000, 51200, 10000, 256)
SETUP = AcquisitionSetup(1000.0, 256, (ChannelSetup("hammer", "right:6:-X", "force", 2.0, "mV/N", "AC", True, 10.0),),
                         TriggerSetup(0, 50.0, "rising", 16))
# the same set-up on the wire: header (v1, 1 channel, trigger ch 0, rising, 1000 Hz, 256, 16, 0.1 V)
# and one record (input 0, AC, IEPE, force, 10000 mV, 0.002 V/N, point)
SETUP_WIRE = (struct.pack("<BBBBIIId", 1, 1, 0, 0, 1000, 256, 16, 50.0 * 0.002)
              + struct.pack("<BBBBId", 0, 0, 1, 0, 10000, 0.002) + b"right:6:-X".ljust(24, b"\0"))


def caps_script(first_tag: int = 1) -> list:
    t = first_tag
    return [(cbw(t, 16, True, "c0010010000000000000"), CAPS_HEAD + csw(t)),
            (cbw(t + 1, 32, True, "c0010020000000000000"), CAPS_HEAD + CAPS_BODY + csw(t + 1))]


def test_identify_conversation():
    vpd = bytes([0x03, 0x80, 0x00, 0x04]) + b"SN42"
    t = ScriptedTransport([
        (cbw(1, 36, True, "120000002400"), INQUIRY_DATA + csw(1)),
        (cbw(2, 64, True, "120180004000"), vpd + bytes(56) + csw(2, residue=56)),  # stream: padded
    ])
    ident = Analyser(t).identify()
    t.check_done()
    assert (ident.vendor, ident.product, ident.revision, ident.serial) == ("IMPACTLB", "SIGLAB-SIM 2042", "0100", "SN42")


def test_capabilities_conversation():
    t = ScriptedTransport(caps_script())
    caps = Analyser(t).capabilities()
    t.check_done()
    assert caps.n_inputs == 4 and caps.sample_rates_hz == (1000.0, 51200.0) and caps.ranges_v == (10.0,)
    assert caps.block_sizes == (256,) and caps.couplings == ("AC", "DC") and caps.iepe and caps.max_transfer == 256


def test_configure_conversation_validates_writes_and_reads_back():
    t = ScriptedTransport(caps_script() + [
        (cbw(3, 64, False, "c1010040000000000000") + SETUP_WIRE, csw(3)),
        (cbw(4, 64, True, "c2010040000000000000"), SETUP_WIRE + csw(4)),
    ])
    an = Analyser(t)
    an.configure(SETUP)
    t.check_done()
    assert an.setup == SETUP


def test_configure_refuses_a_bad_setup_before_writing():
    t = ScriptedTransport(caps_script())  # only the capabilities may be asked
    bad = AcquisitionSetup(2000.0, 256, SETUP.channels, SETUP.trigger)
    with pytest.raises(SetupError, match="sample rate 2000 Hz is not offered; choose one of 1000, 51200 Hz"):
        Analyser(t).configure(bad)
    t.check_done()


def _image(seq: int) -> tuple[bytes, np.ndarray, float]:
    counts = ((np.arange(256) * 97) % 4001 - 2000).astype("<i2")
    vpc = 10.0 / 32768
    head = struct.pack("<BBBxIIIdd", 1, 1, 1, seq, 256, 16, 1000.0, 12.5)  # overload on channel 0
    return head + struct.pack("<d", vpc) + counts.tobytes(), counts, vpc


def test_capture_conversation_arm_poll_read_in_chunks_abort():
    image, counts, vpc = _image(9)
    assert len(image) == 32 + 8 + 512
    status_armed = struct.pack("<BBBBIII", 1, 1, 0, 1, 8, 0, 0)
    status_ready = struct.pack("<BBBBIII", 1, 3, 1, 1, 9, 256, 1)
    t = ScriptedTransport(caps_script() + [
        (cbw(3, 64, False, "c1010040000000000000") + SETUP_WIRE, csw(3)),
        (cbw(4, 64, True, "c2010040000000000000"), SETUP_WIRE + csw(4)),
        (cbw(5, 0, False, "c3010000000000000000"), csw(5)),                       # ARM
        (cbw(6, 16, True, "c4010010000000000000"), status_armed + csw(6)),        # GET STATUS: armed
        (cbw(7, 16, True, "c4010010000000000000"), status_ready + csw(7)),        # GET STATUS: block ready
        (cbw(8, 256, True, "c501" "00000009" "00000000" "00000100" "0000"), image[:256] + csw(8)),
        (cbw(9, 256, True, "c501" "00000009" "00000100" "00000100" "0000"), image[256:512] + csw(9)),
        (cbw(10, 40, True, "c501" "00000009" "00000200" "00000028" "0000"), image[512:] + csw(10)),
        (cbw(11, 0, False, "c6010000000000000000"), csw(11)),                     # ABORT
    ])
    with Analyser(t) as an:
        an.configure(SETUP)
        block = an.capture(timeout_s=1.0)
        an.abort()
    t.check_done()
    assert t.closed
    assert isinstance(block, Block) and block.sequence == 9 and block.trigger_index == 16
    assert block.sample_rate_hz == 1000.0 and block.device_time_s == 12.5 and block.overload.tolist() == [True]
    assert block.counts.dtype == np.int16 and np.array_equal(block.counts[0], counts)
    assert np.allclose(block.data[0], counts * vpc / 0.002, rtol=1e-12)  # N = counts * V/count / (V/N)
    assert block.channels == ("hammer",) and block.units == ("N",)


def test_acceleration_is_scaled_from_mv_per_g_to_m_per_s2():
    ch = ChannelSetup("a", "top:4:X", "acceleration", 100.0, "mV/g", "AC", True, 5.0)
    assert ch.volts_per_unit == pytest.approx(0.1 / 9.80665, rel=1e-15)
    assert ch.unit == "m/s^2"


def test_packetized_conversation_short_transfer_ends_data_phase():
    # USB: the analyser sends 36 bytes of a 64-byte request as one short transfer, then the status
    t = ScriptedTransport([(cbw(1, 64, True, "120000004000"), [INQUIRY_DATA, csw(1, residue=28)])], packetized=True)
    an = Analyser(t)
    data = an.bot.command(P.Op.INQUIRY, length=64).data
    t.check_done()
    assert data == INQUIRY_DATA


# ---------------------------------------------------------------------- end to end over the real firmware


PULSE_DELAY = 5  # samples after the pre-trigger where the stand-in's pulse starts


class PulseStand:
    """Stand-in test stand: a half-sine force pulse (``amplitude_n``, 1.2 ms) starting
    ``PULSE_DELAY`` samples after the pre-trigger, and on every other channel a decaying 50 Hz
    acceleration of ``accel_ms2`` peak starting with it; volts = value * sensitivity."""

    def __init__(self, amplitude_n: float = 100.0, accel_ms2: float = 30.0) -> None:
        self.amplitude_n = amplitude_n
        self.accel_ms2 = accel_ms2
        self.channels: list = []
        self.strikes = 0

    def set_channels(self, channels) -> None:
        self.channels = list(channels)

    def strike(self, fs_hz: float, n_samples: int, pretrigger: int):
        self.strikes += 1
        t = (np.arange(n_samples) - (pretrigger + PULSE_DELAY)) / fs_hz
        width = 0.0012
        force = np.where((t >= 0) & (t < width), self.amplitude_n * np.sin(np.pi * np.clip(t, 0, width) / width), 0.0)
        accel = np.where(t >= 0, self.accel_ms2 * np.exp(-3.0 * t) * np.sin(2 * np.pi * 50.0 * t), 0.0)
        volts = np.array([(force if ch.quantity == "force" else accel) * ch.sensitivity for ch in self.channels])
        return SimpleNamespace(volts=volts, info={})


@pytest.mark.parametrize("packetized", [False, True], ids=["stream", "packetized"])
def test_end_to_end_identify_configure_arm_wait_read(packetized):
    stand = PulseStand()
    fw = Firmware(stand, packetized=packetized)
    setup = default_setup()
    pre = setup.trigger.pretrigger_samples
    with Analyser(LoopbackTransport(fw), poll_interval_s=0.001) as an:
        assert an.identify().product == "SIGLAB-SIM 2042"
        an.configure(setup)
        assert [c.point for c in stand.channels] == ["right:6:-X", "left:9:Y", "top:4:X", "right:4:-Z"]
        an.arm()
        assert an.status().state == P.State.ARMED  # the operator has not struck yet
        st = an.wait_for_trigger(1.0)
        assert st.state == P.State.BLOCK_READY and st.sequence == 1 and stand.strikes == 1
        block = an.read_block()
        again = an.capture(1.0)
    assert block.counts.shape == (4, setup.block_size) and block.trigger_index == pre
    f = block.data[0]
    assert f[pre] >= setup.trigger.level > f[pre - 1]  # the trigger crossing sits at the pre-trigger
    assert f[:pre - 10].std() < 0.5 and 90.0 < f.max() < 110.0  # quiet before, ~100 N pulse
    assert 20.0 < np.abs(block.data[1]).max() < 40.0  # the 30 m/s^2 stand-in response, in m/s^2
    assert not block.overload.any() and block.units == ("N", "m/s^2", "m/s^2", "m/s^2")
    assert again.sequence == 2 and np.array_equal(again.counts, block.counts)  # deterministic stand-in


def test_overload_flags_per_channel():
    stand = PulseStand(accel_ms2=600.0)  # 600 m/s^2 * 10.2 mV/(m/s^2) = 6.1 V > the 5 V range
    with Analyser(LoopbackTransport(Firmware(stand, strike_after_polls=0))) as an:
        an.configure(default_setup())
        block = an.capture(1.0)
    assert block.overload.tolist() == [False, True, True, True]
    assert np.abs(block.counts[1]).max() >= 32767


def test_no_trigger_times_out_with_a_clear_message():
    stand = PulseStand(amplitude_n=10.0)  # below the 20 N trigger level
    fw = Firmware(stand, max_strikes=2)
    with Analyser(LoopbackTransport(fw), poll_interval_s=0.001) as an:
        # 8192-sample blocks: both strikes must fit in the 0.05 s wait, also on a loaded machine
        an.configure(dataclasses.replace(default_setup(), block_size=8192))
        an.arm()
        with pytest.raises(TriggerTimeout, match="no trigger within 0.05 s.*did not cross the trigger level"):
            an.wait_for_trigger(0.05)
        assert stand.strikes == 2  # the operator gave up after max_strikes
        an.abort()
        with pytest.raises(CommandFailed, match="idle, not armed"):
            an.wait_for_trigger(0.05)
        with pytest.raises(CommandFailed, match="no block is ready"):
            an.read_block()


def test_arm_before_configure_is_not_ready():
    with Analyser(LoopbackTransport(Firmware(PulseStand()))) as an:
        with pytest.raises(CommandFailed, match=r"ARM failed: NOT READY \(ASC 0x04/0x80") as err:
            an.arm()
    assert (err.value.sense_key, err.value.asc, err.value.ascq) == (2, 0x04, 0x80)


# ---------------------------------------------------------------------- with the real simulated frame



@pytest.mark.parametrize("packetized", [False, True], ids=["stream", "packetized"])
def test_end_to_end_with_the_simulated_frame(packetized):
    fw = create_analyser({"seed": 11, "packetized": packetized})
    setup = default_setup()
    pre = setup.trigger.pretrigger_samples
    with Analyser(LoopbackTransport(fw), poll_interval_s=0.001) as an:
        ident = an.identify()
        an.configure(setup)
        an.arm()
        assert an.status().state == P.State.ARMED
        an.wait_for_trigger(2.0)
        block = an.read_block()
    assert (ident.vendor, ident.product, ident.revision) == ("IMPACTLB", "SIGLAB-SIM 2042", "0100")
    assert fw.stand.hammer_point == "right:6:-X"  # the operator strikes where the force channel is
    assert block.counts.shape == (4, setup.block_size) and block.trigger_index == pre and block.sequence == 1
    f = block.data[0]
    assert f[pre] >= setup.trigger.level > f[pre - 1]
    assert 60.0 < f.max() < 160.0 and np.abs(f[:pre - 8]).max() < 2.0  # a ~100 N hit, quiet before it
    assert not block.overload.any()


def test_h1_from_simulated_blocks_matches_the_analytic_accelerance():
    """Noise off, DC coupling, no IEPE: the only difference between channels is the physics.

    The anti-alias filter is the same on every channel and cancels in H1 = sum(conj(F) X) / sum(|F|^2).
    The block (65536 samples at 6400 Hz = 10.2 s, > 7 time constants of the slowest mode) holds the
    whole decay, so the DFT of the block is the spectrum of the response. Only resonances below
    fs/25 are compared, where the simulator's time discretisation changes the FRF by well under 1 %
    (a first-order hold of the force would give sinc^2(f/fs), at most 0.5 % there). Ranges are chosen
    like an analyser's auto-range (a trial hit at 10 V, then the smallest range above 1.1 x the peak):
    without noise there is no dither, and a mode whose share of a channel's signal is small decays
    into the ADC's dead zone (|v| < half a count reads 0) early, which cuts its spectral peak
    (0.6 % at the 12.9 Hz mode of left:9:Y with the tightest range, 1.4 % one range up). The peaks
    compared are each output's dominant resonances (at least a fifth of its largest one)."""
    fs, n = 6400.0, 65536
    fw = create_analyser({"seed": 3, "noise": False, "polls": 0})
    base = default_setup()
    chans = tuple(dataclasses.replace(c, coupling="DC", iepe=False, range_v=10.0) for c in base.channels)
    setup = dataclasses.replace(base, sample_rate_hz=fs, block_size=n, channels=chans)
    with Analyser(LoopbackTransport(fw)) as an:
        an.configure(setup)
        trial = an.capture(5.0)
        peak_v = np.abs(trial.data).max(axis=1) * np.array([c.volts_per_unit for c in chans])
        ranges = an.capabilities().ranges_v
        chans = tuple(dataclasses.replace(c, range_v=min(r for r in ranges if r >= 1.1 * max(p, 1e-6)))
                      for c, p in zip(chans, peak_v))
        an.configure(dataclasses.replace(setup, channels=chans))
        sxx = 0.0
        sxy = 0.0
        for _ in range(3):
            fw.stand.next_strike(neighbour=False, double_hit=False)
            block = an.capture(5.0)
            assert not block.overload.any()
            F = np.fft.rfft(block.data[0])
            sxx = sxx + np.abs(F) ** 2
            sxy = sxy + np.conj(F) * np.fft.rfft(block.data[1:], axis=-1)
    h1 = sxy / sxx
    freq = np.fft.rfftfreq(n, 1.0 / fs)
    outputs = [c.point for c in chans[1:]]
    expected = fw.stand.analytic_frf(outputs, chans[0].point, freq, "accelerance").H[:, 0, :]
    modes = fw.stand.model.modes()
    tau_s = 1.0 / (modes.damping * 2 * np.pi * modes.freq_hz)
    assert n / fs > 7 * tau_s.max()  # precondition: the block holds the whole decay
    fn = modes.freq_hz
    bins = [int(np.argmin(np.abs(freq - f))) for f in fn[(fn > 1.0) & (fn < fs / 25)]]
    peaks = np.abs(expected[:, bins])  # (output, mode)
    errors = []
    for o in range(len(outputs)):
        for j, i in enumerate(bins):
            if peaks[o, j] >= max(0.2 * peaks[o].max(), 0.05):  # a dominant resonance at this output, (m/s^2)/N
                errors.append(abs(h1[o, i] / expected[o, i] - 1))
                assert errors[-1] < 0.01, (outputs[o], freq[i], errors[-1])
    assert len(errors) >= 6, errors


def test_cli_identify_prints_identity_and_capabilities(capsys):
    import json

    from acquisition.cli_identify import main

    assert main(["--device", "sim://?seed=1"]) == 0
    out = capsys.readouterr().out
    assert "IMPACTLB" in out and "SIGLAB-SIM 2042" in out and "SL2042-0000001" in out
    assert "51200 Hz" in out and "0.1, 0.2, 0.5, 1, 2, 5, 10 V" in out and "65536" in out
    assert main(["--device", "usbsim://?seed=1", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["identity"]["serial"] == "SL2042-0000001" and info["capabilities"]["inputs"] == 4
    assert info["capabilities"]["bandwidths_hz"][-1] == 20000.0  # 51200 / 2.56
    assert main(["--device", "bogus://x"]) == 2  # a usage error, as in capture
    assert "invalid device URL" in capsys.readouterr().err
