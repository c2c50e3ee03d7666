"""A :class:`~acquisition.transport.Transport` over a pyusb device (packetized semantics).

The analyser exposes one vendor-specific interface (class 0xFF, subclass 0x06, protocol 0x50)
with a bulk OUT and a bulk IN endpoint. ``read(n)`` is one bulk IN transfer of 1..n bytes (a
short packet ends a data phase early); endpoints may stall.

Error mapping (pyusb -> impactlab): ``USBTimeoutError`` / ``ETIMEDOUT`` -> :class:`TransportTimeout`;
``EPIPE`` -> :class:`EndpointStalled`; ``ENODEV``, ``ENOENT``, ``EIO`` -> :class:`DeviceGone`; any
other ``USBError`` -> :class:`TransportError`.

Reset recovery (USB Mass Storage Bulk-Only Transport 5.3.4): the class request
*Bulk-Only Mass Storage Reset* (bmRequestType 0x21, bRequest 0xFF, wIndex = interface) on the
control endpoint, then CLEAR_FEATURE(ENDPOINT_HALT) on the bulk IN and the bulk OUT endpoints.
"""
from __future__ import annotations

import array
import errno
import logging
from typing import Any

import usb.core
import usb.util

from acquisition.errors import DeviceGone, EndpointStalled, TransportError, TransportTimeout
from acquisition.transport import Transport

__all__ = ["UsbTransport", "BOT_RESET", "GET_MAX_LUN"]

_log = logging.getLogger(__name__)

#: (bmRequestType, bRequest) of the bulk-only class requests
BOT_RESET = (0x21, 0xFF)
GET_MAX_LUN = (0xA1, 0xFE)

_GONE_ERRNOS = {errno.ENODEV, errno.ENOENT, errno.EIO}


def _ms(timeout_s: float) -> int:
    """Seconds to pyusb milliseconds (at least 1 ms: 0 would mean 'forever' in libusb)."""
    t = float(timeout_s)
    if not t > 0:
        raise ValueError(f"timeout_s must be a positive number of seconds, got {timeout_s!r}")
    return max(1, int(round(t * 1000.0)))


class UsbTransport(Transport):
    """Bulk-only byte link over a ``usb.core.Device``.

    ``UsbTransport(device)`` selects the configuration, finds the bulk-only interface and its two
    bulk endpoints and claims the interface. :meth:`find` locates a device by VID/PID/serial.
    """

    packetized = True

    def __init__(self, device: Any, url: str = "") -> None:
        self._dev = device
        self.url = url or f"usb://{device.idVendor:04x}:{device.idProduct:04x}"
        self._closed = False
        try:
            try:
                cfg = device.get_active_configuration()
            except usb.core.USBError:
                device.set_configuration()
                cfg = device.get_active_configuration()
            intf = usb.util.find_descriptor(
                cfg,
                custom_match=lambda i: i.bInterfaceClass == 0xFF and i.bInterfaceProtocol == 0x50,
            )
            if intf is None:
                raise TransportError(
                    f"{self.url}: the device has no bulk-only vendor interface (class 0xFF, protocol 0x50); "
                    "is this the analyser?"
                )
            ep_out = usb.util.find_descriptor(
                intf, custom_match=lambda e: usb.util.endpoint_direction(e.bEndpointAddress) == usb.util.ENDPOINT_OUT
                and usb.util.endpoint_type(e.bmAttributes) == usb.util.ENDPOINT_TYPE_BULK)
            ep_in = usb.util.find_descriptor(
                intf, custom_match=lambda e: usb.util.endpoint_direction(e.bEndpointAddress) == usb.util.ENDPOINT_IN
                and usb.util.endpoint_type(e.bmAttributes) == usb.util.ENDPOINT_TYPE_BULK)
            if ep_out is None or ep_in is None:
                raise TransportError(f"{self.url}: the bulk-only interface lacks a bulk IN or OUT endpoint")
            usb.util.claim_interface(device, intf)
        except usb.core.USBError as exc:
            self._release_quietly()
            raise self._map(exc, "open") from exc
        except TransportError:
            self._release_quietly()
            raise
        self._intf_number = int(intf.bInterfaceNumber)
        self._ep_out = int(ep_out.bEndpointAddress)
        self._ep_in = int(ep_in.bEndpointAddress)
        self.max_packet = int(ep_in.wMaxPacketSize)

    @classmethod
    def find(cls, vid: int, pid: int, *, serial: str | None = None, backend: Any = None,
             url: str = "") -> UsbTransport:
        """Open the first device with this VID/PID (and serial number, when given).

        ``backend``: a pyusb backend (None = libusb found by pyusb; ``SimUsbBackend`` for usbsim://).
        """
        name = url or f"usb://{vid:04x}:{pid:04x}" + (f"/{serial}" if serial else "")

        def match(dev: Any) -> bool:
            if serial is None:
                return True
            try:
                return dev.serial_number == serial
            except (usb.core.USBError, ValueError):
                return False

        try:
            dev = usb.core.find(idVendor=vid, idProduct=pid, backend=backend, custom_match=match)
        except usb.core.NoBackendError as exc:
            raise DeviceGone(
                f"{name}: pyusb found no USB backend; install libusb-1.0 (e.g. apt install libusb-1.0-0) "
                "or use usbsim:// for the simulated analyser"
            ) from exc
        except usb.core.USBError as exc:
            raise DeviceGone(f"{name}: USB enumeration failed: {exc}") from exc
        if dev is None:
            raise DeviceGone(
                f"{name}: no USB device {vid:04x}:{pid:04x}{' with serial ' + repr(serial) if serial else ''} found; "
                "check the cable, power and permissions (udev rule for the VID/PID)"
            )
        return cls(dev, url=name)

    @property
    def device(self) -> Any:
        """The underlying ``usb.core.Device``."""
        return self._dev

    # -- helpers -----------------------------------------------------------------------------
    def _map(self, exc: usb.core.USBError, what: str, timeout_s: float | None = None) -> Exception:
        code = exc.errno
        if isinstance(exc, usb.core.USBTimeoutError) or code == errno.ETIMEDOUT:
            bound = f" within {timeout_s:g} s" if timeout_s is not None else ""
            return TransportTimeout(f"{self.url}: {what} did not complete{bound} ({exc}); "
                                    "the analyser is busy or hung: retry, or do reset recovery")
        if code == errno.EPIPE:
            return EndpointStalled(f"{self.url}: {what}: endpoint stalled ({exc}); clear the halt and read the status")
        if code == errno.EBUSY:
            return TransportError(f"{self.url}: {what}: the interface is in use ({exc}); close the other program "
                                  "that holds the analyser")
        if code == errno.EACCES:
            return TransportError(f"{self.url}: {what}: permission denied ({exc}); add a udev rule granting access "
                                  "to this VID:PID, or run with the needed rights")
        if code in _GONE_ERRNOS:
            return DeviceGone(f"{self.url}: {what}: the device is gone ({exc}); check the cable and reopen the URL")
        return TransportError(f"{self.url}: {what} failed: {exc}")

    def _check_open(self, what: str) -> None:
        if self._closed:
            raise DeviceGone(f"{self.url}: {what}: the transport is closed; reopen the device URL")

    # -- Transport ---------------------------------------------------------------------------
    def write(self, data: bytes, timeout_s: float) -> None:
        """One bulk OUT transfer of all of ``data`` within ``timeout_s`` seconds."""
        self._check_open("write")
        ms = _ms(timeout_s)
        try:
            n = self._dev.write(self._ep_out, data, ms)
        except usb.core.USBError as exc:
            raise self._map(exc, f"bulk write of {len(data)} bytes", timeout_s) from exc
        if n != len(data):
            raise TransportTimeout(f"{self.url}: only {n} of {len(data)} bytes were accepted within {timeout_s:g} s")

    def read(self, n: int, timeout_s: float) -> bytes:
        """One bulk IN transfer of 1..``n`` bytes within ``timeout_s`` seconds."""
        if n <= 0:
            raise ValueError(f"read size must be a positive byte count, got {n!r}")
        self._check_open("read")
        ms = _ms(timeout_s)
        buf = array.array("B", bytes(n))
        try:
            got = self._dev.read(self._ep_in, buf, ms)
        except usb.core.USBError as exc:
            raise self._map(exc, f"bulk read of up to {n} bytes", timeout_s) from exc
        return buf[:got].tobytes() if got != n else buf.tobytes()

    def clear_halt(self, direction_in: bool) -> None:
        """CLEAR_FEATURE(ENDPOINT_HALT) on the bulk IN (True) or OUT (False) endpoint."""
        self._check_open("clear halt")
        ep = self._ep_in if direction_in else self._ep_out
        try:
            self._dev.clear_halt(ep)
        except usb.core.USBError as exc:
            raise self._map(exc, f"clear halt on endpoint {ep:#04x}") from exc

    def reset_recovery(self, timeout_s: float = 1.0) -> None:
        """Bulk-only mass storage reset (0x21/0xFF), then clear halt on bulk IN and OUT."""
        self._check_open("reset recovery")
        ms = _ms(timeout_s)
        try:
            self._dev.ctrl_transfer(BOT_RESET[0], BOT_RESET[1], 0, self._intf_number, None, ms)
        except usb.core.USBError as exc:
            raise self._map(exc, "bulk-only reset request", timeout_s) from exc
        self.clear_halt(True)
        self.clear_halt(False)

    def max_lun(self, timeout_s: float = 1.0) -> int:
        """GET MAX LUN (0xA1/0xFE): the highest logical unit number (0 for one unit)."""
        self._check_open("get max LUN")
        try:
            reply = self._dev.ctrl_transfer(GET_MAX_LUN[0], GET_MAX_LUN[1], 0, self._intf_number, 1, _ms(timeout_s))
        except usb.core.USBError as exc:
            if exc.errno == errno.EPIPE:  # devices with one LUN may stall the request (BOT 3.2)
                return 0
            raise self._map(exc, "get max LUN", timeout_s) from exc
        return int(reply[0]) if len(reply) else 0

    def _release_quietly(self) -> None:
        try:
            usb.util.dispose_resources(self._dev)
        except usb.core.USBError as exc:  # unplugged: nothing left to release
            _log.debug("%s: release: %s", self.url, exc)

    def close(self) -> None:
        """Release the interface and the device handle (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._release_quietly()

    def __repr__(self) -> str:
        return f"UsbTransport({self.url!r})"
