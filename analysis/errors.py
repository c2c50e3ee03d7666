"""The impactlab error root and the errors of the bottom layer (containers, numerics, file formats).

Every impactlab error derives from :class:`ImpactlabError` *and* from the matching built-in, so a
caller may catch ``ImpactlabError`` (anything of ours) or the built-in (``ValueError``,
``OSError``) as usual. Every message names the problem and what to do about it. The device and
transport errors live in :mod:`acquisition.errors`, the simulator's in its modules; all share this
root.
"""
from __future__ import annotations

__all__ = ["ImpactlabError", "RecordingError", "UsageError"]


class ImpactlabError(Exception):
    """Base of all impactlab errors."""


class RecordingError(ImpactlabError, OSError):
    """A recording file that cannot be read or written (damaged, wrong schema version...)."""


class UsageError(ImpactlabError, ValueError):
    """A command line or call that asks for something impossible (wrong option, missing input)."""
