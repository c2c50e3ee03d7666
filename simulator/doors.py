"""The simulator's device doors, registered with the driver through entry points.

The driver (:mod:`acquisition.urls`) never imports the simulator: it looks a URL's scheme up in the
entry-point group ``acquisition.urls.DOOR_GROUP`` (``impactlab.doors`` in ``pyproject.toml``), as
pyvisa-sim registers its backend with PyVISA. The simulator uses two of the kinds of door the
driver opens (``acquisition.urls.plugin_scheme`` describes all three):

* a *pyserial* door names a package of pyserial URL handlers (``protocol_<scheme>`` modules); the
  driver adds it to ``serial.protocol_handler_packages`` and opens the URL with
  ``serial.serial_for_url`` (``sim://``: an in-process simulated analyser over a byte stream);
* a *pyusb* door builds a ``usb.backend.IBackend`` from the URL's options; the driver hands it to
  pyusb's own core (``usbsim://``: the simulated analyser behind a simulated USB bus).

Nothing is built at import time.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["SerialDoor", "UsbBackendDoor", "SIM", "USBSIM"]


@dataclass(frozen=True)
class SerialDoor:
    """A door opened through pyserial: ``handler_package`` holds ``protocol_<scheme>`` modules."""

    kind = "pyserial"
    handler_package: str


@dataclass(frozen=True)
class UsbBackendDoor:
    """A door opened through pyusb's core over a backend built from the URL's options."""

    kind = "pyusb"

    def backend(self, options: Mapping[str, Any]) -> Any:
        """A ``usb.backend.IBackend`` serving one simulated analyser built from ``options``
        (``seed``, ``config``, ``faults``, ...: the options of a ``usbsim://`` URL); it has the
        attributes ``vid`` and ``pid`` of the device it enumerates."""
        from simulator.usb_backend import SimUsbBackend

        return SimUsbBackend(options=dict(options))


#: ``sim://``: in-process simulated analyser behind pyserial's URL machinery
SIM = SerialDoor("simulator.urlhandlers")
#: ``usbsim://``: the simulated analyser on a simulated USB bus, through pyusb's own core
USBSIM = UsbBackendDoor()
