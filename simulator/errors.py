"""Errors of the simulator (frame model, configuration, test stand). Each derives from the impactlab
root :class:`analysis.errors.ImpactlabError` and a built-in, so callers may catch broadly; the
message says where and what to do."""
from __future__ import annotations

from analysis.errors import ImpactlabError

__all__ = ["ConfigError", "ModelError", "StandError"]


class StandError(ImpactlabError, ValueError):
    """A request the test stand cannot carry out (bad channel set-up, point off the frame...)."""


class ConfigError(ImpactlabError, ValueError):
    """A configuration file or value that cannot be used; the message says where and what to do."""


class ModelError(ImpactlabError, ValueError):
    """A frame model request that cannot be served (unknown point, bad quantity...)."""
