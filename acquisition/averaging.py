"""Averaging of accepted hits per measurement point: the one path from a hit's EU data to its
spectra (:func:`process_hit`), the running average (:class:`MeasurementAverage`) and the
recomputation from a recording (:func:`average_recorded_hits`)."""

from __future__ import annotations

from typing import Any, Optional, Sequence

import numpy as np

from analysis.frf import FRFSet
from analysis.spectra import FRFAccumulator, HitSpectra, WindowSettings, hit_spectra

from .plan import FRF_QUANTITY
from analysis.recording import RecordingWriter
from .session_errors import SessionError

__all__ = ["process_hit", "MeasurementAverage", "average_recorded_hits"]


def process_hit(
    data: np.ndarray, fs_hz: float, trigger_index: int, force_channel: int, response_channels: Sequence[int],
    windows: WindowSettings,
) -> HitSpectra:
    """Windows and spectra of one hit (``data[n_ch, n]`` in EU): the one path used by capture, replay, import."""
    return hit_spectra(data[force_channel], data[list(response_channels)], fs_hz, trigger_index, windows)


# -- averaging per measurement --------------------------------------------------------------------
class MeasurementAverage:
    """The running average of one measurement point and the indices of its accepted hits.

    ``sample_rate_hz``: the acquisition's sample rate (Hz), carried from the set-up or the recorded
    hits so that consumers (the alias-free band fs / 2.56) never recompute it from the frequency axis.
    """

    def __init__(self, index: int, point: str, reference: str, outputs: Sequence[str], quantity: str, unit: str,
                 windows: WindowSettings, sample_rate_hz: Optional[float] = None) -> None:
        self.index = int(index)
        self.point = str(point)
        self.reference = str(reference)
        self.outputs = tuple(outputs)
        self.quantity = quantity
        self.unit = unit
        self.windows = windows
        self.sample_rate_hz = None if sample_rate_hz is None else float(sample_rate_hz)
        self.acc = FRFAccumulator(self.outputs, self.reference, quantity, unit)
        self.hits: list[int] = []

    @property
    def n_averages(self) -> int:
        return self.acc.n_averages

    def frfset(self, estimator: str = "H1") -> FRFSet:
        return self.acc.frfset(estimator, meta={"measurement": f"m{self.index:03d}", "point": self.point,
                                                "windows": self.windows.to_dict()},
                               sample_rate_hz=self.sample_rate_hz)

    def mean_coherence(self, lo_hz: float = 0.0, hi_hz: float = np.inf) -> Optional[float]:
        """Mean coherence over lo..hi Hz and the outputs that carry a signal (None before two hits:
        one hit gives 1 trivially)."""
        if self.acc.n_averages < 2:
            return None
        f = self.acc.freq_hz
        sel = (f >= lo_hz) & (f <= hi_hz) & (f > 0)
        live = np.any(self.acc.spectra()[1] > 0, axis=1)  # outputs that record anything at all
        if not live.any():
            return 0.0
        return float(np.mean(self.acc.coherence()[live][:, sel]))

    def write(self, writer: RecordingWriter) -> None:
        Gff, Gxx, Gfx = self.acc.spectra()
        writer.write_frf(
            self.index, point=self.point, freq_hz=self.acc.freq_hz, H1=self.acc.h1(), H2=self.acc.h2(),
            coherence=self.acc.coherence(), Gff=Gff, Gxx=Gxx, Gfx=Gfx, outputs=self.outputs,
            reference=self.reference, n_averages=self.n_averages, hits=self.hits, quantity=self.quantity,
            unit=self.unit, windows=self.windows, exp_window_tau_s=self.acc.tau_s,
            sample_rate_hz=self.sample_rate_hz,
        )



def average_recorded_hits(
    hits: Sequence[Any], windows: WindowSettings, channels: Sequence[dict],
) -> list[MeasurementAverage]:
    """Recompute the averages of recorded hits (``analysis.recording.RecordedHit``), grouped by
    measurement in order, with ``windows`` (a decay-fraction exponential is resolved from the first
    hit's block layout). ``channels`` is the recording's channel table (for quantity and unit)."""
    hits = list(hits)
    if not hits:
        raise SessionError("no accepted hits to average: the recording (after exclusions) holds none")
    h0 = hits[0]
    win = windows.resolved(h0.counts.shape[1], h0.sample_rate_hz, h0.trigger_index)
    qs = {str(channels[i]["quantity"]) for i in h0.response_channels} if channels else {"acceleration"}
    if len(qs) != 1 or next(iter(qs)) not in FRF_QUANTITY:
        raise SessionError(f"response channels must share one motion quantity; got {sorted(qs)}")
    quantity, unit = FRF_QUANTITY[next(iter(qs))]
    units = {str(channels[i].get("unit", "")) for i in h0.response_channels} if channels else set()
    funit = str(channels[h0.force_channel].get("unit", "N")) if channels else "N"
    if units and units != {"m/s^2"} and len(units) == 1:
        unit = f"{next(iter(units))}/{funit}"
    groups: dict[int, MeasurementAverage] = {}
    for h in hits:
        avg = groups.get(h.measurement)
        if avg is None:
            avg = MeasurementAverage(h.measurement, h.point, h.reference, h.outputs, quantity, unit, win,
                                     h.sample_rate_hz)
            groups[h.measurement] = avg
        spectra = process_hit(h.data, h.sample_rate_hz, h.trigger_index, h.force_channel, h.response_channels, win)
        avg.acc.add(spectra)
        avg.hits.append(h.index)
    return [groups[k] for k in sorted(groups)]
