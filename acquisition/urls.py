"""Device URLs: which door leads to the analyser.

A device URL names one way of reaching an analyser (PyVISA style). Each door is one row of
:data:`SCHEMES` (:class:`Scheme`: its URL syntax, what it is, its transport, how it parses and how it
opens); the rows generate :data:`URL_SYNTAX` (shown with every bad URL), the table of
``docs/device-urls.md`` (:func:`door_table`) and the simulated doors ``devices`` lists
(:func:`installed_doors`). :func:`parse_device_url` parses a URL into a small frozen dataclass,
:func:`open_transport` turns it into a :class:`~acquisition.transport.Transport`.

Installed packages add doors through the entry-point group :data:`DOOR_GROUP`: an entry point named
after a new scheme loads a door object whose ``kind`` says how the driver opens it (see
:func:`plugin_scheme`). The simulator's ``sim://`` and ``usbsim://`` doors come that way, so the driver
never imports the simulator.
"""
from __future__ import annotations

import re
import urllib.parse
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

from acquisition.errors import DeviceGone, InvalidDeviceURL, TransportError
from acquisition.transport import Transport

__all__ = [
    "URL_SYNTAX",
    "DOOR_GROUP",
    "SCHEMES",
    "Scheme",
    "SimURL",
    "SocketURL",
    "SerialURL",
    "UsbURL",
    "UsbSimURL",
    "PluginURL",
    "DeviceURL",
    "parse_device_url",
    "open_transport",
    "register_url_handlers",
    "find_door",
    "plugin_scheme",
    "installed_doors",
    "url_syntax",
    "door_table",
]

#: entry-point group in which installed packages register doors by URL scheme (see simulator.doors)
DOOR_GROUP = "impactlab.doors"

#: default baud rate for serial ports (ignored by pseudo-terminals)
DEFAULT_BAUD = 115200


def _bad(url: object, problem: str) -> InvalidDeviceURL:
    return InvalidDeviceURL(f"invalid device URL {url!r}: {problem}\n{url_syntax()}")


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


@dataclass(frozen=True)
class PluginURL:
    """``SCHEME://[?options]`` of a door an installed package registers (:func:`plugin_scheme`):
    ``options`` as for ``sim://`` (``seed`` int, ``noise`` bool, everything else str)."""

    scheme: str
    options: dict = field(default_factory=dict)
    url: str = ""


DeviceURL = SimURL | UsbSimURL | SocketURL | SerialURL | UsbURL | PluginURL

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


def _parse_path(url: str, text: str) -> SerialURL:
    if text.startswith("/dev/") or re.fullmatch(r"(?i)COM[0-9]+", text):
        return SerialURL(path=text, url=url)
    raise _bad(url, "not a URL (SCHEME://...) nor a serial device path (/dev/...)")


def _parse_serial_url(url: str, rest: str) -> SerialURL:
    path, _, query = rest.partition("?")
    return _parse_serial(url, path, query)


def _parse_options(scheme: str) -> Callable[[str, str], PluginURL]:
    """The parser of an installed door's ``SCHEME://[?options]`` (the same query rules as ``sim://``)."""
    def parse(url: str, rest: str) -> PluginURL:
        path, _, query = rest.partition("?")
        if path not in ("", "/"):
            raise _bad(url, f"{scheme}:// takes no host or path (got {path!r}); put options after '?'")
        return PluginURL(scheme=scheme, options=_parse_query(url, query), url=url)
    return parse


@dataclass(frozen=True)
class Scheme:
    """One door: a row of :data:`SCHEMES` (or of an installed package, :func:`plugin_scheme`).

    ``scheme``: the URL scheme without ``://`` ("" for a bare serial device path); ``syntax``: how
    the URL is written; ``summary``: what the door reaches (one line, Markdown backticks allowed);
    ``transport`` and ``link``: the :class:`Transport` class and its link kind (stream or
    packetized); ``parse(url, rest)``: the URL dataclass of ``rest`` (the text after ``scheme://``),
    raising :class:`InvalidDeviceURL`; ``open(target, timeout_s)``: the connected transport;
    ``simulated``: the door needs no hardware, so ``devices`` lists it when it is installed;
    ``source``: the entry point that installed it ("" for the driver's own rows)."""

    scheme: str
    syntax: str
    summary: str
    transport: str
    link: str
    parse: Callable[[str, str], DeviceURL]
    open: Callable[[Any, float], Transport]
    simulated: bool = False
    source: str = ""


def find_door(scheme: str, url: str = "") -> Any:
    """The door object registered for ``scheme`` in the entry-point group :data:`DOOR_GROUP`.

    The simulated doors (``sim``, ``usbsim``) are registered by the simulator package in
    ``pyproject.toml``, so the driver never imports the simulator. Raises
    :class:`InvalidDeviceURL` naming the scheme when nothing is installed for it."""
    from importlib.metadata import entry_points

    found = [ep for ep in entry_points(group=DOOR_GROUP) if ep.name == scheme]
    if not found:
        raise _bad(url or f"{scheme}://", f"no door is installed for {scheme}:// (entry-point group {DOOR_GROUP!r}); "
                   "install impactlab with its simulator: pip install -e . in the checkout")
    return found[0].load()


def _query(options: dict) -> str:
    """The query of a URL's options again (booleans as on/off), with its '?' (empty without options)."""
    text = urllib.parse.urlencode({k: ("on" if v is True else "off" if v is False else v) for k, v in options.items()})
    return f"?{text}" if text else ""


def _open_door(door: Any, scheme: str, target: Any, timeout_s: float) -> Transport:
    """Open an installed door by its ``kind``: ``pyserial`` (its ``handler_package`` holds
    ``protocol_<scheme>`` modules; pyserial opens the URL), ``pyusb`` (``backend(options)`` builds a
    pyusb backend with attributes ``vid`` and ``pid``; pyusb's own core drives it) or ``transport``
    (``open(target, timeout_s)`` returns the :class:`Transport` itself)."""
    kind = getattr(door, "kind", "")
    try:
        if kind == "pyserial":
            return _open_stream(f"{scheme}://{_query(target.options)}", target, timeout_s)
        if kind == "pyusb":
            from acquisition.usb_transport import UsbTransport

            backend = door.backend(dict(target.options))
            return UsbTransport.find(backend.vid, backend.pid, backend=backend, url=target.url)
        if kind == "transport":
            transport = door.open(target, timeout_s)
            if not isinstance(transport, Transport):
                raise TransportError(f"the door of {scheme}:// returned {type(transport).__name__}, not a Transport; "
                                     "fix the package that installs it")
            return transport
    except (InvalidDeviceURL, TransportError):
        raise
    except ValueError as exc:  # the door refused an option (unknown name, bad value)
        raise _bad(target.url, str(exc)) from exc
    raise _bad(target.url, f"the door installed for {scheme}:// is of kind {kind!r}; the driver opens the kinds "
                           "'pyserial', 'pyusb' and 'transport': fix or uninstall the package that installs it")


def _open_installed(scheme: str) -> Callable[[Any, float], Transport]:
    """The opener of a built-in row whose door an installed package provides (``sim``, ``usbsim``)."""
    def open_(target: Any, timeout_s: float) -> Transport:
        return _open_door(find_door(scheme, target.url), scheme, target, timeout_s)
    return open_


def _open_socket(target: SocketURL, timeout_s: float) -> Transport:
    host = f"[{target.host}]" if ":" in target.host else target.host
    return _open_stream(f"socket://{host}:{target.port}", target, timeout_s)


def _open_serial(target: SerialURL, timeout_s: float) -> Transport:
    return _open_stream(target.path, target, timeout_s)


def _open_usb(target: UsbURL, timeout_s: float) -> Transport:
    from acquisition.usb_transport import UsbTransport

    return UsbTransport.find(target.vid, target.pid, serial=target.serial, url=target.url)


#: the driver's own doors, in the order they are listed (:data:`URL_SYNTAX`, ``docs/device-urls.md``)
SCHEMES: tuple[Scheme, ...] = (
    Scheme("sim", "sim://[?seed=N&config=PATH&noise=on|off&...]", "in-process simulated analyser, through pyserial",
           "StreamTransport", "stream", lambda url, rest: _parse_sim(url, rest, SimURL), _open_installed("sim"),
           simulated=True),
    Scheme("socket", "socket://HOST:PORT", "raw TCP through pyserial (e.g. `python -m simulator serve --tcp`)",
           "StreamTransport", "stream", _parse_socket, _open_socket),
    Scheme("", "/dev/ttyUSB0, /dev/pts/N, COM3", "serial port or pseudo-terminal at 115200 baud",
           "StreamTransport", "stream", _parse_path, _open_serial),
    Scheme("serial", "serial:///dev/ttyUSB0?baud=N", "the same with a baud rate",
           "StreamTransport", "stream", _parse_serial_url, _open_serial),
    Scheme("usb", "usb://VID:PID[/SERIAL]", "real analyser through pyusb and libusb (VID/PID in hex)",
           "UsbTransport", "packetized", _parse_usb, _open_usb),
    Scheme("usbsim", "usbsim://[?seed=N&config=PATH&noise=on|off&...]",
           "simulated analyser as a USB device: pyusb's core over `SimUsbBackend`",
           "UsbTransport", "packetized", lambda url, rest: _parse_sim(url, rest, UsbSimURL), _open_installed("usbsim"),
           simulated=True),
)
_BY_SCHEME = {row.scheme: row for row in SCHEMES}
#: the scheme of each URL dataclass of the driver's own rows (a bare path parses to SerialURL too)
_SCHEME_OF: dict[type, str] = {SimURL: "sim", UsbSimURL: "usbsim", SocketURL: "socket", SerialURL: "serial",
                               UsbURL: "usb"}


def _syntax_line(syntax: str, summary: str) -> str:
    return f"  {syntax:<48s} {summary.replace('`', '')}"


#: the accepted URLs of the driver's own doors, as every bad-URL message shows them
URL_SYNTAX = "accepted device URLs:\n" + "\n".join(_syntax_line(r.syntax, r.summary) for r in SCHEMES)


def _plugin_entry_points() -> list:
    from importlib.metadata import entry_points

    return sorted((ep for ep in entry_points(group=DOOR_GROUP) if ep.name not in _BY_SCHEME), key=lambda e: e.name)


def url_syntax() -> str:
    """:data:`URL_SYNTAX` and a line per door an installed package adds (nothing is loaded)."""
    extra = [_syntax_line(f"{ep.name}://[?OPTIONS]", f"door installed by {ep.value}") for ep in _plugin_entry_points()]
    return "\n".join([URL_SYNTAX, *extra])


def plugin_scheme(scheme: str, url: str = "") -> Scheme:
    """The row of a door an installed package registers in :data:`DOOR_GROUP` under ``scheme``.

    The entry point loads a door object: ``kind`` (``"pyserial"``, ``"pyusb"`` or ``"transport"``,
    see :func:`_open_door`) and optionally ``syntax`` and ``summary`` (text for the syntax list and
    ``devices``). Its URLs are ``SCHEME://[?KEY=VALUE&...]`` parsed into :class:`PluginURL`.
    A scheme of the driver's own rows is never taken over. Raises :class:`InvalidDeviceURL` when
    nothing is installed for ``scheme``."""
    found = [ep for ep in _plugin_entry_points() if ep.name == scheme]
    if not found:
        raise _bad(url or f"{scheme}://", f"unknown scheme {scheme + '://'!r}")
    ep = found[0]
    door = ep.load()
    return Scheme(scheme, str(getattr(door, "syntax", "") or f"{scheme}://[?OPTIONS]"),
                  str(getattr(door, "summary", "") or f"door installed by {ep.value}"),
                  "Transport", "packetized" if getattr(door, "kind", "") == "pyusb" else "stream",
                  _parse_options(scheme), lambda target, timeout_s: _open_door(door, scheme, target, timeout_s),
                  simulated=True, source=ep.value)


def installed_doors() -> list[Scheme]:
    """The doors that need no hardware and are installed: the simulator's (when the simulator is
    installed) and every door an installed package adds (``devices`` lists them)."""
    from importlib.metadata import entry_points

    names = {ep.name: ep.value for ep in entry_points(group=DOOR_GROUP)}
    own = [replace(row, source=names[row.scheme]) for row in SCHEMES if row.simulated and row.scheme in names]
    return own + [plugin_scheme(ep.name) for ep in _plugin_entry_points()]


def door_table() -> str:
    """The Markdown table of the driver's doors in ``docs/device-urls.md`` (generated from :data:`SCHEMES`)."""
    lines = ["| URL | door | transport | link |", "|---|---|---|---|"]
    for row in SCHEMES:
        url = row.syntax.replace("|", "\\|")
        lines.append(f"| `{url}` | {row.summary} | `{row.transport}` | {row.link} |")
    return "\n".join(lines)


def parse_device_url(url: str) -> DeviceURL:
    """Parse a device URL into its dataclass; raise :class:`InvalidDeviceURL` showing the syntax."""
    if not isinstance(url, str):
        raise _bad(url, f"expected a string, got {type(url).__name__}")
    text = url.strip()
    if not text:
        raise _bad(url, "empty string")
    if "://" not in text:
        return _BY_SCHEME[""].parse(url, text)
    scheme, _, rest = text.partition("://")
    scheme = scheme.lower()
    row = _BY_SCHEME.get(scheme) if scheme else None
    if row is None:
        if not re.fullmatch(r"[a-z][a-z0-9+.-]*", scheme):
            raise _bad(url, f"unknown scheme {scheme + '://'!r}")
        row = plugin_scheme(scheme, url)
    return row.parse(url, rest)


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
    if isinstance(target, PluginURL):
        row = plugin_scheme(target.scheme, target.url)
    else:
        row = _BY_SCHEME[_SCHEME_OF[type(target)]]
    return row.open(target, timeout_s)
