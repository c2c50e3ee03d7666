"""The simulated analyser's firmware: a byte-level state machine (bytes in, bytes out).

Built from three parts, each testable alone: :mod:`simulator.link` (the bulk-only link state
machine: CBW / data / CSW framing, stalls, resets), :mod:`simulator.commands` (the SCSI command
handlers) and :mod:`simulator.capture` (arming, the strike, the ADC, the trigger search, the
block). :func:`simulator.analyser.create_analyser` builds one from URL options.

The host writes bulk-only command block wrappers (CBW), optional data-out, and reads data-in
and command status wrappers (CSW), all laid out by :mod:`acquisition.protocol`. Commands run
synchronously inside :meth:`Firmware.write`; their replies wait in an output queue that
:meth:`Firmware.read` drains.

Two link flavours
-----------------
* ``packetized=True`` (USB bulk endpoints): each ``write`` is one OUT transfer, each ``read``
  returns at most one IN transfer (a data phase or a CSW; never both), so a data phase shorter
  than the host asked for ends with a short packet. A command that fails while the host expects
  data-in stalls the IN endpoint (the CSW follows after ``clear_halt(True)``); an invalid CBW
  stalls both endpoints until :meth:`bulk_only_reset` (then the host clears both halts).
  The transport checks :attr:`halted_in` / :attr:`halted_out` before each transfer (a halted
  endpoint answers STALL): ``read`` returns ``b""`` and ``write`` drops data while halted.
* ``packetized=False`` (serial, TCP, pty): the firmware always sends exactly the host's
  announced data-in length (zero padded) and reports the residue in the CSW. An invalid CBW makes
  the firmware discard all input until :data:`acquisition.protocol.STREAM_RESET` arrives; that
  frame is recognised anywhere in the input and acts as the bulk-only mass storage reset.

Bulk-only cases (host expectation H vs device intent D, USB MSC BOT 1.0 section 6.7):
Hn with Di/Do -> phase error (2); Hi with Do, Ho with Di -> phase error; Hi < Di -> the first
Hi bytes, then phase error; Ho < Do -> phase error (command not executed); Hi > Di, Ho > Do ->
residue H - D.

SCSI behaviour
--------------
Sense data of the last command is kept for REQUEST SENSE (a passing command clears it). After
power-on and after every reset a UNIT ATTENTION (0x06, ASC 0x29) is pending: the next command
other than INQUIRY and REQUEST SENSE fails with it (and is not executed); REQUEST SENSE reports
and clears it. Unsupported opcode -> ILLEGAL REQUEST/0x20; a CDB field out of range ->
ILLEGAL REQUEST/0x24; a set-up outside the capabilities -> ILLEGAL REQUEST/0x26 (0x1A for a bad
length, or a channel point the test stand refuses); LUN other than 0 -> ILLEGAL REQUEST/0x25;
ARM or GET SET-UP before SET UP -> NOT READY/0x04/0x80; READ BLOCK with no block ready ->
NOT READY/0x04/0x81; SET UP while armed -> NOT READY/0x04/0x82; a stand that fails to strike (or
no stand) -> HARDWARE ERROR/0x44. A reset abandons an armed capture but keeps the set-up and a
ready block, so an idempotent READ BLOCK can be repeated after reset recovery.

Capture
-------
ARM moves to ``ARMED``. The simulated operator strikes the frame when the host polls: GET STATUS
number ``strike_after_polls + 1`` after ARM (default 1, so one poll sees "armed"; 0 strikes at
ARM) calls ``stand.strike(fs, n + margin, pretrigger)``, filters every channel with the
front end's anti-alias filter, digitises it (``simulator.frontend.quantize``), searches the
trigger channel for the first crossing of the trigger level with the set slope at or after
sample ``pretrigger``, and keeps ``n`` samples starting ``pretrigger`` samples before the
crossing. A strike whose record never crosses the level leaves the state ``ARMED`` with the
``no trigger`` flag; the operator strikes again after as many polls, at most
``max_strikes`` times per ARM (then the host's wait times out). The ``TRIGGERED`` state is never
observed: a simulated capture is instantaneous.

SET UP hands the stand its channels (:class:`StandChannel` dicts: point, quantity, sensitivity in
V per SI unit with unit ``"V/EU"``, IEPE, coupling, range) and aims the operator's hammer at the
force channel's point (``stand.set_hammer_point``), so a roving-hammer test moves the hammer by
changing the set-up. The stand models everything up to the analyser's anti-alias filter (sensors,
IEPE, input AC coupling).

Speed: block images are built once per strike with ``numpy.tobytes`` and served as
``memoryview`` slices (no per-byte Python work); a stand whose event carries
``info["cache_key"]`` (:class:`PrecomputedStand`) has its digitised block reused.
"""

from __future__ import annotations

from acquisition import protocol as P
from simulator.capture import PrecomputedStand, StandChannel, StandLike
from simulator.commands import DEFAULT_SERIAL, IDENTITY, ScsiCommands
from simulator.link import BulkOnlyLink, Reply

__all__ = ["Firmware", "Reply", "StandLike", "StandChannel", "PrecomputedStand", "IDENTITY", "DEFAULT_SERIAL"]


class Firmware(ScsiCommands, BulkOnlyLink):
    """The analyser's firmware (see the module docstring for the behaviour).

    ``stand``: the simulated operator + frame (``set_channels``, ``strike``); ``packetized``: USB
    bulk behaviour (True) or byte stream (False); ``strike_after_polls``: GET STATUS polls
    answered "armed" before the operator strikes; ``max_strikes``: strikes per ARM when the
    trigger level is never crossed; ``margin``: extra samples requested from the stand beyond the
    block (room for the trigger to land late).
    """

    def __init__(self, stand: StandLike | None = None, *, packetized: bool = False,
                 serial: str = DEFAULT_SERIAL, capabilities: P.CapabilitiesData = P.SIGLAB_2042,
                 strike_after_polls: int = 1, max_strikes: int = 3, margin: int = 1024,
                 identity: P.Inquiry = IDENTITY) -> None:
        if strike_after_polls < 0 or max_strikes < 1 or margin < 0:
            raise ValueError("strike_after_polls and margin must be >= 0 and max_strikes >= 1")
        self.stand = stand
        self.packetized = bool(packetized)
        self.serial = serial
        self.capabilities = capabilities
        self.identity = identity
        self.strike_after_polls = int(strike_after_polls)
        self.max_strikes = int(max_strikes)
        self.margin = int(margin)
        self._caps_bytes = P.encode_capabilities(capabilities)
        self._inquiry_bytes = P.encode_inquiry(identity)
        self._handlers = self._command_table()
        # acquisition state (survives a bulk-only reset, except an armed capture)
        self._init_capture()
        # counters for tests and benchmarks
        self.commands_executed = 0
        self.resets = 0
        self._power_on()

    @property
    def state(self) -> P.State:
        """The acquisition state (for tests and servers)."""
        return self._state

    def _on_reset(self) -> None:
        """A bulk-only reset abandons an armed capture (the set-up and a ready block stay)."""
        if self._state == P.State.ARMED:
            self._state = P.State.IDLE
