"""The part of a diagnosis that a stage decides: the fields a stage's outcome and the final
:class:`analysis.diagnosis.verdict.Diagnosis` share, declared once.

The physical stage (:class:`analysis.diagnosis.physical_verdict.PhysicalOutcome`) fills them as it
decides; when it gives the verdict, :meth:`VerdictPart.verdict_fields` hands them to the
``Diagnosis`` as they are.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

from ..frf import FRFSet

__all__ = ["VerdictPart"]


@dataclass(kw_only=True)
class VerdictPart:
    """verdict : the named cause's name, ``"combined"`` for two, ``"none"`` or ``"unexplained"``.
    causes : one dict per cause tried, sorted by held-out gain (``effect``, ``parameters``, ``gain_db``,
    ``error_before_db``, ``error_after_db``, ``z``, ``significant``, ``evidence``, ...).
    extended : the simulation with the accepted causes (None: not reached).
    error_before_db, error_after_db : held-out (typical) FRF error of the simulation and of the
    extension, dB. combined : the accepted causes stage by stage (verdict first), each with its held-out
    gain. reason : why the verdict is ``unexplained`` (or what it lacks). named : the named causes,
    ``{"effect", "parameters"}`` each (at most two). next_measurement : the measurement that separates
    two close candidates, None without rivals."""

    verdict: str = "none"
    causes: list = field(default_factory=list)
    extended: FRFSet | None = None
    error_before_db: float = float("nan")
    error_after_db: float = float("nan")
    combined: list = field(default_factory=list)
    reason: str = ""
    named: list = field(default_factory=list)
    next_measurement: dict | None = None

    def verdict_fields(self) -> dict[str, Any]:
        """The fields of :class:`VerdictPart` by name (not copied), for a ``Diagnosis`` built from them."""
        return {f.name: getattr(self, f.name) for f in fields(VerdictPart)}
