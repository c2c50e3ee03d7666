"""FRFs from raw hammer time data with the project's spectra (:mod:`analysis.spectra`), hit by hit."""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from acquisition.importers import detect_trigger
from analysis.frf import FRFSet
from analysis.spectra import FRFAccumulator, WindowSettings, hit_spectra

__all__ = ["impact_frf", "per_hit_frfs"]

#: samples kept before the detected force onset (the windows start there)
PRE_SAMPLES = 10


def impact_frf(hits: Sequence[tuple[np.ndarray, np.ndarray]], fs_hz: float, windows: WindowSettings, *,
               outputs: Sequence[str] = ("n:2:Z",), reference: str = "n:1:Z", unit: str = "",
               estimator: str = "H1", meta: dict | None = None) -> FRFSet:
    """H1 (or H2) averaged over hits ``(force[n] N, responses[n_resp, n])`` by :class:`FRFAccumulator`.

    Each hit's window origin is ``PRE_SAMPLES`` before the sample where the force first reaches 10 %
    of its peak (:func:`acquisition.importers.detect_trigger`). The FRF set carries the exponential
    window's tau (s) when one is used, so the fitter removes its damping.
    """
    acc = FRFAccumulator(outputs, reference, "accelerance", unit)
    for force, resp in hits:
        k0 = max(detect_trigger(force) - PRE_SAMPLES, 0)
        acc.add(hit_spectra(force, np.atleast_2d(resp), fs_hz, k0, windows))
    return acc.frfset(estimator, meta=meta)


def per_hit_frfs(hits: Sequence[tuple[np.ndarray, np.ndarray]], fs_hz: float, windows: WindowSettings,
                 **kw) -> list[FRFSet]:
    """One FRF set per hit (no averaging), for the hit-to-hit consistency of the poles."""
    return [impact_frf([h], fs_hz, windows, **kw) for h in hits]
