"""The operator's side of a capture, as callbacks any front end supplies (a terminal, a browser
station, a script): :class:`HitSummary` is the per-hit event, :class:`Operator` the protocol.

The session calls ``operator.decide(summary)`` for a hit that passed the automatic checks (True:
accept, False: reject, raise :class:`OperatorQuit` to end the test), ``operator.progress(text)``
with the lines to show, and ``operator.on_hit(summary)`` once per hit after it is on disk, with
the verdict (``summary.decision``: True accepted, False rejected), the reasons and the data.
Library code here prints nothing: the terminal dialogue lives in :mod:`acquisition.cli_capture`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from .hitcheck import HitCheck
from .session_errors import OperatorQuit

__all__ = ["HitSummary", "Operator", "CallbackOperator", "auto_accept", "OperatorQuit"]


@dataclass
class HitSummary:
    """What the operator sees after a hit."""

    measurement: int
    n_measurements: int
    point: str
    attempt: int
    accepted: int
    target: int
    rejected: int
    check: HitCheck
    coherence_so_far: float | None = None

    #: the point's running average (``acquisition.averaging.MeasurementAverage``; this hit included while deciding)
    average: Any = field(default=None, repr=False)
    #: filled in when the hit is decided: True accepted, False rejected; why; its index in the recording
    decision: bool | None = None
    reasons: list = field(default_factory=list)
    hit_index: int = -1
    #: the hit itself (``analysis.hit.Hit`` before its verdict): its data, sample rate and trigger
    hit: Any = field(default=None, repr=False)

    @property
    def data(self) -> Any:
        """The hit's channels in engineering units, ``[n_channels, n]`` (None without a hit)."""
        return None if self.hit is None else self.hit.data

    @property
    def sample_rate_hz(self) -> float:
        return 0.0 if self.hit is None else float(self.hit.sample_rate_hz)

    @property
    def trigger_index(self) -> int:
        return 0 if self.hit is None else int(self.hit.trigger_index)

    def text(self) -> str:
        c = self.check
        ovl = ",".join(str(i + 1) for i, o in enumerate(c.overload) if o) or "none"
        coh = "-" if self.coherence_so_far is None else f"{self.coherence_so_far:.3f}"
        s = (f"point {self.measurement + 1}/{self.n_measurements} {self.point}  hit {self.attempt}: "
             f"force peak {c.force_peak_n:.1f} N, pulse {c.pulse_width_ms:.2f} ms, overload {ovl}, "
             f"double hit {'YES' if c.double_hit else 'no'} ({100 * c.second_peak_ratio:.0f} %), coherence {coh}")
        if c.verdict.accept is False:
            s += "  -> REJECTED: " + "; ".join(c.verdict.reasons)
        return s


def auto_accept(summary: HitSummary) -> bool:
    """The ``--auto`` operator: accept every hit that passed the automatic checks."""
    return True



class Operator(Protocol):
    """What a capture session asks of its front end (see the module docstring)."""

    def decide(self, summary: HitSummary) -> bool: ...

    def progress(self, text: str) -> None: ...

    def on_hit(self, summary: HitSummary) -> None: ...


class CallbackOperator:
    """An :class:`Operator` from plain callables (``decide`` default :func:`auto_accept`; the others
    default to doing nothing)."""

    def __init__(self, decide: Callable[[HitSummary], bool] = auto_accept,
                 progress: Callable[[str], None] | None = None,
                 on_hit: Callable[[HitSummary], None] | None = None) -> None:
        self._decide = decide
        self._progress = progress
        self._on_hit = on_hit

    def decide(self, summary: HitSummary) -> bool:
        return bool(self._decide(summary))

    def progress(self, text: str) -> None:
        if self._progress is not None:
            self._progress(text)

    def on_hit(self, summary: HitSummary) -> None:
        if self._on_hit is not None:
            self._on_hit(summary)
