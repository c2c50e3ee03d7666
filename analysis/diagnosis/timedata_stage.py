"""The time-data stage of the diagnosis: a recording's accepted hits, per reference point, through the
detectors of :mod:`analysis.diagnosis.timedata` and, with a simulation at the hits' points, their
held-out gains (:func:`analysis.diagnosis.timedata_gain.diagnose_time_effects`)."""
from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..modal import ModalModel
from .rule import DEFAULT_RULE, DecisionRule

__all__ = ["time_data_causes"]

log = logging.getLogger(__name__)


def time_data_causes(path: str | Path, band: tuple, base: ModalModel | None = None,
                     rule: DecisionRule = DEFAULT_RULE) -> list:
    """Time-data causes (:mod:`analysis.diagnosis.timedata`) of a recording's accepted hits (those its
    FRFs were made from; rejected hits changed nothing), per reference point; [] when the file is not
    a recording or holds no accepted hits. With ``base`` (the simulation as a receptance
    pole-residue model holding the hits' points), each cause also gets its held-out ``gain_db``,
    ``error_before_db``, ``error_after_db``, ``significant`` and ``counts`` from
    :func:`analysis.diagnosis.timedata_gain.diagnose_time_effects` (re-simulated or hits excluded), judged
    by ``rule`` (the diagnosis' one :class:`~analysis.diagnosis.rule.DecisionRule`)."""
    from ..inputs import detect_format
    from .timedata import diagnose_hits

    if detect_format(path) != "recording":
        return []
    from ..recording import Recording, RecordingError

    groups: dict = {}
    try:
        with Recording(path) as rec:
            for h in rec.hits(accepted_only=True, skip_damaged=True):
                groups.setdefault((h.reference, h.sample_rate_hz, h.data.shape), []).append(h)
    except (RecordingError, OSError) as exc:
        log.warning("time data of %s not read: %s", path, exc)
        return []
    out = []
    for (ref, fs, _), hits in groups.items():
        if len(hits) < 2:
            continue
        force = np.array([h.data[h.force_channel] for h in hits])
        resp = np.array([h.data[h.response_channels] for h in hits])
        flags = np.array([h.overload for h in hits])
        gains = _time_gains(force, resp, fs, band, base, hits[0].outputs, ref, flags, rule) if base is not None else {}
        for c in diagnose_hits(force, resp, fs, band, overload_flags=flags):
            c["reference"] = ref
            c.update(gains.get(c["effect"], {}))
            out.append(c)
    return sorted(out, key=lambda c: (not c["present"], -c.get("gain_db", 0.0)))


def _time_gains(force: np.ndarray, resp: np.ndarray, fs: float, band: tuple, base: ModalModel,
                outputs: Sequence[str], ref: str, flags: np.ndarray, rule: DecisionRule) -> dict:
    """Held-out gains of the time-data effects per effect name ({} when the simulation cannot be used)."""
    from dataclasses import replace

    from .timedata_gain import diagnose_time_effects

    try:
        oi = [list(base.outputs).index(o) for o in outputs]
        ri = list(base.references).index(ref)
        sub = replace(base, residues=base.residues[oi][:, [ri]], outputs=tuple(outputs), references=(ref,))
        d = diagnose_time_effects(force, resp, fs, sub, band, overload_flags=flags, outputs=outputs, reference=ref,
                                  rule=rule)
    except (ValueError, IndexError) as exc:
        log.info("time-data gains of %s not measured: %s", ref, exc)
        return {}
    keys = ("gain_db", "error_before_db", "error_after_db", "z", "significant", "counts", "kind")
    return {c["effect"]: {k: c[k] for k in keys} for c in d["causes"]}
