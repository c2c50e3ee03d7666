"""A pyusb backend (``usb.backend.IBackend``) whose only device is the simulated analyser.

``usb.core.find(backend=SimUsbBackend(...), idVendor=SIM_VID, idProduct=SIM_PID)`` returns a
normal ``usb.core.Device``; pyusb's own core (descriptors, ``set_configuration``,
``claim_interface``, ``dev.write`` / ``dev.read`` on the bulk endpoints, ``ctrl_transfer``,
``clear_halt``) runs unmodified on top of it. Nothing is mocked: this class plays the role that
``usb.backend.libusb1`` plays for real hardware, and the far end is a
``simulator.firmware.Firmware`` in packetized mode (one ``read`` = one bulk transfer).

The device (one configuration, one interface, two bulk endpoints):

* device descriptor: USB 2.0, high speed, VID:PID ``1209:0001`` (pid.codes test ID),
  strings 1 manufacturer, 2 product, 3 serial number (language 0x0409);
* interface 0: class 0xFF (vendor specific), subclass 0x06 (SCSI transparent command set),
  protocol 0x50 (bulk-only transport), so no operating-system storage driver claims it;
* endpoints: bulk OUT 0x01 and bulk IN 0x81, ``wMaxPacketSize`` 512.

Errors are raised as libusb would report them through pyusb: a stalled endpoint is
``usb.core.USBError`` with ``errno == EPIPE``; nothing to read before the timeout is
``usb.core.USBTimeoutError`` (``ETIMEDOUT``); an unplugged device gives ``ENODEV``; an unknown
endpoint, interface or configuration gives ``ENOENT``; a request the device does not support is
answered with a control-endpoint stall (``EPIPE``).

Timeouts are in milliseconds (pyusb's unit); 0 means wait forever, as in libusb. The firmware
runs in the caller's thread; while it has nothing to send a read polls it with a short sleep.
"""
from __future__ import annotations

import array
import errno
import logging
import struct
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import usb.backend
import usb.core
import usb.util

from .usb_descriptors import CONFIG_VALUE, EP_IN, EP_OUT, LANGID_EN_US, MAX_PACKET, SIM_PID, SIM_VID
from .usb_descriptors import ConfigurationDescriptor as _ConfigurationDescriptor
from .usb_descriptors import DeviceDescriptor as _DeviceDescriptor
from .usb_descriptors import EndpointDescriptor as _EndpointDescriptor
from .usb_descriptors import InterfaceDescriptor as _InterfaceDescriptor

__all__ = ["SimUsbBackend", "SIM_VID", "SIM_PID", "EP_OUT", "EP_IN", "MAX_PACKET"]

_log = logging.getLogger(__name__)


# control requests
_GET_STATUS = 0x00
_CLEAR_FEATURE = 0x01
_GET_DESCRIPTOR = 0x06
_GET_CONFIGURATION = 0x08
_SET_CONFIGURATION = 0x09
_GET_INTERFACE = 0x0A
_BOT_RESET = 0xFF  # class request, bmRequestType 0x21
_GET_MAX_LUN = 0xFE  # class request, bmRequestType 0xA1
_ENDPOINT_HALT = 0

_POLL_MIN_S = 0.0002
_POLL_MAX_S = 0.005


def _usb_error(text: str, err: int) -> usb.core.USBError:
    return usb.core.USBError(f"{text} [{errno.errorcode.get(err, err)}]", None, err)


@dataclass(frozen=True)
class _DeviceId:
    """What ``enumerate_devices`` yields: identifies the one simulated device."""

    bus: int
    address: int


class _Handle:
    """An open device handle (what ``open_device`` returns)."""

    def __init__(self, dev: _DeviceId) -> None:
        self.dev = dev
        self.claimed: set[int] = set()
        self.closed = False


class SimUsbBackend(usb.backend.IBackend):
    """pyusb backend presenting one simulated analyser on bus 1.

    ``firmware``: a packetized ``simulator.firmware.Firmware``; when omitted one is built with
    ``simulator.analyser.create_analyser(options)`` (``options`` as in a ``usbsim://`` URL).
    ``vid``/``pid``/``serial``/``manufacturer``/``product`` set the descriptors.
    """

    def __init__(
        self,
        firmware: Any = None,
        *,
        options: dict | None = None,
        vid: int = SIM_VID,
        pid: int = SIM_PID,
        serial: str = "SIM00001",
        manufacturer: str = "impactlab",
        product: str = "Simulated dynamic signal analyser",
        bus: int = 1,
        address: int = 4,
        port_numbers: tuple = (2,),
    ) -> None:
        super().__init__()
        if firmware is None:
            firmware = _make_packetized_firmware(dict(options or {}))
        self.firmware = firmware
        self.vid = int(vid)
        self.pid = int(pid)
        self.strings = {1: manufacturer, 2: product, 3: serial}
        self._id = _DeviceId(bus=int(bus), address=int(address))
        self._device = _DeviceDescriptor(
            idVendor=self.vid, idProduct=self.pid, bus=int(bus), address=int(address),
            port_number=int(port_numbers[-1]) if port_numbers else 0, port_numbers=tuple(port_numbers),
        )
        self._config = _ConfigurationDescriptor()
        self._interface = _InterfaceDescriptor()
        self._endpoints = (_EndpointDescriptor(EP_OUT), _EndpointDescriptor(EP_IN))
        self._configuration = CONFIG_VALUE  # the operating system configured it at enumeration
        self._plugged = True
        self._handles: list[_Handle] = []

    # -- test hooks ----------------------------------------------------------------------------
    def unplug(self) -> None:
        """Simulate pulling the cable: every later call fails with ENODEV."""
        self._plugged = False

    @property
    def open_handles(self) -> int:
        """How many device handles are open (for leak checks)."""
        return sum(1 for h in self._handles if not h.closed)

    # -- checks --------------------------------------------------------------------------------
    def _alive(self) -> None:
        if not self._plugged:
            raise _usb_error("No such device (it may have been disconnected)", errno.ENODEV)

    def _handle(self, handle: _Handle) -> _Handle:
        self._alive()
        if not isinstance(handle, _Handle) or handle.closed or handle.dev != self._id:
            raise _usb_error("Invalid or closed device handle", errno.EINVAL)
        return handle

    def _check_dev(self, dev: _DeviceId) -> None:
        if dev != self._id:
            raise _usb_error(f"Entity not found: no device {dev!r}", errno.ENOENT)

    def _check_config_index(self, config: int) -> None:
        if config != 0:
            raise _usb_error(f"Entity not found: configuration index {config}", errno.ENOENT)

    def _check_bulk(self, handle: _Handle, ep: int, intf: int, want_in: bool) -> None:
        if self._configuration != CONFIG_VALUE:
            raise _usb_error("Entity not found: the device is not configured", errno.ENOENT)
        if intf not in handle.claimed:
            raise _usb_error(f"Entity not found: interface {intf} is not claimed", errno.ENOENT)
        if ep != (EP_IN if want_in else EP_OUT):
            raise _usb_error(f"Entity not found: no bulk {'IN' if want_in else 'OUT'} endpoint {ep:#04x}", errno.ENOENT)

    # -- enumeration and descriptors -------------------------------------------------------------
    def enumerate_devices(self) -> Iterator[_DeviceId]:
        if self._plugged:
            yield self._id

    def get_parent(self, dev: _DeviceId) -> None:
        return None

    def get_device_descriptor(self, dev: _DeviceId) -> _DeviceDescriptor:
        self._check_dev(dev)
        return self._device

    def get_configuration_descriptor(self, dev: _DeviceId, config: int) -> _ConfigurationDescriptor:
        self._check_dev(dev)
        self._check_config_index(config)
        return self._config

    def get_interface_descriptor(self, dev: _DeviceId, intf: int, alt: int, config: int) -> _InterfaceDescriptor:
        self._check_dev(dev)
        self._check_config_index(config)
        if intf != 0 or alt != 0:
            raise _usb_error(f"Entity not found: interface {intf} alternate setting {alt}", errno.ENOENT)
        return self._interface

    def get_endpoint_descriptor(self, dev: _DeviceId, ep: int, intf: int, alt: int, config: int) -> _EndpointDescriptor:
        self.get_interface_descriptor(dev, intf, alt, config)
        if not 0 <= ep < len(self._endpoints):
            raise _usb_error(f"Entity not found: endpoint index {ep}", errno.ENOENT)
        return self._endpoints[ep]

    # -- handles, configuration, interfaces -----------------------------------------------------------
    def open_device(self, dev: _DeviceId) -> _Handle:
        self._alive()
        self._check_dev(dev)
        handle = _Handle(dev)
        self._handles.append(handle)
        return handle

    def close_device(self, dev_handle: _Handle) -> None:
        if isinstance(dev_handle, _Handle):
            dev_handle.closed = True
            dev_handle.claimed.clear()
        self._handles = [h for h in self._handles if not h.closed]

    def set_configuration(self, dev_handle: _Handle, config_value: int) -> None:
        handle = self._handle(dev_handle)
        if config_value not in (0, CONFIG_VALUE):
            raise _usb_error(f"Entity not found: configuration value {config_value}", errno.ENOENT)
        if handle.claimed:
            raise _usb_error("Resource busy: release the interfaces before changing configuration", errno.EBUSY)
        self._configuration = int(config_value)

    def get_configuration(self, dev_handle: _Handle) -> int:
        self._handle(dev_handle)
        return self._configuration

    def set_interface_altsetting(self, dev_handle: _Handle, intf: int, altsetting: int) -> None:
        handle = self._handle(dev_handle)
        if intf not in handle.claimed:
            raise _usb_error(f"Entity not found: interface {intf} is not claimed", errno.ENOENT)
        if altsetting != 0:
            raise _usb_error(f"Entity not found: alternate setting {altsetting}", errno.ENOENT)

    def claim_interface(self, dev_handle: _Handle, intf: int) -> None:
        handle = self._handle(dev_handle)
        if self._configuration != CONFIG_VALUE or intf != 0:
            raise _usb_error(f"Entity not found: interface {intf}", errno.ENOENT)
        for other in self._handles:
            if other is not handle and not other.closed and intf in other.claimed:
                raise _usb_error(f"Resource busy: interface {intf} is claimed by another handle", errno.EBUSY)
        handle.claimed.add(int(intf))

    def release_interface(self, dev_handle: _Handle, intf: int) -> None:
        handle = self._handle(dev_handle)
        if intf not in handle.claimed:
            raise _usb_error(f"Entity not found: interface {intf} is not claimed", errno.ENOENT)
        handle.claimed.discard(intf)

    def is_kernel_driver_active(self, dev_handle: _Handle, intf: int) -> bool:
        self._handle(dev_handle)
        return False

    def detach_kernel_driver(self, dev_handle: _Handle, intf: int) -> None:
        self._handle(dev_handle)
        raise _usb_error(f"Entity not found: no kernel driver on interface {intf}", errno.ENOENT)

    def attach_kernel_driver(self, dev_handle: _Handle, intf: int) -> None:
        self._handle(dev_handle)
        raise _usb_error(f"Entity not found: no kernel driver for interface {intf}", errno.ENOENT)

    # -- bulk transfers ------------------------------------------------------------------------------
    def bulk_write(self, dev_handle: _Handle, ep: int, intf: int, data: array.array, timeout: int) -> int:
        """One bulk OUT transfer: hand ``data`` to the firmware; returns the byte count."""
        handle = self._handle(dev_handle)
        self._check_bulk(handle, ep, intf, want_in=False)
        if self.firmware.halted_out:
            raise _usb_error("Pipe error: bulk OUT endpoint 0x01 is halted (clear the halt)", errno.EPIPE)
        payload = bytes(data)
        self.firmware.write(payload)
        return len(payload)

    def bulk_read(self, dev_handle: _Handle, ep: int, intf: int, buff: array.array, timeout: int) -> int:
        """One bulk IN transfer into the preallocated ``buff``; returns the byte count.

        Waits up to ``timeout`` ms (0 = forever) for the firmware to have something to send.
        """
        handle = self._handle(dev_handle)
        self._check_bulk(handle, ep, intf, want_in=True)
        size = len(buff) * buff.itemsize
        deadline = None if not timeout else time.monotonic() + timeout / 1000.0
        pause = _POLL_MIN_S
        while True:
            if self.firmware.halted_in:
                raise _usb_error("Pipe error: bulk IN endpoint 0x81 is halted (clear the halt)", errno.EPIPE)
            data = self.firmware.read(size)
            if data:
                break
            if self.firmware.halted_in:
                raise _usb_error("Pipe error: bulk IN endpoint 0x81 stalled", errno.EPIPE)
            if deadline is not None:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise usb.core.USBTimeoutError(
                        f"Operation timed out: nothing to read within {timeout} ms [ETIMEDOUT]", None, errno.ETIMEDOUT
                    )
                time.sleep(min(pause, left))
            else:
                time.sleep(pause)
            pause = min(2 * pause, _POLL_MAX_S)
            self._alive()
        n = len(data)
        if n > size:
            raise _usb_error(f"Overflow: the device sent {n} bytes into a {size}-byte buffer", errno.EOVERFLOW)
        view = memoryview(buff).cast("B")
        view[:n] = data
        return n

    def clear_halt(self, dev_handle: _Handle, ep: int) -> None:
        """CLEAR_FEATURE(ENDPOINT_HALT) on a bulk endpoint."""
        self._handle(dev_handle)
        if ep == EP_IN:
            self.firmware.clear_halt(True)
        elif ep == EP_OUT:
            self.firmware.clear_halt(False)
        else:
            raise _usb_error(f"Entity not found: endpoint {ep:#04x}", errno.ENOENT)

    def reset_device(self, dev_handle: _Handle) -> None:
        """Port reset: the device abandons any command and both endpoints are clear."""
        self._handle(dev_handle)
        self.firmware.bulk_only_reset()
        self.firmware.clear_halt(True)
        self.firmware.clear_halt(False)

    # -- control transfers -----------------------------------------------------------------------------
    def ctrl_transfer(self, dev_handle: _Handle, bmRequestType: int, bRequest: int, wValue: int, wIndex: int,
                      data: array.array, timeout: int) -> int:
        """Control transfer on endpoint 0; returns the number of bytes moved in the data stage."""
        self._handle(dev_handle)
        length = len(data) * data.itemsize if data is not None else 0
        reply = self._control(bmRequestType, bRequest, wValue, wIndex, length)
        if bmRequestType & usb.util.CTRL_IN:
            n = min(len(reply), length)
            if n:
                memoryview(data).cast("B")[:n] = reply[:n]
            return n
        return length

    def _stall(self, what: str) -> usb.core.USBError:
        return _usb_error(f"Pipe error: control request {what} not supported (endpoint 0 stalled)", errno.EPIPE)

    def _control(self, req_type: int, req: int, value: int, index: int, length: int) -> bytes:
        what = f"bmRequestType={req_type:#04x} bRequest={req:#04x} wValue={value:#06x} wIndex={index:#06x}"
        if req_type == 0x80 and req == _GET_DESCRIPTOR:
            return self._descriptor(value >> 8, value & 0xFF, index, what)
        if req_type == 0x80 and req == _GET_STATUS:
            return struct.pack("<H", 0x0001)  # self powered
        if req_type == 0x80 and req == _GET_CONFIGURATION:
            return bytes([self._configuration])
        if req_type == 0x00 and req == _SET_CONFIGURATION:
            if value not in (0, CONFIG_VALUE):
                raise self._stall(what)
            self._configuration = value
            return b""
        if req_type == 0x81 and req == _GET_INTERFACE and index == 0:
            return b"\x00"
        if req_type == 0x82 and req == _GET_STATUS:
            if index == EP_IN:
                return struct.pack("<H", int(bool(self.firmware.halted_in)))
            if index == EP_OUT:
                return struct.pack("<H", int(bool(self.firmware.halted_out)))
            raise self._stall(what)
        if req_type == 0x02 and req == _CLEAR_FEATURE and value == _ENDPOINT_HALT:
            if index not in (EP_IN, EP_OUT):
                raise self._stall(what)
            self.firmware.clear_halt(index == EP_IN)
            return b""
        if req_type == 0x21 and req == _BOT_RESET and value == 0 and index == 0 and length == 0:
            self.firmware.bulk_only_reset()
            return b""
        if req_type == 0xA1 and req == _GET_MAX_LUN and value == 0 and index == 0 and length == 1:
            return b"\x00"  # a single logical unit
        raise self._stall(what)

    def _descriptor(self, kind: int, idx: int, langid: int, what: str) -> bytes:
        if kind == usb.util.DESC_TYPE_DEVICE and idx == 0:
            return self._device.pack()
        if kind == usb.util.DESC_TYPE_CONFIG and idx == 0:
            return (self._config.pack() + self._interface.pack()
                    + b"".join(ep.pack() for ep in self._endpoints))
        if kind == usb.util.DESC_TYPE_STRING:
            if idx == 0:
                return struct.pack("<BBH", 4, usb.util.DESC_TYPE_STRING, LANGID_EN_US)
            text = self.strings.get(idx)
            if text is not None and langid == LANGID_EN_US:
                body = text.encode("utf-16-le")
                return bytes([2 + len(body), usb.util.DESC_TYPE_STRING]) + body
        raise self._stall(what)


def _make_packetized_firmware(options: dict) -> Any:
    """A packetized firmware from ``usbsim://`` options (through ``create_analyser``)."""
    from simulator.analyser import create_analyser

    return create_analyser(dict(options, packetized=True))
