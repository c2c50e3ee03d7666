"""The physical stage's judge built as :mod:`analysis.diagnosis.physical_verdict` builds it, for the tests that call
the pair search's parts directly (the pair counts and the pair bounds)."""
from __future__ import annotations

import numpy as np
from shared_frames import frame_variants
from test_diagnosis_physical import OUTS, REFS


def physical_stage(measured, mm) -> tuple:
    """The nominal frame's simulation at the test points and its judge for ``measured`` (FRFs) and ``mm`` (their
    modes): (simulation, cause specs by name, fmax in Hz, judge)."""
    from analysis.diagnosis.compare import line_weights, typical_error_db
    from analysis.diagnosis.effects import predict
    from analysis.diagnosis.physical import residuals
    from analysis.diagnosis.physical_verdict import FMAX_FACTOR, _Judge
    from analysis.diagnosis.verdict import known_processing

    fv = frame_variants(None, OUTS, REFS)
    specs = {c.name: c for c in fv.causes()}
    fmax = FMAX_FACTOR * float(mm.freq_hz[-1])
    prior, weights = known_processing(measured), line_weights(measured)

    def frf(changes: list):
        model = fv.model(None, {}) if not changes else fv.model_of(changes)
        return predict(model, measured.freq_hz, measured.quantity, prior, outputs=measured.outputs,
                       references=measured.references)

    f0, P0 = fv.modes(None, {}, fmax)
    base = np.sum(residuals(mm, f0, P0) ** 2, axis=1)
    judge = _Judge(measured, frf, weights, base, np.zeros(base.size, bool),
                   typical_error_db(measured, frf([]).H, weights), -60.0)
    return fv, specs, fmax, judge
