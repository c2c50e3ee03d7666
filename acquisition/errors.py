"""Exceptions of the acquisition layer (device, link, set-up). Each subclasses the impactlab root
:class:`analysis.errors.ImpactlabError` and a built-in so callers may catch broadly.

Every message names the problem and what to do about it.
"""
from __future__ import annotations

from analysis.errors import ImpactlabError, RecordingError, UsageError

__all__ = [
    "ImpactlabError",
    "InvalidDeviceURL",
    "TransportError",
    "TransportTimeout",
    "TriggerTimeout",
    "DeviceGone",
    "EndpointStalled",
    "ProtocolError",
    "CommandFailed",
    "SetupError",
    "RecordingError",
    "UsageError", "ImportDataError", "NonFiniteSamples"]


class InvalidDeviceURL(ImpactlabError, ValueError):
    """A device URL that no door understands; the message shows the accepted syntax."""


class SetupError(ImpactlabError, ValueError):
    """A set-up value outside the analyser's capabilities (checked before anything is written)."""


class TransportError(ImpactlabError, OSError):
    """The byte link failed."""


class TransportTimeout(TransportError, TimeoutError):
    """A read or write did not complete within its bound."""


class TriggerTimeout(TransportTimeout):
    """The armed analyser saw no trigger within the wait (the link itself is fine)."""


class DeviceGone(TransportError, ConnectionError):
    """The device disconnected or the link closed."""


class EndpointStalled(TransportError):
    """A USB bulk endpoint answered STALL (the host must clear the halt)."""


class ProtocolError(ImpactlabError, OSError):
    """The device broke the bulk-only envelope: bad signature, wrong tag, phase error, bad length."""


class CommandFailed(ImpactlabError, OSError):
    """A command ended with CHECK CONDITION; carries the sense data the device reported."""

    def __init__(self, message: str, *, opcode: int = -1, sense_key: int = 0, asc: int = 0, ascq: int = 0):
        super().__init__(message)
        self.opcode = opcode
        self.sense_key = sense_key
        self.asc = asc
        self.ascq = ascq


class ImportDataError(ImpactlabError, ValueError):
    """Input data that cannot be imported; the message names the problem and the fix."""


class NonFiniteSamples(ImportDataError):
    """Time data holding NaN or infinite samples; ``test`` is what was read (the importer's
    ``drop_nonfinite_hits`` can leave those hits out)."""

    def __init__(self, message: str, test: object) -> None:
        super().__init__(message)
        self.test = test
