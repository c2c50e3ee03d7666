"""Hits that do not belong with the others of their point, and the FRFs made without them.

A recording's FRF at a point is the average of its accepted hits (H1 = sum G_fx / sum G_ff). A hit
that landed elsewhere (a neighbouring node, another direction) or whose force the window cut (a
double hit the checks let through) measures another FRF: averaged in, it moves the point's FRF by a
fraction of that difference, the same on every line, and the comparison with a simulation then
reads it as a cause (a sensor's sensitivity, a missing mode at a mode the two strike points see
differently). Sensor noise alone never does that: every hit of a point measures the same FRF.

The test, per group of hits with the same reference and outputs (at least
:attr:`~.rule.DecisionRule.stray_min_hits` hits), on the diagnosis' band and line weights (``w``, the relative error's):

* the distance of two hits ``i, j`` is the median over lines and outputs of ``w |H_i - H_j|^2``,
  divided by ``1/g_i + 1/g_j`` (``g``: each hit's median force power relative to the group's, so a
  soft hit's larger noise is not taken for a difference);
* the consensus hit is the one with the smallest median distance to the others; the group's spread
  is its distance to its nearest other hit;
* a hit is stray when its distance to the consensus hit exceeds the spread by
  :attr:`~.rule.DecisionRule.stray_excess_db` (6 dB: four times the spread; two hits of the same FRF differ by their
  noise alone, whose median over hundreds of lines varies by well under 1 dB), and only while the
  stray hits are fewer than half of the group (otherwise there is no consensus to keep: e.g. soft and
  hard hits of a nonlinear joint, which the level stage compares instead).

The FRFs of a group with stray hits are made again from its other hits with the recording's
estimator (H1 or H2, whichever reproduces the stored FRFs; a group whose stored FRFs neither
reproduces is left as stored), the coherence with them.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..frf import FRFSet
from ..recording import Recording, RecordingError
from ..spectra import hit_spectra
from .rule import DEFAULT_RULE, DecisionRule

__all__ = ["StrayHits", "stray_excess_db", "without_stray_hits"]

log = logging.getLogger(__name__)



@dataclass(frozen=True)
class StrayHits:
    """The measured FRFs without the stray hits (``measured``) and what was left out: ``dropped`` one
    ``{"reference", "outputs", "hits" (the recording's hit indices), "n_hits" (of the group),
    "excess_db" (each dropped hit's distance to the consensus above the spread, dB)}`` per group, and
    ``kept``: reference -> the recording's indices of the hits kept at it (for the hits' own noise)."""

    measured: FRFSet
    dropped: list = field(default_factory=list)
    kept: dict = field(default_factory=dict)

    def cause(self) -> dict:
        """The time-data cause that says it (``kind`` data_quality, ``present``)."""
        n = sum(len(d["hits"]) for d in self.dropped)
        where = "; ".join(f"hit(s) {', '.join(str(i) for i in d['hits'])} of {d['n_hits']} at {d['reference']} "
                          f"({', '.join(f'+{e:.0f} dB' for e in d['excess_db'])} from the others)" for d in self.dropped)
        return {"effect": "stray_hit", "kind": "data_quality", "present": True, "counts": True, "significant": True,
                "reference": ", ".join(d["reference"] for d in self.dropped),
                "parameters": {"hits": [i for d in self.dropped for i in d["hits"]],
                               "references": [d["reference"] for d in self.dropped]},
                "evidence": (f"{n} hit(s) measured another FRF than the other hits of their point: {where}; "
                             "struck elsewhere (a neighbouring node, another direction) or cut by the force window; "
                             "the FRFs were compared without them (measure the point again to replace them)")}


def stray_excess_db(H: np.ndarray, force_power: np.ndarray, weights: np.ndarray,
                    min_hits: int = DEFAULT_RULE.stray_min_hits) -> np.ndarray:
    """Each hit's distance (dB) to the consensus hit above the group's spread (module docs): ``H``
    (n_hits, n_out, n_freq) the hits' FRFs, ``force_power`` (n_hits,) their force power (any common
    scale, e.g. the median of G_ff), ``weights`` (n_out, n_freq) the line weights. Zero for the
    consensus hit and for every hit of a group of fewer than ``min_hits``."""
    n = H.shape[0]
    if n < min_hits:
        return np.zeros(n)
    g = np.asarray(force_power, float) / float(np.median(force_power))
    D = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1, n):
            d = float(np.median(weights * np.abs(H[i] - H[j]) ** 2)) / (1.0 / g[i] + 1.0 / g[j])
            D[i, j] = D[j, i] = d
    off = ~np.eye(n, dtype=bool)
    centre = int(np.argmin([np.median(D[i][off[i]]) for i in range(n)]))
    spread = float(np.min(D[centre][off[centre]]))
    excess = 10 * np.log10(np.maximum(D[centre], 1e-300) / max(spread, 1e-300))
    excess[centre] = 0.0
    return np.asarray(excess)


def _estimate(Gff: np.ndarray, Gxx: np.ndarray, Gfx: np.ndarray, estimator: str) -> np.ndarray:
    """H1 (sum G_fx / sum G_ff) or H2 (sum G_xx / sum conj(G_fx)) of the hits' spectra (n_hits first)."""
    if estimator == "H1":
        return Gfx.sum(0) / Gff.sum(0)[None, :]
    return Gxx.sum(0) / np.conj(Gfx.sum(0))


def without_stray_hits(path: str | Path, measured: FRFSet, weights: np.ndarray,
                       rule: DecisionRule = DEFAULT_RULE) -> StrayHits | None:
    """``measured`` (the FRFs of the recording ``path`` in the diagnosis' band, ``weights`` its line
    weights) made again without the stray hits of each group (module docs); None when no hit is stray
    or the recording's hits cannot be read or matched to the FRFs."""
    groups: dict = {}
    try:
        with Recording(path) as rec:
            windows = rec.windows
            pre = int(rec.setup["trigger"]["pretrigger_samples"])
            for h in rec.hits(accepted_only=True, skip_damaged=True):
                sp = hit_spectra(h.data[h.force_channel], h.data[h.response_channels], h.sample_rate_hz, pre, windows)
                groups.setdefault((h.reference, tuple(h.outputs)), []).append((h.index, sp))
    except (RecordingError, OSError, KeyError, TypeError, ValueError) as exc:
        log.info("stray hits of %s not looked for: %s", path, exc)
        return None
    f = measured.freq_hz
    H = measured.H.copy()
    coh = None if measured.coherence is None else measured.coherence.copy()
    dropped: list[dict] = []
    kept: dict[str, list[int]] = {}
    for (ref, outs), hits in groups.items():
        kept.setdefault(ref, []).extend(i for i, _ in hits)
        if ref not in measured.references or len(hits) < rule.stray_min_hits:
            continue
        fh = hits[0][1].freq_hz
        idx = np.searchsorted(fh, f)
        if np.any(idx >= fh.size) or not np.allclose(fh[np.clip(idx, 0, fh.size - 1)], f):
            continue
        pairs = [(r, k) for k, o in enumerate(outs) for r, mo in enumerate(measured.outputs) if mo == o]
        if not pairs:
            continue
        rows, cols = [p[0] for p in pairs], [p[1] for p in pairs]
        j = measured.references.index(ref)
        Gff = np.array([sp.Gff[idx] for _, sp in hits])
        Gxx = np.array([sp.Gxx[cols][:, idx] for _, sp in hits])
        Gfx = np.array([sp.Gfx[cols][:, idx] for _, sp in hits])
        est = next((e for e in ("H1", "H2") if np.allclose(_estimate(Gff, Gxx, Gfx, e), H[rows, j], rtol=1e-6,
                                                           atol=0.0)), None)
        if est is None:
            log.info("stray hits at %s not looked for: the stored FRFs are not the hits' H1 or H2", ref)
            continue
        excess = stray_excess_db(Gfx / Gff[:, None, :], np.median(Gff, axis=1), weights[rows, j],
                                 rule.stray_min_hits)
        stray = excess > rule.stray_excess_db
        if not stray.any() or 2 * int(stray.sum()) >= len(hits):
            continue
        keep = ~stray
        H[rows, j] = _estimate(Gff[keep], Gxx[keep], Gfx[keep], est)
        if coh is not None:
            coh[rows, j] = np.abs(Gfx[keep].sum(0)) ** 2 / (Gff[keep].sum(0)[None, :] * Gxx[keep].sum(0))
        kept[ref] = [i for i in kept[ref] if i not in {hits[k][0] for k in np.flatnonzero(stray)}]
        dropped.append({"reference": ref, "outputs": list(outs), "hits": [int(hits[k][0]) for k in np.flatnonzero(stray)],
                        "n_hits": len(hits), "excess_db": [float(excess[k]) for k in np.flatnonzero(stray)]})
    if not dropped:
        return None
    meta = {**measured.meta, "stray_hits": dropped}
    return StrayHits(measured=replace(measured, H=H, coherence=coh, meta=meta), dropped=dropped, kept=kept)
