"""The noise of a recording's averaged FRFs measured from its own hits.

Each accepted hit at a point gives one FRF estimate ``H_i = G_fx,i / G_ff,i`` (the recording's windows,
:func:`analysis.spectra.hit_spectra`); with ``n`` hits the averaged FRF's noise variance per line is
about ``sum_i |H_i - mean H|^2 / ((n - 1) n)``. Its weighted median over lines and FRFs, on the scale
of :func:`analysis.diagnosis.compare.noise_level`, is a direct estimate that needs no assumption about
how the noise is correlated from line to line (the second-difference estimate does) and includes
everything that varies from hit to hit (sensor noise, strike position and direction, the hammer).
"""
from __future__ import annotations

import logging
from collections.abc import Collection
from pathlib import Path

import numpy as np

from ..frf import FRFSet
from ..recording import Recording
from ..spectra import hit_spectra
from .rule import db

__all__ = ["hit_scatter_noise_db"]

log = logging.getLogger(__name__)


def hit_scatter_noise_db(path: str | Path, measured: FRFSet, weights: np.ndarray,
                         skip: Collection[int] = ()) -> float | None:
    """Noise level (dB) of ``measured`` (FRFs of the recording ``path``, in its band and point order)
    from the scatter of the recording's accepted hits but those whose index is in ``skip`` (hits the
    FRFs were made without); None when a point has fewer than two hits or the hits cannot be matched
    to the FRFs."""
    try:
        with Recording(path) as rec:
            windows = rec.windows
            pre = int(rec.setup["trigger"]["pretrigger_samples"])
            per_ref: dict = {}
            for h in rec.hits(accepted_only=True, skip_damaged=True):
                if h.index in skip:
                    continue
                sp = hit_spectra(h.data[h.force_channel], h.data[h.response_channels], h.sample_rate_hz, pre, windows)
                per_ref.setdefault(h.reference, []).append((tuple(h.outputs), sp.freq_hz, sp.Gfx / sp.Gff))
    except (OSError, KeyError, TypeError, ValueError) as exc:
        log.info("hit scatter of %s not measured: %s", path, exc)
        return None
    f = measured.freq_hz
    var = np.zeros(measured.H.shape)
    for j, ref in enumerate(measured.references):
        hits = per_ref.get(ref, [])
        if len(hits) < 2:
            return None
        outs, fh, _ = hits[0]
        idx = np.searchsorted(fh, f)
        if not np.allclose(fh[np.clip(idx, 0, fh.size - 1)], f):
            return None
        try:
            rows = [outs.index(o) for o in measured.outputs]
        except ValueError:
            return None
        H = np.array([h[2][rows][:, idx] for h in hits])
        n = H.shape[0]
        var[:, j] = np.sum(np.abs(H - H.mean(axis=0)) ** 2, axis=0) / ((n - 1) * n)
    q = float(np.median(weights * var)) / np.log(2)
    return db(q)
