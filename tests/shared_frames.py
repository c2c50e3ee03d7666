"""The simulations the diagnosis tests fit against, made once per test process.

A :class:`simulator.physical.FrameVariants` keeps what it solved (the Ritz spaces of the parts a cause changes, the
modes of every candidate asked); those depend on the frame and the points alone, not on the measurement a diagnosis
compares with it. Many tests diagnose against the same frame at the same points (the unchanged frame.toml at the test
points): :func:`frame_variants` hands each of them one simulation per frame and points, so a test does not solve again
what an earlier test of its process solved. Its answers are those of a new one (what it keeps is what it would
compute); a test that changes its attributes (``reduced``) or reads its caches makes its own."""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from simulator.config import FrameConfig
from simulator.physical import FrameVariants

_MADE: dict[tuple[str, tuple[str, ...], tuple[str, ...]], FrameVariants] = {}


def frame_variants(config: FrameConfig | str | Path | None, outputs: Sequence[str],
                   references: Sequence[str]) -> FrameVariants:
    """``FrameVariants(config, outputs, references)``, one per frame (compared by value) and points in this process;
    shared: ask it, never change it."""
    cfg = config if isinstance(config, FrameConfig) else FrameConfig.load(config)
    key = (repr(cfg), tuple(map(str, outputs)), tuple(map(str, references)))
    if key not in _MADE:
        _MADE[key] = FrameVariants(cfg, outputs, references)
    return _MADE[key]
