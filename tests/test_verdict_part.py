"""The verdict's fields are declared once (analysis/diagnosis/verdict_part.py): the physical stage's
outcome and the Diagnosis both take them from VerdictPart, and a decided outcome hands them over as they are."""
from __future__ import annotations

from dataclasses import fields

import numpy as np

from analysis.diagnosis.physical_verdict import PhysicalOutcome
from analysis.diagnosis.verdict import Diagnosis
from analysis.diagnosis.verdict_part import VerdictPart
from analysis.frf import FRFSet

NINE = {"verdict", "causes", "extended", "error_before_db", "error_after_db", "combined", "reason", "named",
        "next_measurement"}


def test_the_nine_verdict_fields_are_declared_once() -> None:
    assert {f.name for f in fields(VerdictPart)} == NINE
    for cls in (PhysicalOutcome, Diagnosis):
        assert issubclass(cls, VerdictPart)
        own = set(cls.__dict__.get("__annotations__", {}))
        assert not own & NINE, f"{cls.__name__} declares {own & NINE} again"
        assert NINE <= {f.name for f in fields(cls)}


def test_a_decided_outcome_hands_its_fields_to_the_diagnosis_as_they_are() -> None:
    f = np.linspace(1.0, 10.0, 5)
    frf = FRFSet(freq_hz=f, H=np.ones((1, 1, f.size), complex), quantity="accelerance", outputs=("a:1:Z",),
                 references=("a:2:Z",))
    causes = [{"effect": "mass_scale", "parameters": {"factor": 1.1}}]
    out = PhysicalOutcome(decided=True, verdict="mass_scale", causes=causes, extended=frf, error_before_db=-20.0,
                          error_after_db=-35.0, reason="", named=causes, combined=causes,
                          next_measurement={"point": "a:3:Z"}, doc={"x": 1})
    diag = Diagnosis(noise_db={"diff": -40.0}, comparison={}, unexplained=[], measured=frf, simulated=frf,
                     **out.verdict_fields())
    for name in NINE:
        assert getattr(diag, name) is getattr(out, name)
    assert not hasattr(diag, "doc") and diag.physical == {}
