"""What can be opened: the analysers on USB, the serial ports, and the installed simulated doors.

``list_devices()`` is impactlab's ``list_resources`` (as in PyVISA): every entry carries the device
URL to hand to :class:`acquisition.driver.Analyser` or ``--device``. Nothing is opened: USB devices
are enumerated through pyusb (descriptors only), serial ports through pyserial's port listing,
and the simulated doors come from the ``impactlab.doors`` entry points.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

__all__ = ["DeviceEntry", "ANALYSER_USB_IDS", "list_devices", "list_usb", "list_serial", "list_doors"]

#: USB vendor:product IDs of analysers this driver speaks to (name shown by ``devices``)
ANALYSER_USB_IDS: dict[tuple[int, int], str] = {
    (0x1209, 0x0001): "impactlab analyser (pid.codes test ID; the simulated analyser enumerates as this)",
}


@dataclass(frozen=True)
class DeviceEntry:
    """One thing that can be opened: ``url`` for ``--device``, its ``kind`` (usb, serial,
    simulated) and a human ``description``."""

    url: str
    kind: str
    description: str

    def as_dict(self) -> dict:
        return asdict(self)


def list_usb(backend: Any = None, *, all_devices: bool = False) -> tuple[list[DeviceEntry], str | None]:
    """USB analysers (every USB device with ``all_devices``) as ``usb://VID:PID/SERIAL`` entries.

    ``backend``: a pyusb backend (None: the libusb that pyusb finds). Returns the entries and a note
    when USB could not be searched (no backend), instead of raising."""
    import usb.core

    try:
        found = list(usb.core.find(find_all=True, backend=backend) or [])
    except usb.core.NoBackendError:
        return [], "USB not searched: pyusb found no libusb backend (install libusb-1.0-0)"
    except usb.core.USBError as exc:
        return [], f"USB not searched: enumeration failed ({exc})"
    entries = []
    for dev in found:
        ids = (int(dev.idVendor), int(dev.idProduct))
        if ids not in ANALYSER_USB_IDS and not all_devices:
            continue
        try:
            serial = dev.serial_number
        except (usb.core.USBError, ValueError, NotImplementedError):
            serial = None
        url = f"usb://{ids[0]:04x}:{ids[1]:04x}" + (f"/{serial}" if serial else "")
        entries.append(DeviceEntry(url, "usb", ANALYSER_USB_IDS.get(ids, "USB device (not a known analyser)")))
    return entries, None


def list_serial() -> list[DeviceEntry]:
    """Serial ports (``/dev/ttyUSB0``, ``COM3``...) from pyserial's port listing."""
    from serial.tools import list_ports

    entries = []
    for port in sorted(list_ports.comports(), key=lambda p: p.device):
        text = " ".join(str(x) for x in (port.description, port.hwid) if x and x != "n/a")
        entries.append(DeviceEntry(port.device, "serial", text or "serial port"))
    return entries


def list_doors() -> list[DeviceEntry]:
    """The doors that need no hardware and are installed (:func:`acquisition.urls.installed_doors`:
    the simulator's and those other packages add through the ``impactlab.doors`` entry points)."""
    from acquisition.urls import installed_doors

    return [DeviceEntry(f"{row.scheme}://", "simulated", f"{row.summary.replace('`', '')} (door from {row.source})")
            for row in installed_doors()]


def list_devices(*, usb_backend: Any = None, all_usb: bool = False) -> tuple[list[DeviceEntry], list[str]]:
    """Everything that can be opened, and notes on what could not be searched."""
    usb_entries, note = list_usb(usb_backend, all_devices=all_usb)
    return usb_entries + list_serial() + list_doors(), [note] if note else []
