"""The time data of an import as read (:class:`ImportedTest`) and the checks every reader's output passes.

A reader (:mod:`acquisition.importers_parse`) returns an :class:`ImportedTest`: the file's float
time histories in engineering units, one array per hit, with the channel table the file states.
:func:`_checked` refuses what no hit can be made of (a sample rate that is not a positive number,
blocks of different shapes, non-finite samples, an infinite or zero sensitivity);
:func:`combine_imports` joins the files of one test. Nothing here decides channel roles
(:mod:`acquisition.importers_roles`), quantises (:mod:`acquisition.importers_quantise`) or writes
(:mod:`acquisition.importers_write`).
"""
from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from analysis.finite_checks import describe_nonfinite

from .errors import ImportDataError, NonFiniteSamples

__all__ = ["ImportedTest", "MAX_SAMPLE_RATE_HZ", "drop_nonfinite_hits", "read_dropping_nonfinite",
           "combine_imports", "source_files", "unit_info"]

log = logging.getLogger(__name__)

_UNIT_QUANTITY = {
    "n": ("force", "N"), "newton": ("force", "N"), "newtons": ("force", "N"), "lbf": ("force", "lbf"),
    "g": ("acceleration", "g"), "m/s^2": ("acceleration", "m/s^2"), "m/s2": ("acceleration", "m/s^2"),
    "m/s/s": ("acceleration", "m/s^2"), "m/s": ("velocity", "m/s"), "m": ("displacement", "m"),
    "v": ("voltage", "V"), "volt": ("voltage", "V"), "volts": ("voltage", "V"),
}


#: the highest sample rate accepted from a file (Hz); no impact-test analyser comes near it
MAX_SAMPLE_RATE_HZ = 1e7


@dataclass
class ImportedTest:
    """Time data of one test as read from its file(s): ``hits[k]`` is ``(n_ch, n)`` float in
    engineering units, one block per hit.

    fs_hz : sample rate (Hz).
    channels : dicts with name, quantity, unit, sensitivity (mV/EU or NaN), point.
    trigger_indices : per hit, the sample the windows start at (empty when the file has none: the
        trigger is then found on the force channel).
    source, meta : where the data came from and the reader's notes (format, ...).

    This is the file's content, not yet a set of :class:`analysis.hit.Hit`: the values are kept as
    read (a reader is checked against the file's numbers exactly, and several files are combined
    before anything is decided), and what makes a block a hit (which channel is the force, the
    responses' point labels, the trigger found on the force) may still be set by the user.
    :func:`imported_hits` makes the hits once those are fixed.
    """

    fs_hz: float
    channels: list
    hits: list
    trigger_indices: list
    source: str
    meta: dict = field(default_factory=dict)

    def force_channel(self) -> int:
        idx = [i for i, c in enumerate(self.channels) if c["quantity"] == "force"]
        if len(idx) != 1:
            raise ImportDataError(
                f"{self.source}: found {len(idx)} force channels ({[c['name'] for c in self.channels]}); "
                "name the hammer channel with --force-channel K (1-based)"
            )
        return idx[0]

    def response_channels(self) -> list[int]:
        f = self.force_channel()
        motion = [i for i, c in enumerate(self.channels)
                  if i != f and c["quantity"] in ("acceleration", "velocity", "displacement")]
        if not motion:
            raise ImportDataError(f"{self.source}: no response channel with a motion unit (g, m/s^2, m/s, m); "
                               "name them with --responses")
        return motion


def unit_info(label: str) -> tuple[str, str]:
    key = label.strip().lower()
    return _UNIT_QUANTITY.get(key, ("unknown", label.strip()))


#: what malformed content makes the parsing code raise; readers turn it into ImportDataError
_MALFORMED = (KeyError, IndexError, ValueError, TypeError, ZeroDivisionError, OverflowError, AttributeError, EOFError)


def _checked(test: ImportedTest) -> ImportedTest:
    """``test`` after the consistency checks every importer's output must pass."""
    if not (isinstance(test.fs_hz, (int, float)) and math.isfinite(test.fs_hz) and test.fs_hz > 0):
        raise ImportDataError(f"{test.source}: the sample rate {test.fs_hz!r} Hz is not a positive number; check "
                              "the sample interval / rate in the file or the description")
    if test.fs_hz > MAX_SAMPLE_RATE_HZ:
        raise ImportDataError(f"{test.source}: the sample rate {test.fs_hz:.6g} Hz is above the largest accepted, "
                              f"{MAX_SAMPLE_RATE_HZ:g} Hz; check the sample interval (Delta_X) or rate in the file")
    if not test.hits:
        raise ImportDataError(f"{test.source}: no hit (no time data) found")
    n_ch = len(test.channels)
    for k, h in enumerate(test.hits):
        if h.ndim != 2 or h.shape[0] != n_ch or h.shape[1] < 2 or h.shape != test.hits[0].shape:
            raise ImportDataError(f"{test.source}: hit {k + 1} has shape {h.shape}; expected ({n_ch} channels, "
                                  f">= 2 samples), the same for every hit")
    _require_finite_hits(test)
    for k, c in enumerate(test.channels):
        s = c.get("sensitivity", math.nan) if isinstance(c, dict) else math.nan
        if not (isinstance(s, (int, float)) and (math.isnan(s) or (math.isfinite(s) and s != 0))):
            raise ImportDataError(f"{test.source}: channel {k + 1} ({c.get('name', '')}): the Sensitivity {s!r} "
                                  "(mV/EU) is not a finite nonzero number; correct it in the file or the description "
                                  "(or leave it out: unknown)")
    return test


def _nonfinite_hits(test: ImportedTest) -> list[tuple[int, int, str]]:
    """(hit, channel, description of the first bad sample) of every hit holding a non-finite sample."""
    out = []
    for k, h in enumerate(test.hits):
        for c in range(h.shape[0]):
            what = describe_nonfinite(h[c])
            if what is not None:
                out.append((k, c, what))
                break
    return out


def _require_finite_hits(test: ImportedTest) -> None:
    """Raise :class:`NonFiniteSamples` naming the file, hit, channel and first sample of a NaN/inf."""
    bad = _nonfinite_hits(test)
    if bad:
        k, c, what = bad[0]
        name = test.channels[c].get("name", f"ch{c + 1}") if c < len(test.channels) else f"ch{c + 1}"
        raise NonFiniteSamples(
            f"{test.source}: hit {k + 1}, channel {c + 1} ({name}): {what}; {len(bad)} of {len(test.hits)} hit(s) "
            "hold non-finite samples: fix the export, or import with --drop-nonfinite to leave those hits out", test)


def drop_nonfinite_hits(test: ImportedTest) -> tuple[ImportedTest, int]:
    """``test`` without the hits that hold a non-finite sample, and how many were dropped (a new
    test; ``test`` is not changed). Raises :class:`ImportDataError` when no hit is left."""
    bad = {k for k, _, _ in _nonfinite_hits(test)}
    keep = [k for k in range(len(test.hits)) if k not in bad]
    if not keep:
        raise ImportDataError(f"{test.source}: every hit ({len(test.hits)}) holds non-finite samples; nothing to import")
    triggers = [test.trigger_indices[k] for k in keep] if len(test.trigger_indices) == len(test.hits) else []
    meta = {**test.meta, "dropped_nonfinite_hits": len(bad)}
    return ImportedTest(test.fs_hz, test.channels, [test.hits[k] for k in keep], triggers, test.source, meta), len(bad)


def read_dropping_nonfinite(read: Callable[..., ImportedTest], *args: Any, drop: bool = False,
                            **kwargs: Any) -> ImportedTest:
    """``read(*args, **kwargs)``; with ``drop``, hits holding non-finite samples are left out (and
    counted in ``meta["dropped_nonfinite_hits"]``) instead of failing the import."""
    try:
        return read(*args, **kwargs)
    except NonFiniteSamples as exc:
        if not drop:
            raise
        if not isinstance(exc.test, ImportedTest):
            raise
        test, n = drop_nonfinite_hits(exc.test)
        log.warning("%s: left out %d hit(s) holding non-finite samples", test.source, n)
        return test


def _parsed(read: Callable[[], ImportedTest], what: str, advice: str) -> ImportedTest:
    """``read()`` checked (:func:`_checked`); a malformed input (any of ``_MALFORMED``) becomes one
    :class:`ImportDataError`: ``what`` (the problem), the parser's words, then ``advice``."""
    try:
        return _checked(read())
    except ImportDataError:
        raise
    except _MALFORMED as exc:
        raise ImportDataError(f"{what} ({type(exc).__name__}: {exc}); {advice}") from None


#: what a channel of every file of one import must share (:func:`combine_imports`)
_SAME_IN_EVERY_FILE = ("name", "quantity", "unit", "point", "sensitivity")


def _same_value(a: Any, b: Any) -> bool:
    """``a == b``, NaN equal to NaN (an unknown sensitivity)."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return bool(a == b)


def combine_imports(tests: Sequence[ImportedTest]) -> ImportedTest:
    """One test from several files read alike (e.g. one .lvm per hit): the hits in the order given.
    The files must share the sample rate, the block shape and the channels (name, quantity, unit,
    point, sensitivity, in order); the files' trigger samples are kept
    for the leading hits that all have one (the others' triggers are found on the force). Raises
    :class:`ImportDataError` naming the file that differs."""
    if not tests:
        raise ImportDataError("no file to import")
    first = tests[0]
    hits: list = list(first.hits)
    triggers: list = list(first.trigger_indices)
    for t in tests[1:]:
        if t.fs_hz != first.fs_hz or t.hits[0].shape != first.hits[0].shape:
            raise ImportDataError(f"{t.source} differs in sample rate or block size from {first.source}; "
                                  "import the files separately")
        for c, (a, b) in enumerate(zip(t.channels, first.channels)):
            differ = [key for key in _SAME_IN_EVERY_FILE if not _same_value(a.get(key), b.get(key))]
            if differ:
                raise ImportDataError(f"{t.source}: channel {c + 1} has {differ[0]} {a.get(differ[0])!r}, in "
                                      f"{first.source} {b.get(differ[0])!r}; the files of one import hold the same "
                                      "channels in the same order: import the files separately")
        triggers = triggers + list(t.trigger_indices) if len(triggers) == len(hits) else []
        hits += t.hits
    meta = dict(first.meta)
    meta["sources"] = [src for t in tests for src in source_files(t)]
    return ImportedTest(first.fs_hz, first.channels, hits, triggers, first.source, meta)


def source_files(test: ImportedTest) -> list[str]:
    """The files ``test`` was read from (``meta["sources"]`` when several, else ``source``)."""
    return [str(p) for p in test.meta.get("sources", ())] or [test.source]
