"""A :class:`~acquisition.transport.Transport` over any pyserial port (stream semantics).

Serial ports, pseudo-terminals, ``socket://`` and ``sim://`` all look alike here: an ordered
byte stream without packet boundaries or stalls. ``read(n)`` therefore returns exactly ``n``
bytes or raises; a device always sends the full announced data length.

Error mapping: a read or write that does not complete within its bound raises
:class:`TransportTimeout` (its ``received`` attribute tells how many bytes had arrived, and those
bytes are discarded: the stream is out of step and the caller must do reset recovery); a closed
port, a dropped TCP connection or a vanished tty raises :class:`DeviceGone`.

Reset recovery sends the in-band frame ``acquisition.protocol.STREAM_RESET`` and then drains
stale input until the line has been quiet for ``quiet_s`` (bounded by the caller's timeout).
"""
from __future__ import annotations

import logging
import time
from typing import Any

from acquisition.errors import DeviceGone, TransportTimeout
from acquisition.transport import Transport

__all__ = ["StreamTransport"]

_log = logging.getLogger(__name__)

#: a drain stops once nothing arrived for this long (s)
DEFAULT_QUIET_S = 0.05
#: longest single wait inside a read; the read loops until its own deadline (s)
DEFAULT_POLL_S = 0.1


class StreamTransport(Transport):
    """Bulk-only byte link over a pyserial port object (``serial.Serial``, ``serial_for_url(...)``).

    The transport owns ``port`` and closes it in :meth:`close`. Timeouts are in seconds;
    ``quiet_s``: silence that ends the reset-recovery drain; ``poll_s``: longest single wait of
    the port inside a read (the read loops until its own deadline).
    """

    packetized = False

    def __init__(self, port: Any, url: str = "", *, quiet_s: float = DEFAULT_QUIET_S,
                 poll_s: float = DEFAULT_POLL_S) -> None:
        if not hasattr(port, "read") or not hasattr(port, "write"):
            raise TypeError(f"StreamTransport needs a pyserial port object, got {type(port).__name__}")
        self._port = port
        self.url = url or str(getattr(port, "portstr", "") or "")
        self.quiet_s = float(quiet_s)
        self.poll_s = float(poll_s)
        self._read_timeout: float | None = None
        self._write_timeout: float | None = None
        self._closed = False

    @property
    def port(self) -> Any:
        """The underlying pyserial object."""
        return self._port

    # -- helpers -----------------------------------------------------------------------------
    def _gone(self, what: str, exc: BaseException | None = None) -> DeviceGone:
        detail = f": {exc}" if exc is not None else ""
        return DeviceGone(
            f"{what} on {self.url or 'the stream'} failed, the link is closed or the device went away{detail}; "
            "check the cable / server and reopen the device URL"
        )

    def _check_open(self, what: str) -> None:
        if self._closed or not getattr(self._port, "is_open", True):
            raise DeviceGone(f"{what} on {self.url or 'the stream'}: the transport is closed; reopen the device URL")

    def _set_read_timeout(self, timeout_s: float) -> None:
        # setting a timeout reconfigures a real tty (tcsetattr): only when it changes
        if timeout_s != self._read_timeout:
            self._port.timeout = timeout_s
            self._read_timeout = timeout_s

    def _set_write_timeout(self, timeout_s: float) -> None:
        if timeout_s != self._write_timeout:
            self._port.write_timeout = timeout_s
            self._write_timeout = timeout_s

    @staticmethod
    def _check_timeout(timeout_s: float) -> float:
        t = float(timeout_s)
        if not t > 0:
            raise ValueError(f"timeout_s must be a positive number of seconds, got {timeout_s!r}")
        return t

    # -- Transport ---------------------------------------------------------------------------
    def write(self, data: bytes, timeout_s: float) -> None:
        """Send all of ``data`` within ``timeout_s`` seconds."""
        import serial

        timeout_s = self._check_timeout(timeout_s)
        self._check_open("write")
        try:
            self._set_write_timeout(timeout_s)  # reconfigures a tty: fails too when it vanished
            n = self._port.write(data)
        except serial.SerialTimeoutException as exc:
            raise TransportTimeout(
                f"write of {len(data)} bytes to {self.url} did not complete within {timeout_s:g} s; "
                "the device is not reading: check it is powered and responsive, then reset"
            ) from exc
        except (serial.SerialException, OSError, ValueError) as exc:  # ValueError: closed file
            raise self._gone("write", exc) from exc
        if n is not None and n != len(data):
            raise TransportTimeout(f"only {n} of {len(data)} bytes were written to {self.url} within {timeout_s:g} s")

    def read(self, n: int, timeout_s: float) -> bytes:
        """Receive exactly ``n`` bytes within ``timeout_s`` seconds, else TransportTimeout."""
        import serial

        if n <= 0:
            raise ValueError(f"read size must be a positive byte count, got {n!r}")
        timeout_s = self._check_timeout(timeout_s)
        self._check_open("read")
        deadline = time.monotonic() + timeout_s
        quantum = min(self.poll_s, timeout_s)
        parts = []
        got = 0
        try:
            while got < n:
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                # a constant port timeout (the quantum) spares a tty reconfiguration per read
                self._set_read_timeout(quantum if left >= quantum else left)
                chunk = self._port.read(n - got)
                if chunk:
                    parts.append(chunk)
                    got += len(chunk)
            data = parts[0] if len(parts) == 1 else b"".join(parts)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise self._gone("read", exc) from exc
        if len(data) < n:
            short = TransportTimeout(
                f"read from {self.url}: {len(data)} of {n} bytes arrived within {timeout_s:g} s; "
                "the device is silent or out of step: do reset recovery (or check it is running)"
            )
            short.received = len(data)  # type: ignore[attr-defined]
            raise short
        return data

    def reset_recovery(self, timeout_s: float = 1.0) -> None:
        """Send ``STREAM_RESET`` and drain stale input until quiet (bounded by ``timeout_s``)."""
        import serial

        from acquisition.protocol import STREAM_RESET

        timeout_s = self._check_timeout(timeout_s)
        self._check_open("reset recovery")
        deadline = time.monotonic() + timeout_s
        self.write(STREAM_RESET, timeout_s)
        drained = 0
        quiet = min(self.quiet_s, timeout_s)
        try:
            while True:
                left = deadline - time.monotonic()
                if left <= 0:
                    _log.warning("%s: input still arriving when the reset drain bound of %g s ran out", self.url, timeout_s)
                    break
                self._set_read_timeout(min(quiet, left))
                waiting = getattr(self._port, "in_waiting", 0) or 0
                chunk = self._port.read(max(int(waiting), 4096))
                if not chunk:
                    break
                drained += len(chunk)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise self._gone("reset recovery", exc) from exc
        _log.debug("%s: reset recovery drained %d stale bytes", self.url, drained)

    def close(self) -> None:
        """Close the port (idempotent)."""
        if self._closed:
            return
        self._closed = True
        # pyserial's socket:// skips socket.close() when shutdown() fails on a dead connection
        sock = getattr(self._port, "_socket", None)
        try:
            self._port.close()
        except (OSError, ValueError) as exc:  # closing a vanished device
            _log.debug("%s: close: %s", self.url, exc)
        finally:
            if sock is not None and hasattr(sock, "close"):
                sock.close()

    def __repr__(self) -> str:
        return f"StreamTransport({self.url!r})"
