"""Model discrepancy diagnosis: what the simulation gets wrong, the physical cause, the gain.

Modules: :mod:`.compare` (errors, mode pairing, coherence), :mod:`.effects` (the catalogue),
:mod:`.verdict` (cross-validated gain, significance, verdict), :mod:`.entry` (the whole diagnosis in
one call, :func:`diagnose`), :mod:`.report` (plots and text).
"""
from __future__ import annotations

from .effects import EFFECTS, EffectError, effect_names, predict
from .entry import diagnose
from .verdict import Diagnosis, diagnose_frfs

__all__ = ["EFFECTS", "EffectError", "effect_names", "predict", "Diagnosis", "diagnose", "diagnose_frfs"]
