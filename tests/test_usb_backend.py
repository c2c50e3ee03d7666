"""SimUsbBackend under pyusb's own core, and UsbTransport on top of it.

The far end here is a tiny echo device (each bulk OUT transfer comes back as one bulk IN
transfer) so that the USB plumbing is tested on its own; the real firmware is exercised
through the same backend in ``test_four_doors.py``.
"""
from __future__ import annotations

import array
import errno
import time
from collections import deque

import pytest
import usb.control
import usb.core
import usb.util

from acquisition.errors import DeviceGone, EndpointStalled, TransportTimeout
from acquisition.usb_transport import UsbTransport
from simulator.usb_backend import EP_IN, EP_OUT, SIM_PID, SIM_VID, SimUsbBackend


class EchoDevice:
    """Packetized echo firmware: ``b"STALL-IN"`` / ``b"STALL-OUT"`` halt an endpoint."""

    packetized = True

    def __init__(self) -> None:
        self.outbox: deque[bytes] = deque()
        self.halted_in = False
        self.halted_out = False
        self.resets = 0

    def write(self, data: bytes) -> None:
        if data == b"STALL-IN":
            self.halted_in = True
        elif data == b"STALL-OUT":
            self.halted_out = True
        else:
            self.outbox.append(bytes(data))

    def read(self, max_len: int) -> bytes:
        if not self.outbox:
            return b""
        head = self.outbox[0]
        if len(head) <= max_len:
            return self.outbox.popleft()
        self.outbox[0] = head[max_len:]
        return head[:max_len]

    def bulk_only_reset(self) -> None:
        self.outbox.clear()
        self.resets += 1

    def clear_halt(self, direction_in: bool) -> None:
        if direction_in:
            self.halted_in = False
        else:
            self.halted_out = False


@pytest.fixture
def echo() -> EchoDevice:
    return EchoDevice()


@pytest.fixture
def backend(echo: EchoDevice) -> SimUsbBackend:
    return SimUsbBackend(echo, serial="ECHO0001")


@pytest.fixture
def dev(backend: SimUsbBackend):
    d = usb.core.find(backend=backend, idVendor=SIM_VID, idProduct=SIM_PID)
    assert d is not None
    yield d
    usb.util.dispose_resources(d)


def test_find_filters_by_ids(backend: SimUsbBackend) -> None:
    assert usb.core.find(backend=backend, idVendor=SIM_VID, idProduct=SIM_PID + 1) is None
    found = list(usb.core.find(find_all=True, backend=backend))
    assert len(found) == 1
    d = found[0]
    assert (d.idVendor, d.idProduct, d.bcdUSB, d.bNumConfigurations) == (0x1209, 0x0001, 0x0200, 1)
    assert (d.bus, d.address, d.port_number, d.port_numbers, d.speed) == (1, 4, 2, (2,), usb.util.SPEED_HIGH)


def test_string_descriptors_through_pyusb(dev) -> None:
    assert dev.langids == (0x0409,)
    assert dev.manufacturer == "impactlab"
    assert dev.product == "Simulated dynamic signal analyser"
    assert dev.serial_number == "ECHO0001"


def test_interface_and_endpoints(dev) -> None:
    cfg = dev.get_active_configuration()
    assert cfg.bConfigurationValue == 1 and cfg.bNumInterfaces == 1
    intf = cfg[(0, 0)]
    assert (intf.bInterfaceClass, intf.bInterfaceSubClass, intf.bInterfaceProtocol) == (0xFF, 0x06, 0x50)
    eps = {e.bEndpointAddress: e for e in intf}
    assert set(eps) == {EP_OUT, EP_IN}
    for e in eps.values():
        assert usb.util.endpoint_type(e.bmAttributes) == usb.util.ENDPOINT_TYPE_BULK
        assert e.wMaxPacketSize == 512
        assert e.extra_descriptors == []


def test_raw_descriptors_match_parsed_fields(dev) -> None:
    raw = usb.control.get_descriptor(dev, 18, usb.util.DESC_TYPE_DEVICE, 0)
    assert len(raw) == 18 and raw[0] == 18 and raw[1] == 1
    assert raw[8] | raw[9] << 8 == dev.idVendor and raw[10] | raw[11] << 8 == dev.idProduct
    cfg_raw = usb.control.get_descriptor(dev, 255, usb.util.DESC_TYPE_CONFIG, 0)
    total = cfg_raw[2] | cfg_raw[3] << 8
    assert len(cfg_raw) == total == 32
    # interface descriptor follows the 9-byte configuration descriptor
    assert list(cfg_raw[9:18]) == [9, 4, 0, 0, 2, 0xFF, 0x06, 0x50, 0]
    # the two endpoints: address, bulk, 512
    assert list(cfg_raw[18:25]) == [7, 5, EP_OUT, 2, 0, 2, 0]
    assert list(cfg_raw[25:32]) == [7, 5, EP_IN, 2, 0, 2, 0]


def test_bulk_round_trip_and_short_packets(dev) -> None:
    dev.set_configuration()
    assert dev.write(EP_OUT, b"x" * 1000) == 1000
    first = dev.read(EP_IN, 512)
    second = dev.read(EP_IN, 512)
    assert (len(first), len(second)) == (512, 488)
    buf = array.array("B", bytes(16))
    dev.write(EP_OUT, b"abc")
    assert dev.read(EP_IN, buf) == 3  # filled in place
    assert buf[:3].tobytes() == b"abc" and buf[3:].tobytes() == bytes(13)


def test_nothing_pending_is_timeout(dev) -> None:
    t0 = time.monotonic()
    with pytest.raises(usb.core.USBTimeoutError) as info:
        dev.read(EP_IN, 64, timeout=30)
    elapsed = time.monotonic() - t0
    assert info.value.errno == errno.ETIMEDOUT
    assert elapsed >= 0.025  # it waited for the 30 ms timeout (no upper bound: not a speed test)


def test_stall_then_clear_halt(dev, echo: EchoDevice) -> None:
    dev.write(EP_OUT, b"STALL-IN")
    with pytest.raises(usb.core.USBError) as info:
        dev.read(EP_IN, 64, timeout=10)
    assert info.value.errno == errno.EPIPE and not isinstance(info.value, usb.core.USBTimeoutError)
    # GET_STATUS(endpoint) reports the halt
    assert list(dev.ctrl_transfer(0x82, 0x00, 0, EP_IN, 2)) == [1, 0]
    dev.clear_halt(EP_IN)
    assert not echo.halted_in
    dev.write(EP_OUT, b"STALL-OUT")
    with pytest.raises(usb.core.USBError) as info:
        dev.write(EP_OUT, b"data")
    assert info.value.errno == errno.EPIPE
    dev.clear_halt(EP_OUT)
    dev.write(EP_OUT, b"data")
    assert dev.read(EP_IN, 64).tobytes() == b"data"


def test_class_requests(dev, echo: EchoDevice) -> None:
    dev.write(EP_OUT, b"stale")
    assert dev.ctrl_transfer(0x21, 0xFF, 0, 0, None) == 0
    assert echo.resets == 1 and not echo.outbox
    assert list(dev.ctrl_transfer(0xA1, 0xFE, 0, 0, 1)) == [0]
    with pytest.raises(usb.core.USBError) as info:
        dev.ctrl_transfer(0x21, 0x42, 0, 0, None)  # unsupported: control endpoint stalls
    assert info.value.errno == errno.EPIPE


def test_bad_endpoint_and_unplug(dev, backend: SimUsbBackend) -> None:
    with pytest.raises(ValueError, match="Invalid endpoint"):
        dev.write(0x02, b"x")  # pyusb itself rejects an address not in the descriptors
    with pytest.raises(usb.core.USBError) as info:
        dev.clear_halt(0x05)
    assert info.value.errno == errno.ENOENT
    backend.unplug()
    with pytest.raises(usb.core.USBError) as info:
        dev.write(EP_OUT, b"x")
    assert info.value.errno == errno.ENODEV
    assert usb.core.find(backend=backend) is None


# -- UsbTransport ------------------------------------------------------------------------------
@pytest.fixture
def transport(backend: SimUsbBackend):
    t = UsbTransport.find(SIM_VID, SIM_PID, backend=backend, url="usbsim://")
    yield t
    t.close()


def test_transport_packet_semantics(transport: UsbTransport) -> None:
    assert transport.packetized and transport.max_packet == 512
    transport.write(b"y" * 700, timeout_s=0.5)
    assert transport.read(4096, timeout_s=0.5) == b"y" * 700  # one transfer, shorter than asked
    transport.write(b"z" * 700, timeout_s=0.5)
    assert transport.read(100, timeout_s=0.5) == b"z" * 100


def test_transport_errors_map(transport: UsbTransport, echo: EchoDevice, backend: SimUsbBackend) -> None:
    with pytest.raises(TransportTimeout, match="within 0.02 s"):
        transport.read(64, timeout_s=0.02)
    transport.write(b"STALL-IN", 0.5)
    with pytest.raises(EndpointStalled):
        transport.read(64, 0.5)
    transport.clear_halt(True)
    assert not echo.halted_in
    transport.write(b"STALL-OUT", 0.5)
    with pytest.raises(EndpointStalled):
        transport.write(b"more", 0.5)
    echo.halted_in = True
    echo.outbox.append(b"stale")
    transport.reset_recovery(timeout_s=0.5)
    assert echo.resets == 1 and not echo.halted_in and not echo.halted_out and not echo.outbox
    assert transport.max_lun() == 0
    backend.unplug()
    with pytest.raises(DeviceGone):
        transport.write(b"x", 0.5)
    with pytest.raises(DeviceGone):
        transport.read(8, 0.5)


def test_transport_close_releases_handle(backend: SimUsbBackend) -> None:
    t = UsbTransport.find(SIM_VID, SIM_PID, backend=backend)
    assert backend.open_handles == 1
    t.close()
    t.close()
    assert backend.open_handles == 0
    with pytest.raises(DeviceGone, match="closed"):
        t.write(b"x", 0.1)


def test_transport_configures_an_unconfigured_device(backend: SimUsbBackend) -> None:
    dev = usb.core.find(backend=backend, idVendor=SIM_VID, idProduct=SIM_PID)
    dev.set_configuration(0)  # back to the address state
    with pytest.raises(usb.core.USBError, match="Configuration not set"):
        dev.get_active_configuration()
    with UsbTransport(dev) as t:
        assert dev.get_active_configuration().bConfigurationValue == 1
        t.write(b"ping", 0.5)
        assert t.read(64, 0.5) == b"ping"


def test_second_claim_is_busy(backend: SimUsbBackend) -> None:
    from acquisition.errors import TransportError

    with UsbTransport.find(SIM_VID, SIM_PID, backend=backend):
        with pytest.raises(TransportError, match="in use"):
            UsbTransport.find(SIM_VID, SIM_PID, backend=backend)
        assert backend.open_handles == 1  # the failed open released its handle
    assert backend.open_handles == 0


def test_transport_find_by_serial(backend: SimUsbBackend) -> None:
    with UsbTransport.find(SIM_VID, SIM_PID, serial="ECHO0001", backend=backend) as t:
        assert t.url == "usb://1209:0001/ECHO0001"
    with pytest.raises(DeviceGone, match="with serial 'OTHER'"):
        UsbTransport.find(SIM_VID, SIM_PID, serial="OTHER", backend=backend)


def test_transport_rejects_bad_arguments(transport: UsbTransport) -> None:
    with pytest.raises(ValueError, match="timeout_s"):
        transport.read(8, 0)
    with pytest.raises(ValueError, match="read size"):
        transport.read(0, 1.0)


# -- the real firmware behind the same backend ------------------------------------------------------
@pytest.fixture(scope="module")
def usbsim():
    from acquisition.urls import open_transport

    t = open_transport("usbsim://?seed=2")
    yield t
    t.close()


def test_usbsim_failed_data_in_stalls_and_bot_recovers(usbsim) -> None:
    from acquisition import protocol as P
    from acquisition.bot import BulkOnly
    from acquisition.errors import CommandFailed

    bot = BulkOnly(usbsim, timeout_s=2.0)
    # READ BLOCK with no block: the firmware stalls the IN endpoint (real EPIPE through pyusb),
    # the host clears the halt, reads the failed status, then REQUEST SENSE says why
    with pytest.raises(CommandFailed) as info:
        bot.command("READ BLOCK", length=64, sequence=1, offset=0, count=64)
    assert info.value.sense_key == P.SenseKey.NOT_READY
    assert (info.value.asc, info.value.ascq) == P.ASC_NOT_READY_NO_BLOCK
    assert P.decode_inquiry(bot.command("INQUIRY", length=36).data).vendor == "IMPACTLB"


def test_usbsim_invalid_cbw_needs_reset_recovery(usbsim) -> None:
    from acquisition import protocol as P
    from acquisition.bot import BulkOnly

    usbsim.write(b"\xff" * 31, 1.0)  # not a CBW: both endpoints stall until reset recovery
    with pytest.raises(EndpointStalled):
        usbsim.read(13, 0.2)
    with pytest.raises(EndpointStalled):
        usbsim.write(b"\x00" * 31, 0.2)
    usbsim.reset_recovery(timeout_s=1.0)
    bot = BulkOnly(usbsim, timeout_s=2.0)
    assert P.decode_inquiry(bot.command("INQUIRY", length=36).data).product == "SIGLAB-SIM 2042"
