"""pyserial handler for ``sim://[?seed=N&config=PATH&noise=on|off&...]``.

``serial.serial_for_url("sim://?seed=3")`` (after ``acquisition.urls.register_url_handlers()``)
returns a :class:`Serial` that talks to an in-process simulated analyser: the bytes written go
into ``simulator.firmware.Firmware.write`` and the bytes read come out of ``Firmware.read``, in
stream mode (no packets, no stalls), exactly as a serial cable or a TCP socket would carry them.

Reads follow pyserial semantics: ``read(n)`` returns ``n`` bytes, or fewer when ``timeout``
(seconds) expires first; ``timeout=None`` waits until ``n`` bytes have come. The firmware runs in
the caller's thread; while it has nothing to send the read polls it with a short sleep.
"""
from __future__ import annotations

import time
import urllib.parse
from typing import Any

from serial.serialutil import PortNotOpenError, SerialBase, SerialException, SerialTimeoutException, to_bytes

__all__ = ["Serial"]

#: largest chunk pulled from the firmware per call (bytes)
_CHUNK = 1 << 20
#: polling interval bounds while the firmware has nothing to say (s)
_POLL_MIN_S = 0.0002
_POLL_MAX_S = 0.005


class Serial(SerialBase):
    """A pyserial port whose far end is an in-process simulated analyser (stream mode)."""

    BAUDRATES = SerialBase.BAUDRATES
    is_open: bool

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._firmware: Any = None
        self._rx = bytearray()
        self.options: dict = {}
        super().__init__(*args, **kwargs)

    # -- opening -----------------------------------------------------------------------------
    @classmethod
    def from_firmware(cls, firmware: Any, *, timeout: float | None = None) -> Serial:
        """An open port over an existing stream-mode firmware object (benchmarks, tests)."""
        port = cls(None, timeout=timeout)
        port._port = "sim://"
        port.portstr = "sim://"
        port._firmware = firmware
        port.is_open = True
        return port

    def open(self) -> None:
        """Build the simulated analyser named by the URL's query and connect to it."""
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        if self.is_open:
            raise SerialException("Port is already open.")
        self.options = self.from_url(self.portstr)
        from simulator.analyser import create_analyser

        self._firmware = create_analyser(dict(self.options))
        self._rx = bytearray()
        self.is_open = True

    @staticmethod
    def from_url(url: str) -> dict:
        """Options of a ``sim://`` URL (``seed`` int, ``noise`` bool, the rest str).

        Raises ``acquisition.errors.InvalidDeviceURL`` (a ValueError) for a malformed query.
        """
        from acquisition.urls import SimURL, parse_device_url

        parts = urllib.parse.urlsplit(url)
        if parts.scheme.lower() != "sim":
            raise SerialException(f"expected a sim:// URL, got {url!r}")
        target = parse_device_url(url)  # InvalidDeviceURL (a ValueError) names the problem
        assert isinstance(target, SimURL)
        return dict(target.options)

    def close(self) -> None:
        """Disconnect from the simulated analyser (idempotent)."""
        if self.is_open:
            self.is_open = False
            self._firmware = None
            self._rx = bytearray()
        super().close()

    def _reconfigure_port(self) -> None:
        """Line settings mean nothing to an in-process simulator."""

    # -- data --------------------------------------------------------------------------------
    @property
    def firmware(self) -> Any:
        """The simulated analyser behind this port (None when closed)."""
        return self._firmware

    def _pull(self, want: int) -> None:
        """Move pending firmware output into the receive buffer (up to ``want`` more bytes)."""
        while len(self._rx) < want:
            chunk = self._firmware.read(max(want - len(self._rx), _CHUNK) if want > 0 else _CHUNK)
            if not chunk:
                return
            self._rx += chunk

    @property
    def in_waiting(self) -> int:
        """Bytes the simulated analyser has ready to be read."""
        if not self.is_open:
            raise PortNotOpenError()
        pending = getattr(self._firmware, "pending", None)
        if callable(pending):
            return len(self._rx) + int(pending())
        self._pull(len(self._rx) + _CHUNK)
        return len(self._rx)

    def read(self, size: int = 1) -> bytes:
        """Read ``size`` bytes, fewer if ``timeout`` (s) expires first (pyserial semantics)."""
        if not self.is_open:
            raise PortNotOpenError()
        if size <= 0:
            return b""
        if len(self._rx) < size:
            self._pull(size)
        if len(self._rx) < size and self._timeout != 0:
            deadline = None if self._timeout is None else time.monotonic() + self._timeout
            pause = _POLL_MIN_S
            while len(self._rx) < size:
                if deadline is not None:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        break
                    time.sleep(min(pause, left))
                else:
                    time.sleep(pause)
                pause = min(2 * pause, _POLL_MAX_S)
                if not self.is_open:
                    raise PortNotOpenError()
                self._pull(size)
        n = min(size, len(self._rx))
        if n == len(self._rx):
            data = bytes(self._rx)
            self._rx = bytearray()
        else:
            data = bytes(self._rx[:n])
            del self._rx[:n]
        return data

    def write(self, data: Any) -> int:
        """Hand ``data`` to the simulated analyser; returns the byte count."""
        if not self.is_open:
            raise PortNotOpenError()
        payload = to_bytes(data)
        try:
            self._firmware.write(payload)
        except TimeoutError as exc:  # a firmware that refuses input behaves like a full line
            raise SerialTimeoutException(f"Write timeout: {exc}") from exc
        return len(payload)

    def flush(self) -> None:
        """Nothing is buffered on the way out (also called by ``close``)."""

    def reset_input_buffer(self) -> None:
        """Discard everything the analyser has sent and not yet been read."""
        if not self.is_open:
            raise PortNotOpenError()
        self._rx = bytearray()
        while self._firmware.read(_CHUNK):
            pass

    def reset_output_buffer(self) -> None:
        """Nothing is buffered on the way out."""
        if not self.is_open:
            raise PortNotOpenError()

    @property
    def out_waiting(self) -> int:
        """Always 0: writes reach the firmware at once."""
        if not self.is_open:
            raise PortNotOpenError()
        return 0

    def cancel_read(self) -> None:
        """Not supported by the in-process simulator (reads are bounded by ``timeout``)."""

    def cancel_write(self) -> None:
        """Writes never block."""

    # modem lines: a three-wire cable with everything looped back as "ready"
    def _update_break_state(self) -> None:
        if not self.is_open:
            raise PortNotOpenError()

    def _update_rts_state(self) -> None:
        """RTS is not wired."""

    def _update_dtr_state(self) -> None:
        """DTR is not wired."""

    @property
    def cts(self) -> bool:
        if not self.is_open:
            raise PortNotOpenError()
        return True

    @property
    def dsr(self) -> bool:
        if not self.is_open:
            raise PortNotOpenError()
        return True

    @property
    def ri(self) -> bool:
        if not self.is_open:
            raise PortNotOpenError()
        return False

    @property
    def cd(self) -> bool:
        if not self.is_open:
            raise PortNotOpenError()
        return True
