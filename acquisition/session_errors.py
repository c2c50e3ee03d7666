"""Errors of a capture session."""

from __future__ import annotations

from .errors import ImpactlabError

__all__ = ["OperatorQuit", "SessionError"]


class OperatorQuit(ImpactlabError):
    """The operator ended the test (key q); the session keeps what it has."""


class SessionError(ImpactlabError, RuntimeError):
    """The session cannot go on (no triggers, every hit rejected...); the message says why."""
