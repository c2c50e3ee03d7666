"""StreamTransport over real pyserial ports (loop://, socket://) and the sim:// handler."""
from __future__ import annotations

import socket
import threading
import time

import pytest
import serial

from acquisition.errors import DeviceGone, TransportTimeout
from acquisition.protocol import STREAM_RESET
from acquisition.stream_transport import StreamTransport
from simulator.urlhandlers.protocol_sim import Serial as SimSerial


class StreamEcho:
    """Stream-mode fake firmware: echoes its input reversed per write; counts resets."""

    packetized = False

    def __init__(self) -> None:
        self.pending = bytearray()
        self.resets = 0
        self.halted_in = self.halted_out = False

    def write(self, data: bytes) -> None:
        if data == STREAM_RESET:
            self.pending.clear()
            self.resets += 1
        else:
            self.pending += data[::-1]

    def read(self, max_len: int) -> bytes:
        out = bytes(self.pending[:max_len])
        del self.pending[:max_len]
        return out

    def bulk_only_reset(self) -> None:
        self.pending.clear()
        self.resets += 1

    def clear_halt(self, direction_in: bool) -> None:
        pass


def test_loop_exact_reads() -> None:
    # loop:// models the line rate and holds 4096 bytes: keep below both limits
    with StreamTransport(serial.serial_for_url("loop://", baudrate=10_000_000), url="loop://") as t:
        payload = bytes(range(256)) * 12
        t.write(payload, timeout_s=1.0)
        assert t.read(10, 1.0) == payload[:10]
        assert t.read(len(payload) - 10, 1.0) == payload[10:]


def test_partial_read_times_out_with_count() -> None:
    with StreamTransport(serial.serial_for_url("loop://"), url="loop://") as t:
        t.write(b"abcde", 1.0)
        t0 = time.monotonic()
        with pytest.raises(TransportTimeout, match="5 of 13 bytes") as info:
            t.read(13, timeout_s=0.05)
        assert info.value.received == 5
        assert time.monotonic() - t0 > 0.04  # it waited for the timeout (an upper bound would be a speed test)


def test_reset_recovery_drains_stale_bytes() -> None:
    with StreamTransport(serial.serial_for_url("loop://"), url="loop://", quiet_s=0.02) as t:
        t.write(b"stale" * 100, 1.0)
        t.reset_recovery(timeout_s=0.5)  # the loop echoes STREAM_RESET too: all of it must go
        with pytest.raises(TransportTimeout) as info:
            t.read(1, timeout_s=0.02)
        assert info.value.received == 0
        t.write(b"fresh", 1.0)
        assert t.read(5, 1.0) == b"fresh"


def test_closed_transport_is_device_gone() -> None:
    t = StreamTransport(serial.serial_for_url("loop://"), url="loop://")
    t.close()
    t.close()
    with pytest.raises(DeviceGone, match="closed"):
        t.read(1, 0.1)
    with pytest.raises(DeviceGone):
        t.write(b"x", 0.1)


def test_bad_arguments() -> None:
    with StreamTransport(serial.serial_for_url("loop://")) as t:
        with pytest.raises(ValueError, match="timeout_s"):
            t.read(1, -1)
        with pytest.raises(ValueError, match="read size"):
            t.read(0, 1)
    with pytest.raises(TypeError, match="pyserial port"):
        StreamTransport(object())


def _one_shot_server(behaviour: str) -> tuple[int, threading.Thread]:
    """A loopback TCP peer: 'echo4' echoes 4 bytes then hangs up; 'silent' accepts and waits."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    srv.settimeout(5)
    port = srv.getsockname()[1]

    def run() -> None:
        conn, _ = srv.accept()
        with conn:
            conn.settimeout(5)
            if behaviour == "echo4":
                conn.sendall(conn.recv(4))
            else:
                time.sleep(0.3)
        srv.close()

    th = threading.Thread(target=run, daemon=True)
    th.start()
    return port, th


def test_socket_disconnect_is_device_gone() -> None:
    port, th = _one_shot_server("echo4")
    t = StreamTransport(serial.serial_for_url(f"socket://127.0.0.1:{port}"))
    t.write(b"ping", 1.0)
    assert t.read(4, 1.0) == b"ping"
    th.join(5)
    with pytest.raises(DeviceGone, match="went away"):
        t.read(4, 1.0)
    t.close()


def test_socket_silence_is_timeout() -> None:
    port, th = _one_shot_server("silent")
    t = StreamTransport(serial.serial_for_url(f"socket://127.0.0.1:{port}"))
    with pytest.raises(TransportTimeout, match="0 of 8 bytes"):
        t.read(8, 0.05)
    th.join(5)
    t.close()


# -- the sim:// handler over a fake firmware ----------------------------------------------------
def test_sim_handler_semantics() -> None:
    fw = StreamEcho()
    port = SimSerial.from_firmware(fw, timeout=0.05)
    assert port.is_open and port.in_waiting == 0
    port.write(b"hello")
    assert port.in_waiting == 5
    assert port.read(3) == b"oll"
    assert port.read(10) == b"eh"  # fewer than asked: timeout expired
    port.write(b"xyz")
    port.reset_input_buffer()
    assert port.in_waiting == 0
    port.close()
    with pytest.raises(serial.PortNotOpenError):
        port.read(1)


def test_sim_handler_under_stream_transport() -> None:
    fw = StreamEcho()
    with StreamTransport(SimSerial.from_firmware(fw), url="sim://") as t:
        t.write(b"0123456789", 1.0)
        assert t.read(4, 1.0) == b"9876"
        t.reset_recovery(timeout_s=0.2)
        assert fw.resets == 1
        with pytest.raises(TransportTimeout):
            t.read(1, 0.01)


# -- the real firmware behind sim:// -------------------------------------------------------------
def test_serial_for_url_sim_speaks_bulk_only() -> None:
    from acquisition import protocol as P
    from acquisition.urls import register_url_handlers

    register_url_handlers()
    port = serial.serial_for_url("sim://?seed=3", timeout=1)
    try:
        port.write(P.encode_cbw(9, 36, True, P.build_cdb(P.Op.INQUIRY, length=36)))
        reply = port.read(36 + 13)
        assert P.decode_inquiry(reply[:36]).vendor == "IMPACTLB"
        csw = P.decode_csw(reply[36:])
        assert (csw.tag, csw.status, csw.residue) == (9, P.CswStatus.PASSED, 0)
    finally:
        port.close()


def test_sim_garbage_then_reset_recovery() -> None:
    from acquisition import protocol as P
    from acquisition.bot import BulkOnly
    from acquisition.urls import open_transport

    with open_transport("sim://?seed=3") as t:
        t.write(b"\x00garbage" * 8, 1.0)  # an invalid CBW: the firmware discards input until STREAM_RESET
        t.write(P.encode_cbw(1, 36, True, P.build_cdb(P.Op.INQUIRY, length=36)), 1.0)
        with pytest.raises(TransportTimeout) as info:
            t.read(36, 0.05)
        assert info.value.received == 0
        t.reset_recovery(timeout_s=1.0)
        bot = BulkOnly(t, timeout_s=2.0)
        assert P.decode_inquiry(bot.command("INQUIRY", length=36).data).vendor == "IMPACTLB"


def test_sim_bad_option_is_invalid_url() -> None:
    from acquisition.errors import InvalidDeviceURL
    from acquisition.urls import open_transport

    with pytest.raises(InvalidDeviceURL, match="unknown simulator option"):
        open_transport("sim://?bogus=1")
    with pytest.raises(InvalidDeviceURL, match="unknown simulator option"):
        open_transport("usbsim://?bogus=1")
