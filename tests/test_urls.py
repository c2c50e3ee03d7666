"""Device URL parsing: every door's syntax, and clear errors for bad strings."""
from __future__ import annotations

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
