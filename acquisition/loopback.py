"""A transport straight onto an in-process :class:`simulator.firmware.Firmware` (tests, cheapest door).

No threads and no waiting: the firmware runs each command inside ``write``, so when it has
nothing to send nothing ever will, and :meth:`LoopbackTransport.read` raises
:class:`~acquisition.errors.TransportTimeout` at once instead of sleeping.
"""
from __future__ import annotations

from typing import Any

from acquisition import protocol
from acquisition.errors import DeviceGone, EndpointStalled, TransportTimeout
from acquisition.transport import Transport

__all__ = ["LoopbackTransport"]


class LoopbackTransport(Transport):
    """``Transport`` over a firmware object; ``packetized`` follows the firmware's own mode."""

    def __init__(self, firmware: Any, url: str = "loopback://") -> None:
        self.firmware = firmware
        self.packetized = bool(getattr(firmware, "packetized", False))
        self.url = url
        self._closed = False

    def _check_open(self) -> None:
        if self._closed:
            raise DeviceGone(f"{self.url}: the loopback transport is closed; open a new one")

    def write(self, data: bytes, timeout_s: float) -> None:
        self._check_open()
        if self.packetized and self.firmware.halted_out:
            raise EndpointStalled(f"{self.url}: bulk OUT endpoint stalled; clear the halt (reset recovery)")
        self.firmware.write(bytes(data))

    def read(self, n: int, timeout_s: float) -> bytes:
        """Packetized: one transfer of 1..n bytes. Stream: exactly n bytes (or TransportTimeout)."""
        self._check_open()
        if self.packetized:
            if self.firmware.halted_in:
                raise EndpointStalled(f"{self.url}: bulk IN endpoint stalled; clear the halt, then read the status")
            data = self.firmware.read(n)
            if not data:
                raise TransportTimeout(f"{self.url}: the device has nothing to send (asked {n} bytes)")
            return data
        data = self.firmware.read(n)
        if len(data) < n:
            raise TransportTimeout(f"{self.url}: the device sent {len(data)} of {n} bytes and has nothing more; "
                                   "the link is out of step (reset recovery needed)")
        return data

    def reset_recovery(self, timeout_s: float = 1.0) -> None:
        """Packetized: class reset + clear both halts. Stream: the in-band reset frame + drain."""
        self._check_open()
        if self.packetized:
            self.firmware.bulk_only_reset()
            self.firmware.clear_halt(True)
            self.firmware.clear_halt(False)
        else:
            self.firmware.write(protocol.STREAM_RESET)
            while self.firmware.read(1 << 20):
                pass

    def clear_halt(self, direction_in: bool) -> None:
        self._check_open()
        self.firmware.clear_halt(direction_in)

    def close(self) -> None:
        self._closed = True
