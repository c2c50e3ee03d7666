"""Every wire format of the analyser link, in one package: the single source of truth for bytes.

Parts: :mod:`.envelope` (CBW/CSW, stream reset), :mod:`.sense` (sense data and codes),
:mod:`.payloads` (INQUIRY, capabilities, set-up, status, block image), :mod:`.commands` (CDBs and
the command table). ``from acquisition import protocol as P`` gives all of them.

Layers
------
1. **Bulk-only envelope** (USB Mass Storage Bulk-Only Transport framing, little-endian):
   command block wrapper ``CBW`` (31 bytes, ``<IIIBBB16s``: signature ``USBC``, tag, data
   transfer length, flags (bit 7 = data in), LUN, CDB length, CDB) and command status wrapper
   ``CSW`` (13 bytes, ``<IIIB``: signature ``USBS``, tag, residue, status 0/1/2).
2. **SCSI command descriptor blocks** (big-endian, as in SPC): TEST UNIT READY 0x00,
   REQUEST SENSE 0x03, INQUIRY 0x12, and the analyser's vendor commands 0xC0..0xC6.
3. **Data-phase payloads** (little-endian, as a USB device lays out its memory): sense data
   (18-byte fixed format, big-endian per SPC), INQUIRY data (36 bytes), capabilities,
   set-up, status, and the block image (header + per-channel volts/count + int16 counts).
   Every analyser payload starts with a version byte equal to :data:`PROTOCOL_VERSION`.

Vendor CDBs (10 bytes, ``>BBH5xB``: opcode, protocol version, parameter/allocation length,
reserved, control) except READ BLOCK (16 bytes, ``>BBIII xB``: opcode, version, block sequence,
byte offset into the block image, byte count). A block image larger than
:data:`MAX_TRANSFER` bytes is read by several READ BLOCK commands with increasing offsets.

Commands (``COMMANDS`` is the table the host validates against and the firmware dispatches on):

======  ================  =====  ===========================================================
opcode  name              data   CDB fields (big-endian) -> data phase
======  ================  =====  ===========================================================
0x00    TEST UNIT READY   none   -
0x03    REQUEST SENSE     in     allocation length (<= 255) -> 18-byte fixed-format sense
0x12    INQUIRY           in     EVPD, page (0x00, 0x80), allocation length -> 36 bytes / VPD
0xC0    GET CAPABILITIES  in     version, allocation length -> capabilities
0xC1    SET UP            out    version, parameter list length <- set-up (header + records)
0xC2    GET SET-UP        in     version, allocation length -> the set-up as stored
0xC3    ARM               none   version
0xC4    GET STATUS        in     version, allocation length -> 16-byte status
0xC5    READ BLOCK        in     version, sequence, offset, count (<= MAX_TRANSFER) -> image bytes
0xC6    ABORT             none   version
======  ================  =====  ===========================================================

Sense codes the analyser reports: ILLEGAL REQUEST (5) with ASC 0x20 (unsupported opcode),
0x24 (invalid CDB field), 0x25 (LUN), 0x26 (set-up value outside the capabilities), 0x1A
(set-up length); NOT READY (2) with ASC 0x04 and ASCQ 0x80 (set-up required), 0x81 (no block),
0x82 (capture in progress); UNIT ATTENTION (6) 0x29 (power-on or reset); HARDWARE ERROR (4) 0x44.

Stream links (serial, TCP, pty) have no out-of-band reset: the host sends
:data:`STREAM_RESET` (31 bytes starting with ``b"USBR"``), which the firmware recognises
anywhere in its input and treats like the bulk-only mass storage reset.

All ``encode_*`` / ``decode_*`` functions are pure and raise
:class:`acquisition.errors.ProtocolError` (decoding) or :class:`ValueError`-derived
:class:`acquisition.errors.SetupError` (encoding a value that does not fit) with a message
naming the field and the allowed values.
"""
from __future__ import annotations

from acquisition.errors import ProtocolError, SetupError  # noqa: F401  (raised by every decoder)

from .commands import *  # noqa: F401,F403
from .commands import __all__ as _commands_all
from .envelope import *  # noqa: F401,F403
from .envelope import __all__ as _envelope_all
from .payloads import *  # noqa: F401,F403
from .payloads import __all__ as _payloads_all
from .sense import *  # noqa: F401,F403
from .sense import __all__ as _sense_all

#: every public name of the four parts (the API of ``from acquisition import protocol as P``)
__all__ = [*_envelope_all, *_sense_all, *_payloads_all, *_commands_all]
