"""Averaging of accepted hits per measurement point: the one path from a hit's EU data to its
spectra (:func:`process_hit`), the running average (:class:`MeasurementAverage`) and the
recomputation from a recording (:func:`average_recorded_hits`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from analysis.frf import FRFSet
from analysis.hit import Hit
from analysis.recording_writer import FRFPoint, RecordingWriter
from analysis.spectra import FRFAccumulator, HitSpectra, WindowSettings, hit_spectra

from .plan import FRF_QUANTITY
from .session_errors import SessionError

__all__ = ["process_hit", "MeasurementAverage", "average_recorded_hits"]


def process_hit(hit: Hit, windows: WindowSettings) -> HitSpectra:
    """Windows and spectra of one hit: the one path used by capture, station, replay and import."""
    data = hit.data
    return hit_spectra(data[hit.force_channel], data[hit.response_channels], hit.sample_rate_hz, hit.trigger_index,
                       windows)


# -- averaging per measurement --------------------------------------------------------------------
class MeasurementAverage:
    """The running average of one measurement point and the indices of its accepted hits.

    ``sample_rate_hz``: the acquisition's sample rate (Hz), carried from the set-up or the recorded
    hits so that consumers (the analyser's band) never recompute it from the frequency axis;
    ``record_s``, ``pretrigger_s``: the analyser's record length and pre-trigger (s) when known.
    """

    def __init__(self, index: int, point: str, reference: str, outputs: Sequence[str], quantity: str, unit: str,
                 windows: WindowSettings, sample_rate_hz: float | None = None, *,
                 record_s: float | None = None, pretrigger_s: float | None = None) -> None:
        self.index = int(index)
        self.point = str(point)
        self.reference = str(reference)
        self.outputs = tuple(outputs)
        self.quantity = quantity
        self.unit = unit
        self.windows = windows
        self.sample_rate_hz = None if sample_rate_hz is None else float(sample_rate_hz)
        self.record_s = record_s
        self.pretrigger_s = pretrigger_s
        self.acc = FRFAccumulator(self.outputs, self.reference, quantity, unit)
        self.hits: list[int] = []

    @property
    def n_averages(self) -> int:
        return self.acc.n_averages

    def frfset(self, estimator: str = "H1") -> FRFSet:
        return self.acc.frfset(estimator, meta={"measurement": f"m{self.index:03d}", "point": self.point,
                                                "windows": self.windows.to_dict()},
                               sample_rate_hz=self.sample_rate_hz, record_s=self.record_s,
                               pretrigger_s=self.pretrigger_s)

    def add(self, hit: Hit) -> None:
        """Add ``hit`` to the average (its index, when written, to :attr:`hits`)."""
        self.acc.add(process_hit(hit, self.windows))
        if hit.index >= 0:
            self.hits.append(hit.index)

    def mean_coherence(self, lo_hz: float = 0.0, hi_hz: float = np.inf) -> float | None:
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
        """Write the point's FRF results (H1, H2, coherence, spectra) to the recording."""
        writer.write_frf(FRFPoint(self.index, self.point, tuple(self.hits)), self.frfset("H1"),
                         self.acc.averaged(self.windows))


def average_recorded_hits(
    hits: Sequence[Hit], windows: WindowSettings, channels: Sequence[dict], *,
    record_s: float | None = None, pretrigger_s: float | None = None,
) -> list[MeasurementAverage]:
    """Recompute the averages of recorded hits, grouped by measurement in order, with ``windows``
    (an end-fraction exponential is resolved from the first hit's block layout). ``channels`` is
    the recording's channel table (for quantity and unit); ``record_s``, ``pretrigger_s`` (s) the
    analyser's record, carried by the FRF sets."""
    hits = list(hits)
    if not hits:
        raise SessionError("no accepted hits to average: the recording (after exclusions) holds none")
    h0 = hits[0]
    win = windows.resolved(h0.n_samples, h0.sample_rate_hz, h0.trigger_index)
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
                                     h.sample_rate_hz, record_s=record_s, pretrigger_s=pretrigger_s)
            groups[h.measurement] = avg
        avg.add(h)
    return [groups[k] for k in sorted(groups)]
