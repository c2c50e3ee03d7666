"""Channel roles of an import: which channel is the force, which are responses, their point labels."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from analysis.points import PointLabelError, parse_point

from .errors import ImportDataError
from .importers_data import ImportedTest

__all__ = ["ChannelRoles", "channel_roles"]

@dataclass(frozen=True)
class ChannelRoles:
    """What an import makes of the file's channels: the channel table (quantities and point labels
    as given or relabelled), the force channel and the response channels (0-based)."""

    channels: list
    force_channel: int
    response_channels: list

    @property
    def reference(self) -> str:
        return str(self.channels[self.force_channel]["point"])

    @property
    def outputs(self) -> list:
        return [str(self.channels[i]["point"]) for i in self.response_channels]

    def describe(self) -> list:
        """One line per used channel: ``force: channel 2 'Force' [N] -> n:1:Z`` (1-based numbers)."""
        def line(role: str, i: int) -> str:
            c = self.channels[i]
            return f"{role}: channel {i + 1} {c.get('name', '')!r} [{c.get('unit', '')}] -> {c['point']}"
        return [line("force", self.force_channel)] + [line("response", i) for i in self.response_channels]


def channel_roles(
    test: ImportedTest,
    *,
    reference: str | None = None,
    outputs: Sequence[str] | None = None,
    force_channel: int | None = None,
    response_channels: Sequence[int] | None = None,
) -> ChannelRoles:
    """The force and response channels of ``test`` and their point labels: from the file, or as
    given (``force_channel``/``response_channels`` 0-based; ``reference``/``outputs`` relabel them)."""
    chans = [dict(c) for c in test.channels]
    if force_channel is not None:
        if not 0 <= force_channel < len(chans):
            raise ImportDataError(f"force channel {force_channel + 1} does not exist (1..{len(chans)})")
        for i, c in enumerate(chans):
            if c["quantity"] == "force" and i != force_channel:
                c["quantity"] = "unknown"
        chans[force_channel]["quantity"] = "force"
        if chans[force_channel]["unit"] in ("", "?", "V"):
            chans[force_channel]["unit"] = "N"
    tmp = ImportedTest(test.fs_hz, chans, test.hits, test.trigger_indices, test.source, test.meta)
    fch = tmp.force_channel()
    rch = list(response_channels) if response_channels is not None else tmp.response_channels()
    for i in rch:
        if not 0 <= i < len(chans) or i == fch:
            raise ImportDataError(f"response channel {i + 1} does not exist or is the force channel")
        if chans[i]["quantity"] not in ("acceleration", "velocity", "displacement"):
            chans[i]["quantity"] = "acceleration"
    try:
        if reference is not None:
            chans[fch]["point"] = str(parse_point(reference))
        if outputs is not None:
            if len(outputs) != len(rch):
                raise ImportDataError(f"{len(outputs)} output labels for {len(rch)} response channels")
            for i, lab in zip(rch, outputs):
                chans[i]["point"] = str(parse_point(lab))
    except PointLabelError as exc:
        raise ImportDataError(str(exc)) from None
    for c in chans:
        p = parse_point(c["point"])
        c.setdefault("direction", p.direction)
        c["direction"] = p.direction
    return ChannelRoles(chans, fch, rch)
