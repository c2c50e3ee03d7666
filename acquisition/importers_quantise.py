"""16-bit counts of imported time data: :func:`quantize`, the check that nothing is lost, the hits.

Each hit and channel gets ``eu_per_count = max|x| / 32767`` (a full-scale range fitted to the hit);
the quantisation error is below 2e-5 of the peak, far under the noise of any hammer test. A hit
where that is not so (one glitch far above the rest of a channel, which the counts would turn into
zeros) is refused (:func:`int16_rest_change`). :func:`imported_hits` makes the
:class:`analysis.hit.Hit` of each block once the channel roles are fixed.
"""
from __future__ import annotations

import time

import numpy as np

from analysis.hit import Hit

from .errors import ImportDataError
from .importers_data import ImportedTest
from .importers_roles import ChannelRoles

__all__ = ["quantize", "int16_rest_change", "INT16_REST_FRACTION", "INT16_MAX_REST_CHANGE", "INT16_MIN_PEAK",
           "INT16_MAX_PEAK", "detect_trigger", "imported_hits"]

def quantize(data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """int16 counts and EU per count per channel for ``data[n_ch, n]`` (full scale = max |x|)."""
    d = np.asarray(data, float)
    peak = np.max(np.abs(d), axis=1)
    eu = np.where(peak > 0, peak / 32767.0, 1.0)
    counts = np.clip(np.rint(d / eu[:, None]), -32768, 32767).astype(np.int16)
    return counts, eu


#: the part of a channel :func:`int16_rest_change` looks at: the samples below this fraction of its peak
INT16_REST_FRACTION = 1e-2
#: the largest rms change 16-bit counts may make to that part of a channel, relative to its rms; real
#: hammer tests stay near 0.02 (the rest spans tens of counts), a glitch 1e5 times the signal gives 1
INT16_MAX_REST_CHANGE = 0.1


def int16_rest_change(data: np.ndarray, counts: np.ndarray, eu_per_count: np.ndarray) -> np.ndarray:
    """Per channel of ``data[n_ch, n]`` stored as ``counts * eu_per_count`` (:func:`quantize`): the
    rms of the rounding error over the samples below :data:`INT16_REST_FRACTION` of the channel's
    peak, relative to their rms (0 where those samples are all zero or there are none). Near 1 means
    the counts lose that part of the channel: one sample (a glitch) sets a scale the rest is below."""
    d = np.asarray(data, float)
    out = np.zeros(d.shape[0])
    for c in range(d.shape[0]):
        ax = np.abs(d[c])
        rest = ax < INT16_REST_FRACTION * np.max(ax)
        scale = float(np.max(ax[rest])) if np.any(rest) else 0.0
        if scale > 0:  # the rounding error never exceeds the sample: both ratios stay <= 1 (no overflow)
            err = (counts[c, rest] * eu_per_count[c] - d[c, rest]) / scale
            out[c] = float(np.sqrt(np.mean(err ** 2) / np.mean((d[c, rest] / scale) ** 2)))
    return out


#: the smallest channel peak :func:`quantize` scales (a smaller one would need a subnormal step)
INT16_MIN_PEAK = float(np.finfo(float).tiny) * 32767.0
#: the largest channel peak :func:`quantize` scales (counts * step must stay a finite float)
INT16_MAX_PEAK = float(np.finfo(float).max) / 2


def _quantized(test: ImportedTest, k: int, data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`quantize` of hit ``k``, refused (:class:`ImportDataError` naming the hit, channel and
    sample) when the 16-bit counts would not keep a channel: its peak too small or too large to
    scale, or part of it lost beside a far larger sample (:func:`int16_rest_change`)."""
    peaks = np.max(np.abs(data), axis=1)
    for c in np.flatnonzero(((peaks > 0) & (peaks < INT16_MIN_PEAK)) | (peaks > INT16_MAX_PEAK)):
        raise ImportDataError(f"{test.source}: hit {k + 1}, channel {c + 1} ({test.channels[c].get('name', '')}): "
                              f"its largest sample is {peaks[c]:.3g}, outside what 16-bit samples can be scaled to "
                              f"({INT16_MIN_PEAK:.3g} to {INT16_MAX_PEAK:.3g}); check the units of the file")
    counts, eu = quantize(data)
    change = int16_rest_change(data, counts, eu)
    for c in np.flatnonzero(change > INT16_MAX_REST_CHANGE):
        x = np.abs(data[c])
        i = int(np.argmax(x))
        rest = x < INT16_REST_FRACTION * x[i]
        name = test.channels[c].get("name", f"ch{c + 1}")
        raise ImportDataError(
            f"{test.source}: hit {k + 1}, channel {c + 1} ({name}): sample {i + 1} is {data[c, i]:.3g} while "
            f"{int(np.sum(rest))} of its {x.size} samples stay within +-{np.max(x[rest]):.3g}; the recording's "
            f"16-bit samples scaled to that peak (step {eu[c]:.3g}) would change those by {change[c]:.0%} rms: "
            "remove the glitch from the file (or cut the block short of it) and import again")
    return counts, eu


def detect_trigger(force: np.ndarray, level: float = 0.1) -> int:
    """First sample where |force| reaches ``level`` times its peak (the window origin of an import)."""
    f = np.abs(np.asarray(force, float))
    return int(np.argmax(f >= level * f.max())) if f.max() > 0 else 0


def imported_hits(test: ImportedTest, roles: ChannelRoles) -> list[Hit]:
    """The hits of ``test`` with the channel ``roles`` (:func:`channel_roles`), not yet checked:
    each block quantised to int16 counts (:func:`quantize`), its trigger from the file or found on
    the force (:func:`detect_trigger`), ``volts_per_count`` from the sensitivities (NaN unknown),
    ``sequence`` the import order, ``timestamp`` the time of the import (s since the epoch).
    Raises :class:`ImportDataError` naming the hit, channel and sample when the 16-bit counts would
    lose part of a channel (:func:`int16_rest_change`, e.g. a glitch far above the rest)."""
    chans, fch, rch = roles.channels, roles.force_channel, roles.response_channels
    ref, outs = roles.reference, roles.outputs
    names = tuple(str(c["name"]) for c in chans)
    sens = np.array([c["sensitivity"] for c in chans], float)
    hits = []
    for k, data in enumerate(test.hits):
        trig = test.trigger_indices[k] if k < len(test.trigger_indices) else detect_trigger(data[fch])
        counts, eu = _quantized(test, k, data)
        hits.append(Hit(counts=counts, eu_per_count=eu, volts_per_count=eu * sens * 1e-3, sample_rate_hz=test.fs_hz,
                        trigger_index=trig, force_channel=fch, response_channels=rch, point=ref, reference=ref,
                        outputs=outs, measurement=0, channel_names=names, timestamp=time.time(), sequence=k))
    return hits
