"""Device URL parsing: every door's syntax, and clear errors for bad strings."""
from __future__ import annotations

import sys
from urllib.parse import quote

import pytest
import serial
from hypothesis import given, settings
from hypothesis import strategies as st

from acquisition.errors import DeviceGone, InvalidDeviceURL
from acquisition.urls import (
    SerialURL,
    SimURL,
    SocketURL,
    UsbSimURL,
    UsbURL,
    open_transport,
    parse_device_url,
    register_url_handlers,
)


def test_sim_url_options_are_typed() -> None:
    u = parse_device_url("sim://?seed=3&config=/tmp/frame.toml&noise=off&hammer=soft")
    assert isinstance(u, SimURL)
    assert u.options == {"seed": 3, "config": "/tmp/frame.toml", "noise": False, "hammer": "soft"}
    assert parse_device_url("sim://").options == {}
    assert parse_device_url("SIM://?noise=ON").options == {"noise": True}


def test_usbsim_url() -> None:
    u = parse_device_url("usbsim://?seed=7")
    assert isinstance(u, UsbSimURL)
    assert u.options == {"seed": 7}


def test_socket_url() -> None:
    assert parse_device_url("socket://127.0.0.1:5025") == SocketURL("127.0.0.1", 5025, "socket://127.0.0.1:5025")
    u = parse_device_url("socket://[::1]:80")
    assert (u.host, u.port) == ("::1", 80)
    assert parse_device_url("socket://localhost:1/").port == 1


def test_serial_paths() -> None:
    u = parse_device_url("/dev/ttyUSB0")
    assert isinstance(u, SerialURL) and u.path == "/dev/ttyUSB0" and u.baud == 115200
    assert parse_device_url("/dev/pts/7").path == "/dev/pts/7"
    u = parse_device_url("serial:///dev/ttyACM1?baud=9600")
    assert (u.path, u.baud) == ("/dev/ttyACM1", 9600)
    assert parse_device_url("COM3").path == "COM3"


def test_usb_url_hex_ids_and_serial() -> None:
    assert parse_device_url("usb://1209:0001") == UsbURL(0x1209, 0x0001, None, "usb://1209:0001")
    u = parse_device_url("usb://0x1209:0xABCD/SN%2042")
    assert (u.vid, u.pid, u.serial) == (0x1209, 0xABCD, "SN 42")


@pytest.mark.parametrize(
    "url, fragment",
    [
        ("", "empty"),
        ("ttyUSB0", "not a URL"),
        ("ftp://x", "unknown scheme"),
        ("sim://?seed=-1", "seed must be a non-negative integer"),
        ("sim://?seed=abc", "seed must be"),
        ("sim://?noise=maybe", "noise must be 'on' or 'off'"),
        ("sim://?seed=1&seed=2", "given twice"),
        ("sim://?config=", "config needs a path"),
        ("sim://host", "takes no host"),
        ("sim://?=3", "empty name"),
        ("usbsim://?packetized=off", "set by the door"),
        ("socket://127.0.0.1", "missing ':PORT'"),
        ("socket://:5000", "missing HOST"),
        ("socket://h:0", "PORT must be"),
        ("socket://h:70000", "PORT must be"),
        ("socket://h:12/x", "only HOST:PORT"),
        ("usb://1209", "VID:PID"),
        ("usb://12g9:0001", "VID must be 1-4 hex digits"),
        ("usb://1209:12345", "PID must be 1-4 hex digits"),
        ("serial:///dev/ttyS0?baud=fast", "baud must be a positive integer"),
        ("serial:///dev/ttyS0?parity=E", "unknown serial option"),
        ("serial://", "missing the serial port path"),
    ],
)
def test_bad_urls_name_problem_and_show_syntax(url: str, fragment: str) -> None:
    with pytest.raises(InvalidDeviceURL) as info:
        parse_device_url(url)
    text = str(info.value)
    assert fragment in text
    assert "accepted device URLs" in text and "usbsim://" in text and "socket://HOST:PORT" in text


def test_non_string_is_rejected() -> None:
    with pytest.raises(InvalidDeviceURL, match="expected a string"):
        parse_device_url(5025)  # type: ignore[arg-type]


def test_invalid_url_is_a_value_error() -> None:
    with pytest.raises(ValueError):
        open_transport("nonsense")


def test_register_is_idempotent() -> None:
    register_url_handlers()
    register_url_handlers()
    assert serial.protocol_handler_packages.count("simulator.urlhandlers") == 1


def test_socket_to_closed_port_is_device_gone() -> None:
    import socket

    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there now
    with pytest.raises(DeviceGone, match="cannot open"):
        open_transport(f"socket://127.0.0.1:{port}", timeout_s=0.5)


def test_missing_serial_port_is_device_gone(tmp_path) -> None:
    with pytest.raises(DeviceGone):
        open_transport(f"serial://{tmp_path}/no-such-tty")


def test_usb_without_device_is_device_gone() -> None:
    # real hardware door: either libusb is missing or no such device is plugged in
    with pytest.raises(DeviceGone, match="usb://fffe:fffd"):
        open_transport("usb://fffe:fffd")


# -- properties -----------------------------------------------------------------------------------
@settings(derandomize=True, max_examples=200, deadline=None)
@given(st.text(max_size=40))
def test_any_string_parses_or_raises_invalid_url(text: str) -> None:
    try:
        parse_device_url(text)
    except InvalidDeviceURL as exc:
        assert "accepted device URLs" in str(exc)


@settings(derandomize=True, max_examples=200, deadline=None)
@given(st.integers(0, 0xFFFF), st.integers(0, 0xFFFF), st.one_of(st.none(), st.text(min_size=1, max_size=12)))
def test_usb_url_round_trip(vid: int, pid: int, serial_no) -> None:
    url = f"usb://{vid:04x}:{pid:04X}" + (f"/{quote(serial_no, safe='')}" if serial_no else "")
    u = parse_device_url(url)
    assert (u.vid, u.pid, u.serial) == (vid, pid, serial_no or None)


@settings(derandomize=True, max_examples=100, deadline=None)
@given(st.integers(1, 65535), st.sampled_from(["127.0.0.1", "localhost", "analyser.lab", "::1"]))
def test_socket_url_round_trip(port: int, host: str) -> None:
    shown = f"[{host}]" if ":" in host else host
    u = parse_device_url(f"socket://{shown}:{port}")
    assert (u.host, u.port) == (host, port)


# -- the door rows and the plug-in path -------------------------------------------------------------
def test_every_door_row_generates_the_syntax_and_the_docs_table() -> None:
    from pathlib import Path

    from acquisition.urls import SCHEMES, URL_SYNTAX, door_table

    for row in SCHEMES:
        assert row.syntax in URL_SYNTAX
        assert f"`{row.syntax.replace('|', chr(92) + '|')}`" in door_table()
    docs = (Path(__file__).resolve().parents[1] / "docs" / "device-urls.md").read_text(encoding="utf-8")
    assert door_table() in docs, "docs/device-urls.md: replace the door table by acquisition.urls.door_table():\n" + door_table()


_DOOR_PACKAGE = '''"""A third-party door package: loopsim:// (a pyserial door) and echo:// (a transport door)."""
import serial

from acquisition.stream_transport import StreamTransport


class PyserialDoor:
    kind = "pyserial"
    handler_package = "loopdoor"
    syntax = "loopsim://[?seed=N]"
    summary = "the simulated analyser through a plug-in pyserial handler"


class EchoDoor:
    kind = "transport"
    summary = "a byte loop-back"

    def open(self, target, timeout_s):
        if set(target.options) - {"tag"}:
            raise ValueError(f"echo:// knows only the option tag, got {sorted(target.options)}")
        return StreamTransport(serial.serial_for_url("loop://", timeout=timeout_s), url=target.url)


DOOR = PyserialDoor()
ECHO = EchoDoor()
'''
_DOOR_HANDLER = '''"""pyserial handler of loopsim://: the simulator's sim:// port under another scheme."""
from acquisition.urls import parse_device_url
from simulator.urlhandlers.protocol_sim import Serial as _SimSerial


class Serial(_SimSerial):
    @staticmethod
    def from_url(url):
        return dict(parse_device_url(url).options)
'''


def _install_door_package(root) -> str:
    """A door package as pip leaves it: its modules and a dist-info whose entry_points.txt registers
    two doors in the group impactlab.doors. Returns the folder to put on the path."""
    from acquisition.urls import DOOR_GROUP

    site = root / "site"
    (site / "loopdoor").mkdir(parents=True)
    (site / "loopdoor" / "__init__.py").write_text(_DOOR_PACKAGE)
    (site / "loopdoor" / "protocol_loopsim.py").write_text(_DOOR_HANDLER)
    dist = site / "loopdoor-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: loopdoor\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(f"[{DOOR_GROUP}]\nloopsim = loopdoor:DOOR\necho = loopdoor:ECHO\n")
    return str(site)


@pytest.fixture
def door_package(tmp_path, monkeypatch) -> str:
    site = _install_door_package(tmp_path)
    monkeypatch.syspath_prepend(site)
    monkeypatch.setattr(serial, "protocol_handler_packages", list(serial.protocol_handler_packages))
    yield site
    for name in [m for m in sys.modules if m == "loopdoor" or m.startswith("loopdoor.")]:
        del sys.modules[name]


def test_an_installed_package_adds_a_door_that_opens(door_package) -> None:
    from acquisition.discovery import list_doors
    from acquisition.driver import Analyser
    from acquisition.urls import PluginURL, url_syntax

    assert parse_device_url("loopsim://?seed=3") == PluginURL("loopsim", {"seed": 3}, "loopsim://?seed=3")
    assert "loopsim://" in url_syntax() and "echo://" in url_syntax()
    assert {"loopsim://", "echo://"} <= {e.url for e in list_doors()}
    with Analyser("loopsim://?seed=3") as analyser:            # pyserial door: the package's own handler
        assert analyser.identify().vendor == "IMPACTLB"
    with open_transport("echo://?tag=a", timeout_s=0.5) as t:  # transport door: the package opens it
        t.write(b"ping", 0.5)
        assert t.read(4, 0.5) == b"ping"
    with pytest.raises(InvalidDeviceURL, match="knows only the option tag"):
        open_transport("echo://?bogus=1")
    with pytest.raises(InvalidDeviceURL, match="echo:// takes no host"):
        parse_device_url("echo://host")


def test_a_door_package_cannot_take_over_a_builtin_scheme(door_package, tmp_path) -> None:
    from acquisition.urls import DOOR_GROUP

    dist = tmp_path / "site" / "loopdoor-0.1.dist-info" / "entry_points.txt"
    dist.write_text(f"[{DOOR_GROUP}]\nsocket = loopdoor:ECHO\n")
    assert isinstance(parse_device_url("socket://h:1"), SocketURL)


def test_devices_command_lists_an_installed_door(door_package) -> None:
    import os
    import subprocess

    env = {**os.environ, "PYTHONPATH": os.pathsep.join([door_package, os.environ.get("PYTHONPATH", "")])}
    out = subprocess.run([sys.executable, "-m", "acquisition", "devices"], capture_output=True, text=True, env=env,
                         timeout=60, check=True).stdout
    assert "loopsim://" in out and "plug-in pyserial handler" in out and "sim://" in out
