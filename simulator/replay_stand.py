"""A test stand that plays a recording back: ``strike()`` returns recorded input volts.

Used behind the device URL ``sim://?replay=REC.h5`` so that the whole capture path (firmware,
bulk-only protocol, driver, session, recording) runs on recorded data. Each strike returns the
next recorded hit of the current measurement: ``volts = counts * volts_per_count`` per channel
(the analyser-input voltages the recording was made from), followed by zeros up to the
requested length. The firmware then filters, digitises and searches the trigger as usual, so
the replayed blocks equal the recorded ones up to the analyser front end's second pass
(anti-alias filter delay and ripple, requantisation): a path test, not a bit-exact copy
(``python -m acquisition replay`` recomputes bit-exactly from the stored counts).

``set_channels`` picks the hits whose reference and output points match the configured
channel points (a roving test replays point by point); when none match, all hits are used in turn.
"""
from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["ReplayStand", "ReplayEvent"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ReplayEvent:
    """What :meth:`ReplayStand.strike` returns: ``volts[n_ch, n]`` and an info dict."""

    volts: np.ndarray
    info: dict


class ReplayStand:
    """Replay the hits of a recording (``accepted_only``: skip the rejected ones)."""

    def __init__(self, path: str | Path, accepted_only: bool = True) -> None:
        from analysis.recording import Recording  # the reader validates the file

        with Recording(path) as rec:
            self.hits = list(rec.hits(accepted_only=accepted_only, skip_damaged=True))
        if not self.hits:
            raise ValueError(f"recording {path} holds no {'accepted ' if accepted_only else ''}hit to replay")
        for h in self.hits:
            if not np.all(np.isfinite(h.volts_per_count)):
                raise ValueError(f"hit {h.index} of {path} has no volts scaling (imported without sensitivities); "
                                 "it cannot be played through the analyser's inputs")
        self.path = str(path)
        self._selected = list(range(len(self.hits)))
        self._next = 0

    def set_channels(self, channels: Sequence[Any]) -> None:
        """Select the hits recorded with the same channel points (force point = reference)."""
        n_ch = self.hits[0].counts.shape[0]
        if len(channels) != n_ch:
            raise ValueError(f"the recording {self.path} holds {n_ch} channels; the set-up has {len(channels)}")
        points = [str(getattr(ch, "point", "")) for ch in channels]
        match = []
        for i, h in enumerate(self.hits):
            rec_points = [""] * n_ch
            rec_points[h.force_channel] = h.reference
            for k, o in zip(h.response_channels, h.outputs):
                rec_points[k] = o
            if rec_points == points:
                match.append(i)
        self._selected = match or list(range(len(self.hits)))
        self._next = 0

    def strike(self, fs_hz: float, n_samples: int, pretrigger: int) -> ReplayEvent:
        """The next recorded hit as input volts, zero-padded to ``n_samples``."""
        h = self.hits[self._selected[self._next % len(self._selected)]]
        self._next += 1
        if abs(fs_hz - h.sample_rate_hz) > 1e-9 * h.sample_rate_hz:
            raise ValueError(f"the recording was made at {h.sample_rate_hz:g} Hz; set the analyser to that rate")
        v = h.volts
        shift = h.trigger_index - int(pretrigger)
        out = np.zeros((v.shape[0], int(n_samples)))
        src = v[:, max(0, shift):]
        dst0 = max(0, -shift)
        m = min(src.shape[1], out.shape[1] - dst0)
        out[:, dst0:dst0 + m] = src[:, :m]
        return ReplayEvent(out, {"replay_hit": h.index, "source": self.path})
