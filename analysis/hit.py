"""One hammer hit: the container every producer of time data makes and every consumer reads.

The analyser's block becomes a :class:`Hit` once (the capture session, the browser station, a
replay, the importers and the simulator's stand all produce one), the recording writes and reads
it whole (``RecordingWriter.write_hit(hit)``, ``Recording.hits()``), and the spectra and the
time-data diagnosis take hits.

The time data are kept as the analyser delivered them, raw int16 ADC counts with the scaling of
each channel, so that a replay computes bit-identical spectra; :attr:`Hit.data`,
:attr:`Hit.force` and :attr:`Hit.responses` are the engineering-unit values
(``counts * eu_per_count``, float64; force in N, responses in the unit of their channel).
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from analysis.errors import UsageError

__all__ = ["Hit", "scale_counts", "stack_hits", "group_hits"]


def scale_counts(counts: np.ndarray, eu_per_count: np.ndarray) -> np.ndarray:
    """Engineering units from raw counts: ``counts[ch, n] * eu_per_count[ch]`` (float64, new array)."""
    c = np.asarray(counts)
    s = np.asarray(eu_per_count, dtype=float)
    return c.astype(np.float64) * s[:, None]


@dataclass(frozen=True, eq=False)
class Hit:
    """One hit (frozen; validated on construction).

    counts : int16 ``(n_channels, n_samples)``, the ADC counts as delivered.
    eu_per_count, volts_per_count : ``(n_channels,)`` scaling to engineering units and to volts at
        the input (NaN where a sensitivity is unknown).
    sample_rate_hz : sample rate (Hz).
    trigger_index : the sample at which the analyser triggered (= the pre-trigger length, samples).
    force_channel, response_channels : the channels' roles (0-based indices into ``counts``).
    point, reference, outputs : the measurement point, the force's point label and the responses'
        point labels (``"right:6:-X"``).
    measurement : index of the measurement point in the test plan.
    channel_names : the channels' names (empty when the producer has none).
    overload : ``(n_channels,)`` bool, the analyser's overload flags.
    timestamp : when the block was taken (s since the Unix epoch; 0.0 when unknown).
    sequence : the analyser's block counter (or the import order).
    accepted, reasons, check : the verdict (automatic checks and the operator) and the check's figures.

    The sequences are stored as copies (lists; ``channel_names`` a tuple).
    index : the hit's index in its recording (-1 before it is written).
    """

    counts: np.ndarray
    eu_per_count: np.ndarray
    volts_per_count: np.ndarray
    sample_rate_hz: float
    trigger_index: int
    force_channel: int
    response_channels: Sequence[int]
    point: str
    reference: str
    outputs: Sequence[str]
    measurement: int = 0
    channel_names: Sequence[str] = ()
    overload: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    timestamp: float = 0.0
    sequence: int = 0
    accepted: bool = True
    reasons: Sequence[str] = field(default_factory=list)
    check: dict = field(default_factory=dict)
    index: int = -1
    crc_ok: bool = True

    def __post_init__(self) -> None:
        c = np.asarray(self.counts)
        if c.dtype != np.int16 or c.ndim != 2:
            raise UsageError(f"hit counts must be int16 of shape (n_channels, n); got {c.dtype} {c.shape}")
        n_ch = c.shape[0]
        eu = np.asarray(self.eu_per_count, dtype=float).ravel()
        vpc = np.asarray(self.volts_per_count, dtype=float).ravel()
        over = np.asarray(self.overload, dtype=bool).ravel()
        if over.size == 0:
            over = np.zeros(n_ch, bool)
        for name, arr in (("eu_per_count", eu), ("volts_per_count", vpc), ("overload", over)):
            if arr.size != n_ch:
                raise UsageError(f"hit {name} has {arr.size} values for {n_ch} channels")
        fs = float(self.sample_rate_hz)
        if not (np.isfinite(fs) and fs > 0):
            raise UsageError(f"hit sample rate {self.sample_rate_hz!r} Hz is not a positive number")
        resp = [int(i) for i in self.response_channels]
        fch = int(self.force_channel)
        if not 0 <= fch < n_ch or any(not 0 <= i < n_ch or i == fch for i in resp):
            raise UsageError(f"hit channel roles (force {fch}, responses {resp}) do not fit its {n_ch} channels")
        names = tuple(str(n) for n in self.channel_names)
        if names and len(names) != n_ch:
            raise UsageError(f"hit has {len(names)} channel names for {n_ch} channels")
        s = object.__setattr__
        s(self, "counts", c)
        s(self, "eu_per_count", eu)
        s(self, "volts_per_count", vpc)
        s(self, "overload", over)
        s(self, "sample_rate_hz", fs)
        s(self, "trigger_index", int(self.trigger_index))
        s(self, "force_channel", fch)
        s(self, "response_channels", resp)
        s(self, "outputs", [str(o) for o in self.outputs])
        s(self, "point", str(self.point))
        s(self, "reference", str(self.reference))
        s(self, "measurement", int(self.measurement))
        s(self, "channel_names", names)
        s(self, "timestamp", float(self.timestamp))
        s(self, "sequence", int(self.sequence))
        s(self, "accepted", bool(self.accepted))
        s(self, "reasons", [str(r) for r in self.reasons])
        s(self, "check", dict(self.check or {}))
        s(self, "index", int(self.index))

    # -- engineering units ---------------------------------------------------------------------
    @property
    def data(self) -> np.ndarray:
        """All channels in engineering units, ``(n_channels, n_samples)`` float64 (a new array)."""
        return scale_counts(self.counts, self.eu_per_count)

    @property
    def volts(self) -> np.ndarray:
        """All channels as input voltage (V), ``(n_channels, n_samples)``."""
        return scale_counts(self.counts, self.volts_per_count)

    @property
    def force(self) -> np.ndarray:
        """The force channel (N), ``(n_samples,)``."""
        return self.counts[self.force_channel].astype(np.float64) * self.eu_per_count[self.force_channel]

    @property
    def responses(self) -> np.ndarray:
        """The response channels in their units, ``(n_responses, n_samples)``."""
        return scale_counts(self.counts[self.response_channels], self.eu_per_count[self.response_channels])

    @property
    def n_samples(self) -> int:
        return int(self.counts.shape[1])

    @property
    def pretrigger_s(self) -> float:
        """Time before the trigger (s)."""
        return self.trigger_index / self.sample_rate_hz

    @property
    def record_s(self) -> float:
        """Length of the block (s)."""
        return self.n_samples / self.sample_rate_hz

    def with_verdict(self, accepted: bool, reasons: Sequence[str] = (), check: dict | None = None) -> Hit:
        """This hit with its verdict set (a new hit)."""
        return replace(self, accepted=bool(accepted), reasons=list(reasons),
                       check=self.check if check is None else dict(check))

    def with_index(self, index: int) -> Hit:
        """This hit as written at ``index`` of its recording (a new hit)."""
        return replace(self, index=int(index))


def stack_hits(hits: Iterable[Hit]) -> tuple[np.ndarray, np.ndarray, float]:
    """A set of hits of one shape as arrays: ``force[n_hits, n]`` (N), ``responses[n_hits, n_out, n]``
    (EU) and the common sample rate (Hz), as the time-data diagnosis takes them."""
    hs = list(hits)
    if not hs:
        raise UsageError("no hits to stack")
    rates = {h.sample_rate_hz for h in hs}
    shapes = {(len(h.response_channels), h.n_samples) for h in hs}
    if len(rates) > 1 or len(shapes) > 1:
        raise UsageError(f"hits differ in sample rate {sorted(rates)} Hz or shape {sorted(shapes)}; stack each "
                         "group on its own")
    return (np.array([h.force for h in hs]), np.array([h.responses for h in hs]), hs[0].sample_rate_hz)


def group_hits(hits: Iterable[Hit]) -> dict[tuple[str, float, int], list[Hit]]:
    """Hits grouped by what lets them be stacked and compared: ``(reference, sample_rate_hz,
    n_samples)``, in order of first appearance, each group in the order given."""
    groups: dict[tuple[str, float, int], list[Hit]] = {}
    for h in hits:
        groups.setdefault((h.reference, h.sample_rate_hz, h.n_samples), []).append(h)
    return groups
