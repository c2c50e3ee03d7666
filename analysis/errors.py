"""The impactlab error root and the errors of the bottom layer (containers, numerics, file formats).

Every impactlab error derives from :class:`ImpactlabError` *and* from the matching built-in, so a
caller may catch ``ImpactlabError`` (anything of ours) or the built-in (``ValueError``,
``OSError``) as usual. Every message names the problem and what to do about it. The device and
transport errors live in :mod:`acquisition.errors`, the simulator's in :mod:`simulator.errors`; all
share this root.
"""
from __future__ import annotations

__all__ = [
    "ImpactlabError",
    "RecordingError",
    "UsageError",
    "SEP005Error",
    "ReportInputError",
    "MissingAssetError",
    "GeometryError",
    "InputError",
    "UFFError",
    "EffectError",
    "FitError",
    "PointLabelError",
    "ChildCrashed",
    "ChildTimeout",
    "FolderBusy",
    "OutputBusy",
    "WorkLimitError",
    "DiskFullError",
    "LevelsDoNotPair",
    "FEModelError",
]


class ImpactlabError(Exception):
    """Base of all impactlab errors."""


class RecordingError(ImpactlabError, OSError):
    """A recording file that cannot be read or written (damaged, wrong schema version...)."""


class UsageError(ImpactlabError, ValueError):
    """A command line or call that asks for something impossible (wrong option, missing input)."""


class SEP005Error(ImpactlabError, ValueError):
    """A document that is not a valid SEP005 list of channels."""


class ReportInputError(ImpactlabError, ValueError):
    """An input of the report that cannot be used; the message says what to do."""


class MissingAssetError(ImpactlabError, FileNotFoundError):
    """A web asset whose package is not installed; the message names the extra to install."""


class GeometryError(ImpactlabError, ValueError):
    """A geometry that cannot be read or does not fit the data; the message says what to do."""


class InputError(ImpactlabError, ValueError):
    """An input file or option that cannot be used; the message says what to do."""


class UFFError(ImpactlabError, ValueError):
    """A UFF file that cannot be written or read as asked (the message says what to do)."""


class EffectError(ImpactlabError, ValueError):
    """An effect name or parameter set that cannot be applied (the message says what is expected)."""


class FitError(ImpactlabError, ValueError):
    """The data cannot be fitted as asked (too few lines, nothing stable...)."""


class PointLabelError(ImpactlabError, ValueError):
    """A point label that is not of the form ``component:node:direction``."""


class ChildCrashed(ImpactlabError, RuntimeError):
    """The child process died without an answer (``exitcode``: negative signal number or status)."""

    def __init__(self, exitcode: int | None) -> None:
        super().__init__(f"the reader process died (exit code {exitcode})")
        self.exitcode = exitcode


class ChildTimeout(ImpactlabError, RuntimeError):
    """The child process did not answer in time (it was killed)."""


class FolderBusy(ImpactlabError, OSError):
    """Another process holds an output folder's lock (a batch writing there); the message names its pid."""


class OutputBusy(ImpactlabError, OSError):
    """An output file that a live writer holds (a recording being captured, recorded by the station or
    imported): nothing is written to it; the message names the writer's pid. Commands exit with 1."""


class LevelsDoNotPair(ImpactlabError, ValueError):
    """FRF sets compared across excitation levels whose modes do not pair by frequency and MAC: not
    measurements of one structure (the message says how many paired)."""


class WorkLimitError(UsageError):
    """A request for more work than the data support or the machine can hold (the message names the
    largest accepted value)."""


class DiskFullError(ImpactlabError, OSError):
    """A file could not be written for want of room (disk full, file size limit, quota); the message
    says what was kept and what to do. Commands end with exit code 1."""


class FEModelError(ImpactlabError):
    """A finite-element model (matrices, DOF map, its TOML) that cannot be used: the message names the file,
    the row and what to do. Not a usage error: the command runs, the model's files are wrong (exit 1)."""
