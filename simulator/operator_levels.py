"""The simulated operator striking force levels in series: ``sim://?levels=0.4,1&per_level=5`` strikes
five hits at 0.4 times the hammer's usual force, then five at full force, at each hammer point (the
count starts again when the hammer moves). This is what ``capture --soft-hard`` prompts a real
operator to do; the simulated operator does not read the prompts, so a rejected hit shifts its
series by one strike (the linearity check groups hits by their measured peak force, not by the
prompt).
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = ["LevelledStand", "levels_from_options", "LEVEL_OPTION_KEYS"]

#: the URL options of the levelled operator
LEVEL_OPTION_KEYS = ("levels", "per_level")


def levels_from_options(opts: Mapping[str, Any]) -> tuple[tuple[float, ...], int] | None:
    """(amplitude scales, hits per level) of the URL options ``levels`` (comma-separated factors of
    the hammer's usual peak force, > 0) and ``per_level`` (default 1); None without ``levels``.
    Raises ValueError for bad values."""
    if not opts.get("levels"):
        if opts.get("per_level"):
            raise ValueError("simulator option per_level needs levels=A,B,... as well")
        return None
    try:
        scales = tuple(float(v) for v in str(opts["levels"]).split(",") if v.strip())
        per = int(opts.get("per_level", 1))
    except ValueError:
        raise ValueError(f"simulator options levels={opts.get('levels')!r}, per_level={opts.get('per_level')!r}: "
                         "levels are comma-separated factors > 0 (e.g. 0.4,1), per_level an integer >= 1") from None
    if not scales or not all(s > 0 for s in scales) or per < 1:
        raise ValueError(f"simulator option levels={opts['levels']!r} per_level={per}: give factors > 0 (e.g. "
                         "levels=0.4,1) and per_level >= 1")
    return scales, per


class LevelledStand:
    """A stand (:class:`simulator.stand.TestStand` or one like it, with ``next_strike``) whose strikes at
    each hammer point go ``per_level`` at each of ``scales`` in turn (amplitude scale factors)."""

    def __init__(self, stand: Any, scales: tuple[float, ...], per_level: int) -> None:
        if not hasattr(stand, "next_strike"):
            raise ValueError("simulator option levels= needs a simulated frame (not a replayed recording)")
        self.stand = stand
        self.scales = tuple(scales)
        self.per_level = int(per_level)
        self._point: str | None = None
        self._count = 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self.stand, name)

    def set_hammer_point(self, point: Any) -> None:
        if str(point) != self._point:
            self._point, self._count = str(point), 0
        self.stand.set_hammer_point(point)

    def scale_of(self, k: int) -> float:
        """The amplitude scale of the ``k``-th strike (from 0) at a point."""
        return self.scales[(k // self.per_level) % len(self.scales)]

    def strike(self, fs_hz: float, n_samples: int, pretrigger: int) -> Any:
        self.stand.next_strike(amplitude_scale=self.scale_of(self._count))
        self._count += 1
        return self.stand.strike(fs_hz, n_samples, pretrigger)
