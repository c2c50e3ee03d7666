"""Device URLs: which door leads to the analyser.

A device URL names one way of reaching an analyser (PyVISA style). Each scheme parses into a
small frozen dataclass; :func:`open_transport` turns it into a :class:`~acquisition.transport.Transport`.

==============================================  =====================================================
URL                                             door
==============================================  =====================================================
``sim://[?seed=N&config=PATH&noise=on|off...]``  in-process simulated analyser through pyserial
``socket://HOST:PORT``                          raw TCP (pyserial), e.g. ``python -m simulator serve``
``/dev/ttyUSB0``, ``/dev/pts/5``                serial port or pseudo-terminal (pyserial)
``serial:///dev/ttyUSB0?baud=115200``           the same with options
``usb://VID:PID[/SERIAL]``                      real hardware through pyusb/libusb (hex VID/PID)
``usbsim://[?seed=N...]``                       simulated USB device: pyusb core over ``SimUsbBackend``
==============================================  =====================================================

See ``docs/device-urls.md`` for the full description.
"""
from __future__ import annotations

import re
import urllib.parse
from dataclasses import dataclass, field
from typing import Any

from acquisition.errors import DeviceGone, InvalidDeviceURL, TransportError
from acquisition.transport import Transport

__all__ = [
    "URL_SYNTAX",
    "SimURL",
    "SocketURL",
    "SerialURL",
    "UsbURL",
    "UsbSimURL",
    "DeviceURL",
    "parse_device_url",
    "open_transport",
    "register_url_handlers",
]

URL_SYNTAX = """accepted device URLs:
  sim://[?seed=N&config=PATH&noise=on|off&...]   in-process simulated analyser (pyserial)
  socket://HOST:PORT                            raw TCP, e.g. to 'python -m simulator serve --tcp'
  /dev/ttyUSB0  or  /dev/pts/N                  serial port or pseudo-terminal (115200 baud)
  serial:///dev/ttyUSB0?baud=115200             serial port with options (baud)
  usb://VID:PID[/SERIAL]                        real analyser over USB, VID/PID in hex (e.g. usb://1209:0001)
  usbsim://[?seed=N&config=PATH&noise=on|off&...]  simulated USB analyser (pyusb core over SimUsbBackend)"""

#: default baud rate for serial ports (ignored by pseudo-terminals)
DEFAULT_BAUD = 115200


def _bad(url: object, problem: str) -> InvalidDeviceURL:
    return InvalidDeviceURL(f"invalid device URL {url!r}: {problem}\n{URL_SYNTAX}")


@dataclass(frozen=True)
class SimURL:
    """``sim://?...``: an in-process simulated analyser reached through pyserial (stream).

    ``options`` holds the query (``seed`` as int, ``noise`` as bool, everything else as str)
    handed to ``simulator.analyser.create_analyser``.
    """

    options: dict = field(default_factory=dict)
    url: str = "sim://"


@dataclass(frozen=True)
class UsbSimURL:
    """``usbsim://?...``: the simulated analyser as a USB device, driven through pyusb's core."""

    options: dict = field(default_factory=dict)
    url: str = "usbsim://"


@dataclass(frozen=True)
class SocketURL:
    """``socket://HOST:PORT``: raw TCP through pyserial (stream)."""

    host: str
    port: int
    url: str = ""


@dataclass(frozen=True)
class SerialURL:
    """A serial port or pseudo-terminal path (stream); ``baud`` in bit/s."""

    path: str
    baud: int = DEFAULT_BAUD
    url: str = ""


@dataclass(frozen=True)
class UsbURL:
    """``usb://VID:PID[/SERIAL]``: a real analyser on USB (packetized), found through libusb."""

    vid: int
    pid: int
    serial: str | None = None
    url: str = ""


DeviceURL = SimURL | UsbSimURL | SocketURL | SerialURL | UsbURL

_INT_RE = re.compile(r"^[0-9]+$")


def _parse_query(url: str, query: str) -> dict:
    """Decode ``a=1&b=2`` into a dict, converting the options every simulator understands."""
    options: dict = {}
    if not query:
        return options
    try:
        pairs = urllib.parse.parse_qsl(query, keep_blank_values=True, strict_parsing=True)
    except ValueError as exc:
        raise _bad(url, f"query {query!r} is not KEY=VALUE pairs joined by '&' ({exc})") from None
    for key, value in pairs:
        if not key:
            raise _bad(url, "an option has an empty name")
        if key in options:
            raise _bad(url, f"option {key!r} given twice")
        if key == "seed":
            if not _INT_RE.match(value):
                raise _bad(url, f"seed must be a non-negative integer, got {value!r}")
            options[key] = int(value)
        elif key == "noise":
            if value.lower() not in ("on", "off"):
                raise _bad(url, f"noise must be 'on' or 'off', got {value!r}")
            options[key] = value.lower() == "on"
        elif key == "packetized":
            raise _bad(url, "'packetized' is set by the door (sim:// is a byte stream, usbsim:// is packetized); "
                            "drop it")
        elif key == "config":
            if not value:
                raise _bad(url, "config needs a path to a TOML file (config=PATH)")
            options[key] = value
        else:
            options[key] = value
    return options


def _parse_sim(url: str, rest: str, cls: type) -> SimURL | UsbSimURL:
    path, _, query = rest.partition("?")
    if path not in ("", "/"):
        raise _bad(url, f"the simulator takes no host or path (got {path!r}); put options after '?'")
    return cls(options=_parse_query(url, query), url=url)


def _parse_socket(url: str, rest: str) -> SocketURL:
    if "?" in rest or "/" in rest.rstrip("/"):
        raise _bad(url, "socket:// takes only HOST:PORT (no path, no options)")
    hostport = rest.rstrip("/")
    if hostport.startswith("["):  # IPv6 literal [::1]:5000
        host, sep, port_s = hostport[1:].partition("]:")
        if not sep:
            raise _bad(url, "an IPv6 host is written [ADDR]:PORT")
    else:
        host, sep, port_s = hostport.rpartition(":")
        if not sep:
            raise _bad(url, "missing ':PORT'")
    if not host:
        raise _bad(url, "missing HOST")
    if not _INT_RE.match(port_s) or not 0 < int(port_s) < 65536:
        raise _bad(url, f"PORT must be an integer 1..65535, got {port_s!r}")
    return SocketURL(host=host, port=int(port_s), url=url)


def _parse_serial(url: str, path: str, query: str) -> SerialURL:
    if not path:
        raise _bad(url, "missing the serial port path")
    baud = DEFAULT_BAUD
    for key, value in _parse_query(url, query).items():
        if key == "baud":
            if not _INT_RE.match(str(value)) or int(value) <= 0:
                raise _bad(url, f"baud must be a positive integer, got {value!r}")
            baud = int(value)
        else:
            raise _bad(url, f"unknown serial option {key!r} (only baud=N)")
    return SerialURL(path=path, baud=baud, url=url)


def _parse_hex16(url: str, text: str, what: str) -> int:
    t = text[2:] if text.lower().startswith("0x") else text
    if not re.fullmatch(r"[0-9a-fA-F]{1,4}", t):
        raise _bad(url, f"{what} must be 1-4 hex digits, got {text!r}")
    return int(t, 16)


def _parse_usb(url: str, rest: str) -> UsbURL:
    if "?" in rest:
        raise _bad(url, "usb:// takes no options")
    ids, _, serial = rest.partition("/")
    vid_s, sep, pid_s = ids.partition(":")
    if not sep:
        raise _bad(url, "expected VID:PID in hex, e.g. usb://1209:0001")
    vid = _parse_hex16(url, vid_s, "VID")
    pid = _parse_hex16(url, pid_s, "PID")
    serial = urllib.parse.unquote(serial.rstrip("/"))
    return UsbURL(vid=vid, pid=pid, serial=serial or None, url=url)


def parse_device_url(url: str) -> DeviceURL:
    """Parse a device URL into its dataclass; raise :class:`InvalidDeviceURL` showing the syntax."""
    if not isinstance(url, str):
        raise _bad(url, f"expected a string, got {type(url).__name__}")
    text = url.strip()
    if not text:
        raise _bad(url, "empty string")
    if "://" not in text:
        if text.startswith("/dev/") or re.fullmatch(r"(?i)COM[0-9]+", text):
            return SerialURL(path=text, url=url)
        raise _bad(url, "not a URL (SCHEME://...) nor a serial device path (/dev/...)")
    scheme, _, rest = text.partition("://")
    scheme = scheme.lower()
    if scheme == "sim":
        return _parse_sim(url, rest, SimURL)
    if scheme == "usbsim":
        return _parse_sim(url, rest, UsbSimURL)
    if scheme == "socket":
        return _parse_socket(url, rest)
    if scheme == "serial":
        path, _, query = rest.partition("?")
        return _parse_serial(url, path, query)
    if scheme == "usb":
        return _parse_usb(url, rest)
    raise _bad(url, f"unknown scheme {scheme + '://'!r}")


#: entry-point group in which installed packages register doors by URL scheme (see simulator.doors)
DOOR_GROUP = "impactlab.doors"


def find_door(scheme: str, url: str = "") -> Any:
    """The door registered for ``scheme`` in the entry-point group :data:`DOOR_GROUP`.

    The simulated doors (``sim``, ``usbsim``) are registered by the simulator package in
    ``pyproject.toml``, so the driver never imports the simulator. Raises
    :class:`InvalidDeviceURL` naming the scheme when nothing is installed for it."""
    from importlib.metadata import entry_points

    found = [ep for ep in entry_points(group=DOOR_GROUP) if ep.name == scheme]
    if not found:
        raise _bad(url or f"{scheme}://", f"no door is installed for {scheme}:// (entry-point group {DOOR_GROUP!r}); "
                   "install impactlab with its simulator: pip install -e . in the checkout")
    return found[0].load()


def register_url_handlers() -> None:
    """Let ``serial.serial_for_url`` find the handlers of every installed pyserial door (idempotent)."""
    from importlib.metadata import entry_points

    import serial

    for ep in entry_points(group=DOOR_GROUP):
        door = ep.load()
        package = getattr(door, "handler_package", None)
        if getattr(door, "kind", "") == "pyserial" and package and package not in serial.protocol_handler_packages:
            serial.protocol_handler_packages.append(package)


def _open_stream(pyserial_url: str, target: DeviceURL, timeout_s: float) -> Transport:
    import serial

    from acquisition.stream_transport import StreamTransport

    register_url_handlers()
    try:
        if isinstance(target, SerialURL):
            # exclusive: an advisory lock keeps a second program off the same port
            port = serial.Serial(target.path, baudrate=target.baud, timeout=timeout_s, write_timeout=timeout_s,
                                 exclusive=True)
        else:
            port = serial.serial_for_url(pyserial_url, timeout=timeout_s, write_timeout=timeout_s)
    except InvalidDeviceURL:
        raise
    except ValueError as exc:  # the simulator refused an option (unknown name, bad value)
        raise _bad(target.url, str(exc)) from exc
    except (serial.SerialException, OSError) as exc:
        raise DeviceGone(
            f"cannot open {target.url!r}: {exc}; check that the device or server is there "
            "(for socket:// start 'python -m simulator serve --tcp HOST:PORT')"
        ) from exc
    return StreamTransport(port, url=target.url)


def open_transport(url: str | DeviceURL, timeout_s: float = 2.0) -> Transport:
    """Open the door a device URL names and return a connected :class:`Transport`.

    ``timeout_s``: the port's initial read/write timeout, seconds (every transport call then
    passes its own bound; pyserial's ``socket://`` connect gives up after its own 5 s).
    Raises :class:`InvalidDeviceURL` for a malformed URL or an option the simulator refuses,
    :class:`DeviceGone` when nothing answers there.
    """
    target = parse_device_url(url) if isinstance(url, str) else url
    if isinstance(target, SimURL):
        query = urllib.parse.urlencode(
            {k: ("on" if v is True else "off" if v is False else v) for k, v in target.options.items()}
        )
        find_door("sim", target.url)  # a clear error when the simulator is not installed
        return _open_stream("sim://" + (f"?{query}" if query else ""), target, timeout_s)
    if isinstance(target, SocketURL):
        host = f"[{target.host}]" if ":" in target.host else target.host
        return _open_stream(f"socket://{host}:{target.port}", target, timeout_s)
    if isinstance(target, SerialURL):
        return _open_stream(target.path, target, timeout_s)
    if isinstance(target, UsbSimURL):
        from acquisition.usb_transport import UsbTransport

        door = find_door("usbsim", target.url)
        try:
            backend = door.backend(dict(target.options))
        except InvalidDeviceURL:
            raise
        except ValueError as exc:
            raise _bad(target.url, str(exc)) from exc
        return UsbTransport.find(backend.vid, backend.pid, backend=backend, url=target.url)
    if isinstance(target, UsbURL):
        from acquisition.usb_transport import UsbTransport

        return UsbTransport.find(target.vid, target.pid, serial=target.serial, url=target.url)
    raise TransportError(f"no door for {target!r}")  # pragma: no cover - the union is closed
