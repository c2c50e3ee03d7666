"""The analyser driver: operator-level calls over the bulk-only protocol.

``Analyser(url_or_transport)`` opens a device URL (``acquisition.urls.open_transport``) or wraps
a ready :class:`~acquisition.transport.Transport` (dependency injection: tests pass a loopback
or a scripted transport). Calls map onto commands of ``acquisition.protocol``:

==========================  =====================================================
``identify()``              INQUIRY (standard data) + INQUIRY VPD page 0x80 (serial)
``capabilities()``          GET CAPABILITIES (cached)
``configure(setup)``        validate against capabilities, SET UP, GET SET-UP read-back
``arm()``                   ARM
``status()``                GET STATUS
``wait_for_trigger(t)``     GET STATUS polls until BLOCK READY (bounded sleeps)
``read_block()``            READ BLOCK in chunks of at most ``max_transfer`` bytes
``abort()``                 ABORT
==========================  =====================================================

Engineering units: ``data = counts * volts_per_count / sensitivity`` with the sensitivity in
V/N (force) or V/(m/s^2) (acceleration; mV/g * 1e-3 / 9.80665).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from acquisition import protocol as P
from acquisition.bot import BulkOnly
from acquisition.errors import CommandFailed, ProtocolError, TriggerTimeout
from acquisition.setup import AcquisitionSetup, Capabilities, setup_from_wire, setup_to_wire, validate_setup
from acquisition.transport import Transport

__all__ = ["Analyser", "Identity", "Block"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Identity:
    """Who the analyser is: INQUIRY vendor/product/revision, VPD serial number, the URL."""

    vendor: str
    product: str
    revision: str
    serial: str
    url: str = ""
    protocol_version: int = P.PROTOCOL_VERSION

    def as_dict(self) -> dict[str, Any]:
        return {"vendor": self.vendor, "model": self.product, "firmware": self.revision, "serial": self.serial,
                "url": self.url, "protocol_version": self.protocol_version}

    def __str__(self) -> str:
        return f"{self.vendor} {self.product} rev {self.revision} serial {self.serial}"


@dataclass(frozen=True)
class Block:
    """One triggered block.

    ``data[n_ch, n]`` float in engineering units (N, m/s^2); ``counts[n_ch, n]`` int16 ADC counts;
    ``volts_per_count[n_ch]`` V; ``overload[n_ch]`` bool; ``trigger_index``: sample of the trigger
    crossing (= the pre-trigger); ``sample_rate_hz``; ``sequence``: the analyser's block number;
    ``timestamp``: host time of arrival (s since the epoch); ``device_time_s``: analyser clock at
    the first sample; ``channels``, ``units``: names and units of the rows.
    """

    data: np.ndarray
    counts: np.ndarray
    volts_per_count: np.ndarray
    overload: np.ndarray
    trigger_index: int
    sample_rate_hz: float
    sequence: int
    timestamp: float
    device_time_s: float = 0.0
    channels: tuple[str, ...] = ()
    units: tuple[str, ...] = ()


class Analyser:
    """A SigLab-like analyser reached through ``url_or_transport``.

    ``timeout_s`` bounds each command; ``poll_interval_s`` is the longest sleep between status
    polls in :meth:`wait_for_trigger`. Use as a context manager or call :meth:`close`.

    Examples
    --------
    The simulated analyser (``usb://1209:0001`` or ``socket://HOST:PORT`` for another door):

    >>> from acquisition import Analyser
    >>> with Analyser("sim://?seed=1") as analyser:
    ...     print(analyser.identify())
    ...     caps = analyser.capabilities()
    IMPACTLB SIGLAB-SIM 2042 rev 0100 serial SL2042-0000001
    >>> caps.n_inputs, max(caps.sample_rates_hz), caps.adc_bits       # channels, Hz, bits
    (4, 51200.0, 16)
    """

    def __init__(self, url_or_transport: str | Transport, timeout_s: float = 2.0,
                 poll_interval_s: float = 0.005) -> None:
        if not (timeout_s > 0 and poll_interval_s > 0):
            raise ValueError(f"timeout_s ({timeout_s}) and poll_interval_s ({poll_interval_s}) must be positive seconds")
        if isinstance(url_or_transport, str):
            from acquisition.urls import open_transport  # lazy: the transport layer is optional here
            self.transport = open_transport(url_or_transport)
        elif isinstance(url_or_transport, Transport):
            self.transport = url_or_transport
        else:
            raise TypeError(f"Analyser needs a device URL or a Transport, got {type(url_or_transport).__name__}")
        self.bot = BulkOnly(self.transport, timeout_s)
        self.timeout_s = float(timeout_s)
        self.poll_interval_s = float(poll_interval_s)
        self._caps: Capabilities | None = None
        self._setup: AcquisitionSetup | None = None
        self._last_status: P.StatusData | None = None
        self._closed = False

    @property
    def url(self) -> str:
        return getattr(self.transport, "url", "")

    @property
    def setup(self) -> AcquisitionSetup | None:
        """The set-up last written by :meth:`configure` (or read back from the analyser)."""
        return self._setup

    # ------------------------------------------------------------------ identity and capabilities
    def identify(self) -> Identity:
        """INQUIRY + serial number (VPD page 0x80)."""
        inq = P.decode_inquiry(self.bot.command(P.Op.INQUIRY, length=P.INQUIRY.size).data)
        vpd = self.bot.command(P.Op.INQUIRY, length=64, evpd=1, page=P.VPD_SERIAL_NUMBER).data
        return Identity(inq.vendor, inq.product, inq.revision, P.decode_serial_vpd(vpd), self.url)

    def test_unit_ready(self) -> None:
        """TEST UNIT READY (raises CommandFailed when not ready)."""
        self.bot.command(P.Op.TEST_UNIT_READY)

    def capabilities(self) -> Capabilities:
        """GET CAPABILITIES (asked once per connection)."""
        if self._caps is None:
            head = self.bot.command(P.Op.GET_CAPABILITIES, length=P.CAPS_HEADER.size).data
            _, _, n_r, n_g, n_b, *_ = P.CAPS_HEADER.unpack(head[:P.CAPS_HEADER.size].ljust(P.CAPS_HEADER.size, b"\0"))
            size = P.CAPS_HEADER.size + 4 * (n_r + n_g + n_b)
            raw = self.bot.command(P.Op.GET_CAPABILITIES, length=size).data
            self._caps = Capabilities.from_wire(P.decode_capabilities(raw))
        return self._caps

    # ------------------------------------------------------------------ set-up and capture
    def configure(self, setup: AcquisitionSetup) -> None:
        """Validate ``setup`` against the capabilities (SetupError before anything is written), send
        it, and read it back (ProtocolError if the analyser holds something else)."""
        validate_setup(setup, self.capabilities())
        raw = P.encode_setup(setup_to_wire(setup))
        self.bot.command(P.Op.SET_UP, data_out=raw)
        back = self.bot.command(P.Op.GET_SET_UP, length=len(raw)).data
        if back != raw:
            raise ProtocolError(f"{self.url}: the set-up read back differs from the one written; configure again")
        self._setup = setup
        self._last_status = None

    def read_setup(self) -> AcquisitionSetup:
        """GET SET-UP: the set-up the analyser holds (channel names are not stored on the device)."""
        head = self.bot.command(P.Op.GET_SET_UP, length=P.SETUP_HEADER.size).data
        n = head[1] if len(head) > 1 else 0
        raw = self.bot.command(P.Op.GET_SET_UP, length=P.setup_size(n)).data
        wire = P.decode_setup(raw)
        names = [c.name for c in self._setup.channels] if (
            self._setup is not None and len(self._setup.channels) == len(wire.channels)) else None
        return setup_from_wire(wire, names)

    def arm(self) -> None:
        """ARM: wait for the trigger (the simulated operator strikes while the host polls)."""
        self.bot.command(P.Op.ARM)
        self._last_status = None

    def status(self) -> P.StatusData:
        """GET STATUS."""
        st = P.decode_status(self.bot.command(P.Op.GET_STATUS, length=P.STATUS.size).data)
        self._last_status = st
        return st

    def wait_for_trigger(self, timeout_s: float) -> P.StatusData:
        """Poll GET STATUS until a block is ready; TriggerTimeout after ``timeout_s`` seconds.

        Sleeps between polls grow from 1 ms to ``poll_interval_s`` and never pass the deadline.
        Raises CommandFailed when the analyser is idle (not armed, aborted or reset).
        """
        deadline = time.monotonic() + float(timeout_s)
        sleep = min(0.001, self.poll_interval_s)
        polls = 0
        while True:
            st = self.status()
            polls += 1
            if st.state == P.State.BLOCK_READY:
                return st
            if st.state == P.State.IDLE:
                raise CommandFailed(f"{self.url}: the analyser is idle, not armed (aborted or reset?); arm it "
                                    "again before waiting", opcode=P.Op.GET_STATUS)
            left = deadline - time.monotonic()
            if left <= 0:
                more = " (the last strike did not cross the trigger level)" if st.no_trigger else ""
                raise TriggerTimeout(f"{self.url}: no trigger within {timeout_s:g} s after {polls} polls{more}; "
                                     "hit the structure, or lower the trigger level / check the trigger channel")
            time.sleep(min(sleep, left))
            sleep = min(sleep * 2, self.poll_interval_s)

    def read_block(self) -> Block:
        """READ BLOCK (all chunks) of the ready block, scaled to engineering units."""
        setup = self._setup if self._setup is not None else self.read_setup()
        st = self._last_status
        if st is None or st.state != P.State.BLOCK_READY:
            st = self.status()
        if st.state != P.State.BLOCK_READY:
            raise CommandFailed(f"{self.url}: no block is ready (state {st.state.name}); arm and wait for the "
                                "trigger first", opcode=P.Op.READ_BLOCK, sense_key=P.SenseKey.NOT_READY,
                                asc=P.ASC_NOT_READY_NO_BLOCK[0], ascq=P.ASC_NOT_READY_NO_BLOCK[1])
        n_ch = len(setup.channels)
        size = P.block_image_size(n_ch, setup.block_size)
        step = max(1, min(self.capabilities().max_transfer, P.MAX_TRANSFER))
        image = bytearray(size)
        view = memoryview(image)
        offset = 0
        while offset < size:  # bounded: every pass advances by >= 1 byte or raises
            count = min(step, size - offset)
            got = self.bot.command(P.Op.READ_BLOCK, length=count, sequence=st.sequence, offset=offset,
                                   count=count).data
            if not got:
                raise ProtocolError(f"{self.url}: READ BLOCK at offset {offset} returned no data; repeat the capture")
            view[offset:offset + len(got)] = got
            offset += len(got)
        header, vpc, counts = P.decode_block_image(bytes(image))
        if header.n_channels != n_ch or header.n_samples != setup.block_size or header.sequence != st.sequence:
            raise ProtocolError(f"{self.url}: block header ({header.n_channels} ch x {header.n_samples}, sequence "
                                f"{header.sequence}) does not match the set-up ({n_ch} x {setup.block_size}, "
                                f"sequence {st.sequence}); configure again")
        vpu = np.array([ch.volts_per_unit for ch in setup.channels], dtype=float)
        data = counts.astype(float) * (vpc / vpu)[:, None]
        overload = np.array([bool(header.overload_mask >> i & 1) for i in range(n_ch)], dtype=bool)
        return Block(data, counts, vpc, overload, header.trigger_index, header.sample_rate_hz, header.sequence,
                     time.time(), header.timestamp_s, tuple(ch.name for ch in setup.channels),
                     tuple(ch.unit for ch in setup.channels))

    def capture(self, timeout_s: float = 5.0) -> Block:
        """ARM, wait for the trigger (at most ``timeout_s``), read the block."""
        self.arm()
        self.wait_for_trigger(timeout_s)
        return self.read_block()

    def abort(self) -> None:
        """ABORT an armed capture (harmless when idle)."""
        self.bot.command(P.Op.ABORT)
        self._last_status = None

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        """Release the transport (also an injected one: the analyser owns its link). Idempotent."""
        if not self._closed:
            self._closed = True
            self.transport.close()

    def __enter__(self) -> Analyser:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
