"""Fault injection (simulator.faults) and the recovery of the driver and the capture session."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from benchmark_modules import load_benchmark

from acquisition import protocol as P
from acquisition.driver import Analyser
from acquisition.errors import CommandFailed, InvalidDeviceURL
from acquisition.loopback import LoopbackTransport
from acquisition.session import CaptureSession, TestPlan
from acquisition.setup import default_setup
from analysis.recording import Recording, counts_crc32
from simulator.analyser import create_analyser
from simulator.faults import FAULT_KINDS, TRANSIENT_SENSES, FaultPlan, FaultyFirmware, parse_faults
from simulator.firmware import Firmware


def _soak_module():
    return load_benchmark("reliability/soak_capture.py")


# ---------------------------------------------------------------------- parsing
def test_parse_faults_reads_kinds_and_all():
    assert parse_faults("short_transfer:0.05, garbage:0.02") == {"short_transfer": 0.05, "garbage": 0.02}
    assert parse_faults("all:0.1") == {k: 0.1 for k in FAULT_KINDS}
    assert parse_faults("") == {}


@pytest.mark.parametrize("text, words", [
    ("gremlins:0.1", "unknown fault kind"),
    ("garbage", "KIND:PROBABILITY"),
    ("garbage:lots", "not a number"),
    ("garbage:1.5", "outside [0, 1]"),
])
def test_parse_faults_rejects_bad_text_with_a_clear_message(text, words):
    with pytest.raises(ValueError, match=words.replace("[", r"\[").replace("]", r"\]")):
        parse_faults(text)


def test_fault_options_in_a_device_url_are_checked():
    with pytest.raises(InvalidDeviceURL, match="unknown fault kind"):
        Analyser("sim://?seed=1&faults=gremlins:0.1")
    with pytest.raises(InvalidDeviceURL, match="need faults"):
        Analyser("sim://?seed=1&fault_seed=3")


# ---------------------------------------------------------------------- wire-level behaviour
def _wrapped(kind: str, p: float = 1.0, packetized: bool = False, seed: int = 0) -> FaultyFirmware:
    return FaultyFirmware(Firmware(None, packetized=packetized), FaultPlan({kind: p}, seed=seed))


def _ua_cleared(a: Analyser) -> None:
    """Power-on UNIT ATTENTION consumed (TEST UNIT READY retries once through it)."""
    a.test_unit_ready()


@pytest.mark.parametrize("packetized", [False, True])
def test_check_condition_is_not_executed_and_reports_transient_sense(packetized):
    fw = _wrapped("check_condition", packetized=packetized)
    a = Analyser(LoopbackTransport(fw))
    a.bot.retry_unit_attention = False
    before = fw.commands_executed
    with pytest.raises(CommandFailed) as info:
        a.bot.command(P.Op.GET_STATUS, length=P.STATUS.size)
    assert fw.commands_executed == before  # the firmware never saw the command (REQUEST SENSE was faked too)
    sense = P.Sense(info.value.sense_key, info.value.asc, info.value.ascq)
    assert sense in TRANSIENT_SENSES
    # the bulk-only layer retries an idempotent command once after ABORTED COMMAND / becoming ready
    retried = sense.key in (P.SenseKey.ABORTED_COMMAND, P.SenseKey.NOT_READY)
    assert fw.injected["check_condition"] == (2 if retried else 1)


def test_one_transient_check_condition_is_retried_by_the_driver():
    fw = FaultyFirmware(Firmware(None), FaultPlan({"check_condition": 0.5}, seed=0))
    a = Analyser(LoopbackTransport(fw))
    ok = 0
    for _ in range(40):
        try:
            a.bot.command(P.Op.TEST_UNIT_READY)
            ok += 1
        except CommandFailed as exc:
            assert P.Sense(exc.sense_key, exc.asc, exc.ascq) in TRANSIENT_SENSES
    # one fault per command would fail 50 % of them; with one retry only about 25 % (+UA cases) fail
    assert ok >= 24 and fw.injected["check_condition"] > 40 - ok


@pytest.mark.parametrize("packetized", [False, True])
def test_phase_error_triggers_reset_recovery_and_one_retry_of_an_idempotent_command(packetized):
    fw = FaultyFirmware(Firmware(None, packetized=packetized), FaultPlan({"phase_error": 1.0}))
    a = Analyser(LoopbackTransport(fw))
    with pytest.raises(Exception, match="phase error"):
        a.identify()  # every attempt fails: the one retry fails too
    assert fw.injected["phase_error"] == 2 and a.bot.recoveries == 2
    fw.plan = FaultPlan({})  # the fault stops: the link works again
    assert a.identify().serial == "SL2042-0000001"


def test_stall_on_a_usb_link_is_cleared_and_the_command_still_answers():
    fw = _wrapped("stall", packetized=True)
    a = Analyser(LoopbackTransport(fw))
    a.test_unit_ready()  # no data stage: the stalled status stage is cleared and read again
    assert fw.injected["stall"] >= 1 and not fw.halted_in


def test_disconnect_makes_the_device_vanish_then_come_back_reset():
    fw = _wrapped("disconnect", packetized=False)
    fw.write(P.encode_cbw(1, 0, False, P.build_cdb(P.Op.TEST_UNIT_READY)))
    assert fw.read(13) == b"" and not fw.present  # the CSW in flight is lost
    fw.plan = FaultPlan({})
    resets = fw.resets
    for _ in range(fw.plan.gone_calls + 1):
        fw.read(13)
    assert fw.present and fw.resets == resets + 1  # back, through a bulk-only reset


def test_garbage_adds_bytes_and_short_transfer_removes_some():
    def csw_bytes(kind):
        fw = _wrapped(kind, seed=3)
        fw.write(P.encode_cbw(7, 0, False, P.build_cdb(P.Op.TEST_UNIT_READY)))
        out = b""
        for _ in range(10):
            out += fw.read(1 << 16)
        return out

    clean = P.encode_csw(7, 0, P.CswStatus.FAILED)  # UNIT ATTENTION after power-on
    g = csw_bytes("garbage")
    assert len(g) > len(clean) and g.endswith(clean)
    s = csw_bytes("short_transfer")
    assert 0 < len(s) < len(clean) and clean.startswith(s)


def test_stand_faults_miss_and_overload():
    fw = create_analyser({"seed": 2, "faults": "no_trigger:1.0"})
    a = Analyser(LoopbackTransport(fw))
    a.configure(default_setup())
    a.arm()
    a.status()  # the first poll sees "armed"; the operator strikes at the second
    st = a.status()
    assert st.no_trigger and st.state == P.State.ARMED and fw.injected["no_trigger"] == 1


# ---------------------------------------------------------------------- session recovery per kind
@pytest.mark.parametrize("packetized", [False, True], ids=["stream", "usb"])
@pytest.mark.parametrize("kind", FAULT_KINDS)
def test_session_recovers_from_each_fault_kind(kind, packetized, tmp_path):
    """10 hits with one kind of fault (15 % per strike, 5 % per command or read): all accepted hits
    recorded, intact and equal to the firmware's own blocks."""
    from acquisition.session import channel_table
    from analysis.recording_writer import RecordingWriter
    from analysis.spectra import WindowSettings

    rate = 0.15 if kind in ("no_trigger", "double_hit", "overload") else 0.05
    fw = create_analyser({"seed": 5, "faults": f"{kind}:{rate}", "fault_seed": 11, "packetized": packetized})
    # 8192-sample blocks: the per-read fault rates are set for that many READ BLOCK calls per hit
    setup = dataclasses.replace(default_setup(), block_size=8192)
    plan = TestPlan(hits_per_point=10)
    out = tmp_path / "rec.h5"
    with Analyser(LoopbackTransport(fw), timeout_s=5.0) as a:
        with RecordingWriter(out, instrument={}, setup=setup.to_dict(), channels=channel_table(setup),
                             windows=WindowSettings()) as w:
            result = CaptureSession(a, setup, plan, writer=w, timeout_s=2.0, max_timeouts=10).run()
    assert result.accepted == 10
    assert sum(fw.injected.values()) >= 1  # the fault did happen
    with Recording(out) as rec:
        accepted = [h for h in rec.hits() if h.accepted]
    assert len(accepted) == 10
    assert len({h.sequence for h in accepted}) == 10
    assert all(counts_crc32(h.counts) == fw.block_crc[h.sequence] for h in accepted)


# ---------------------------------------------------------------------- short soak
@pytest.mark.parametrize("door, hits", [("loopback", 60), ("usbsim", 20)])
def test_short_soak_loses_nothing(door, hits, tmp_path):
    soak = _soak_module()
    rep = soak.run_soak(hits, tmp_path / "soak.h5", door=door, seed=4, hang_limit_s=300)
    assert rep.accepted == rep.hits_target and rep.recorded_accepted == rep.accepted
    assert rep.lost == 0 and rep.corrupted == 0 and rep.duplicated == 0 and not rep.problems
    assert sum(rep.injected.values()) >= 5 and rep.link_faults_recovered >= 1


def test_faulty_firmware_speaks_through_the_url_doors():
    from acquisition.errors import ImpactlabError

    for url in ("sim://?seed=1&faults=phase_error:0.3,garbage:0.1&fault_seed=2",
                "usbsim://?seed=1&faults=stall:0.3,short_transfer:0.1&fault_seed=2"):
        ok = 0
        with Analyser(url, timeout_s=1.0) as a:
            for _ in range(6):
                try:
                    ok += a.identify().vendor == "IMPACTLB"
                except ImpactlabError as exc:  # the retry met a second fault: a typed error saying what happened
                    assert "reset" in str(exc)
            fw = a.transport.port.firmware if url.startswith("sim") else None
        assert ok >= 2
        if fw is not None:
            assert isinstance(fw, FaultyFirmware) and sum(fw.injected.values()) >= 1


def test_block_truth_matches_what_the_driver_reads():
    fw = create_analyser({"seed": 3, "faults": "slow:0.0"})
    assert isinstance(fw, FaultyFirmware)
    with Analyser(LoopbackTransport(fw), timeout_s=5.0) as a:
        a.configure(default_setup())
        block = a.capture(5.0)
    assert fw.block_crc == {block.sequence: counts_crc32(np.asarray(block.counts))}


def test_device_gone_for_good_ends_the_session_saying_why_and_keeps_every_hit(tmp_path):
    from acquisition.session import SessionError, channel_table
    from analysis.recording_writer import RecordingWriter
    from analysis.spectra import WindowSettings

    fw = create_analyser({"seed": 6, "faults": "garbage:0.02", "fault_seed": 1})
    transport = LoopbackTransport(fw)
    setup = default_setup()
    accepted_lines = []

    def progress(text: str) -> None:
        if "progress:" in text:
            accepted_lines.append(text)
            if len(accepted_lines) == 4:
                transport.close()  # the cable is pulled for good

    out = tmp_path / "rec.h5"
    with Analyser(transport, timeout_s=2.0) as a:
        with RecordingWriter(out, instrument={}, setup=setup.to_dict(), channels=channel_table(setup),
                             windows=WindowSettings()) as w:
            with pytest.raises(SessionError, match="keeps failing.*(went away|closed)"):
                CaptureSession(a, setup, TestPlan(hits_per_point=10), writer=w, progress=progress).run()
            w.log("ERROR", "session ended")
    with Recording(out) as rec:
        accepted = [h for h in rec.hits() if h.accepted]
        assert len(accepted) == 4 and rec.closed_cleanly
        assert any("link fault" in m for _, _, m in rec.events())
