"""impactlab.acquisition: the analyser driver (USB bulk-only or byte streams), transports, device
URLs, acquisition set-ups and capture sessions with hit accept/reject.

Imports :mod:`analysis` (containers, recording format), never :mod:`simulator`: the simulated
doors (``sim://``, ``usbsim://``) arrive through the ``impactlab.doors`` entry points.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from analysis._lazy import lazy_exports

#: public name -> the module that defines it (imported on first use)
_EXPORTS = {
    "Analyser": ".driver",
    "Identity": ".driver",
    "Block": ".driver",
    "AcquisitionSetup": ".setup",
    "ChannelSetup": ".setup",
    "TriggerSetup": ".setup",
    "default_setup": ".setup",
    "load_setup": ".setup",
    "CaptureSession": ".session",
    "SessionResult": ".session",
    "TestPlan": ".plan",
    "HitSummary": ".operator",
    "Operator": ".operator",
    "auto_accept": ".operator",
    "parse_device_url": ".urls",
    "open_transport": ".urls",
    "list_devices": ".discovery",
    "ImpactlabError": ".errors",
    "TransportError": ".errors",
    "TransportTimeout": ".errors",
    "ProtocolError": ".errors",
    "CommandFailed": ".errors",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

if TYPE_CHECKING:  # for type checkers and IDEs; at run time the names load lazily
    from .discovery import list_devices  # noqa: F401
    from .driver import Analyser, Block, Identity  # noqa: F401
    from .errors import CommandFailed, ImpactlabError, ProtocolError, TransportError, TransportTimeout  # noqa: F401
    from .operator import HitSummary, Operator, auto_accept  # noqa: F401
    from .plan import TestPlan  # noqa: F401
    from .session import CaptureSession, SessionResult  # noqa: F401
    from .setup import AcquisitionSetup, ChannelSetup, TriggerSetup, default_setup, load_setup  # noqa: F401
    from .urls import open_transport, parse_device_url  # noqa: F401
