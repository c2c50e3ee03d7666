"""Model discrepancy diagnosis: what the simulation gets wrong, the physical cause, the gain.

Modules: :mod:`.compare` (errors, mode pairing, coherence), :mod:`.effects` (the catalogue),
:mod:`.verdict` (cross-validated gain, significance, verdict), :mod:`.report` (plots and text).
"""
from .effects import EFFECTS, EffectError, effect_names, predict
from .verdict import Diagnosis, diagnose

__all__ = ["EFFECTS", "EffectError", "effect_names", "predict", "Diagnosis", "diagnose"]
