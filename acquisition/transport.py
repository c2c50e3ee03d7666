"""The transport interface: a byte link to the analyser, below the bulk-only envelope.

The driver (``acquisition.bot`` / ``acquisition.driver``) speaks the bulk-only protocol:
command block wrapper (31 bytes), optional data phase, command status wrapper (13 bytes).
A transport only moves bytes, bounds every wait, and performs reset recovery.

Two families implement it:

* packetised (USB bulk endpoints through pyusb): ``read(n)`` returns one transfer of
  1..n bytes; a short packet ends a data phase early; endpoints may stall.
* stream (pyserial: serial port, ``socket://``, ``sim://``, pty): ``read(n)`` returns
  exactly n bytes or raises; a device always sends the full announced data length
  (padded) and reports the residue in the status. Reset recovery over a stream is the
  in-band reset frame ``protocol.STREAM_RESET`` followed by a drain of stale bytes.
"""
from __future__ import annotations

import abc

__all__ = ["Transport"]


class Transport(abc.ABC):
    """A bounded, bidirectional byte link to one analyser."""

    #: the URL that opened this transport (for messages)
    url: str = ""
    #: True for USB-style packet transfers (short packets, stalls), False for byte streams
    packetized: bool = False

    @abc.abstractmethod
    def write(self, data: bytes, timeout_s: float) -> None:
        """Send all of ``data`` or raise TransportTimeout / DeviceGone / EndpointStalled."""

    @abc.abstractmethod
    def read(self, n: int, timeout_s: float) -> bytes:
        """Receive up to ``n`` bytes (see module docstring) or raise TransportTimeout / DeviceGone / EndpointStalled."""

    @abc.abstractmethod
    def reset_recovery(self, timeout_s: float = 1.0) -> None:
        """Bulk-only reset recovery: the device abandons any command and both directions are clear."""

    def clear_halt(self, direction_in: bool) -> None:  # noqa: B027  (optional hook)  # pragma: no cover
        """Clear a stalled endpoint (USB only; a no-op on streams)."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the link. Idempotent."""

    def __enter__(self) -> Transport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
