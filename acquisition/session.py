"""The impact-test capture loop: plan, per-hit checks, operator decisions, averaging, recording.

For each measurement point of a :class:`TestPlan` the session configures the analyser (the
roving channel's point changes), then collects ``hits_per_point`` accepted hits:

    arm -> wait for trigger -> read block -> check the hit (force peak, pulse width, overloads,
    double hit) -> overloads and double hits are rejected automatically with the reason ->
    otherwise the hit is added to the average, its summary (with the coherence so far) is shown
    and the operator decides (``decide(summary) -> bool``; a terminal prompt a/r/q, or
    :func:`auto_accept`) -> on reject the average is rolled back -> the hit (accepted or not) is
    written to the recording and flushed -> next arm.

Spectra are computed from the raw counts times the recorded scaling
(:func:`acquisition.recording.scale_counts`), exactly as a replay of the recording does, so a
replay with the same windows reproduces the FRFs bit for bit.

The capture loop lives here, once; its parts are split by job: the plan (:mod:`acquisition.plan`),
the operator callbacks (:mod:`acquisition.operator`: any front end, terminal or browser, supplies
the accept/reject decision and receives a :class:`~acquisition.operator.HitSummary` per hit), link
recovery (:mod:`acquisition.link_recovery`), averaging (:mod:`acquisition.averaging`); the
recording format is :mod:`analysis.recording`. Every accepted hit is on disk before the next arm.

Plans: ``roving_hammer``: the hammer (force channel) moves over the points, the accelerometers
stay (each point is a new reference); ``roving_accelerometer``: the hammer stays at the reference,
the first response channel moves over the points (each point is a new output).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from analysis.errors import DiskFullError
from analysis.frf import FRFSet
from analysis.hit import Hit
from analysis.recording import merge_frfsets
from analysis.recording_writer import RecordingWriter
from analysis.spectra import WindowSettings

from .averaging import MeasurementAverage, average_recorded_hits, process_hit
from .errors import CommandFailed, TriggerTimeout
from .hitcheck import HitCheckSettings, check_hit
from .link_recovery import ILLEGAL_REQUEST, LINK_FAULTS, recover_link, retry_on_link_fault
from .operator import CallbackOperator, HitSummary, Operator, auto_accept
from .plan import FRF_QUANTITY, PLAN_MODES, Measurement, TestPlan, channel_table, eu_per_count_for, force_channel_of
from .session_errors import OperatorQuit, SessionError

__all__ = [
    "FRF_QUANTITY",
    "PLAN_MODES",
    "Measurement",
    "TestPlan",
    "HitSummary",
    "Operator",
    "CallbackOperator",
    "OperatorQuit",
    "SessionError",
    "where_to_strike",
    "hit_from_block",
    "MeasurementAverage",
    "SessionResult",
    "CaptureSession",
    "auto_accept",
    "channel_table",
    "eu_per_count_for",
    "force_channel_of",
    "process_hit",
    "average_recorded_hits",
    "retry_on_link_fault",
    "LINK_FAULTS",
]

log = logging.getLogger(__name__)


def where_to_strike(mode: str, m: Measurement, n_points: int) -> str:
    """The operator's instruction at the start of point ``m``: where the hammer (roving hammer) or
    the accelerometer (roving accelerometer) goes, and where to strike."""
    head = f"point {m.index + 1}/{n_points}: "
    if mode == "roving_accelerometer":
        return (head + f"move the accelerometer to {', '.join(m.outputs)}; strike at {m.reference} "
                "(the hammer stays there)")
    return head + f"move the hammer to {m.reference} and strike there (accelerometers at {', '.join(m.outputs)})"


def hit_from_block(block: Any, m: Measurement, force_channel: int, response_channels: Sequence[int]) -> Hit:
    """The analyser's block (``acquisition.driver.Block``) as a :class:`~analysis.hit.Hit` of
    measurement ``m``: the one place a block becomes a hit (scaling from the set-up's sensitivities)."""
    counts = np.asarray(block.counts)
    n_channels = len(m.setup.channels)
    if counts.dtype != np.int16 or counts.ndim != 2 or counts.shape[0] != n_channels:
        raise SessionError(f"block has counts {counts.dtype} {counts.shape}; expected int16 ({n_channels}, n)")
    return Hit(counts=counts, eu_per_count=eu_per_count_for(m.setup, block.volts_per_count),
               volts_per_count=np.asarray(block.volts_per_count, float), sample_rate_hz=float(block.sample_rate_hz),
               trigger_index=int(block.trigger_index), force_channel=force_channel,
               response_channels=list(response_channels), point=m.point, reference=m.reference, outputs=m.outputs,
               measurement=m.index, channel_names=tuple(f"{ch.name} {ch.point}" for ch in m.setup.channels),
               overload=np.asarray(block.overload, bool).ravel(), timestamp=float(block.timestamp),
               sequence=int(block.sequence), accepted=False)


@dataclass
class SessionResult:
    averages: list = field(default_factory=list)  # MeasurementAverage per completed/started point
    accepted: int = 0
    rejected: list = field(default_factory=list)  # (measurement, point, hit index, reasons)
    aborted: bool = False

    def frfset(self, estimator: str = "H1") -> FRFSet:
        return merge_frfsets([a.frfset(estimator) for a in self.averages if a.n_averages > 0])


class CaptureSession:
    """Run a test plan on an analyser (``acquisition.driver.Analyser`` or anything with the same
    ``identify/configure/arm/wait_for_trigger/read_block`` methods).

    The front end is ``operator`` (an :class:`~acquisition.operator.Operator`: ``decide``, ``progress``,
    ``on_hit``); without one, ``decide(summary) -> bool``, ``progress(text)`` (the lines to show: hit
    summaries, progress) and ``on_hit(summary)`` make it.

    ``gate(measurement, average, result, complete) -> bool`` (optional, e.g. the browser station) is
    asked before each arm and once the point has its hits: False ends the point now; it may block
    (pause), undo hits through :meth:`withdraw_last` / :meth:`withdraw_point` or raise
    :class:`OperatorQuit`. An operator object with a ``gate`` method supplies it too.
    """

    def __init__(
        self,
        analyser: Any,
        setup: Any,
        plan: TestPlan,
        *,
        writer: RecordingWriter | None = None,
        windows: WindowSettings = WindowSettings(),
        decide: Callable[[HitSummary], bool] = auto_accept,
        operator: Operator | None = None,
        check_settings: HitCheckSettings = HitCheckSettings(),
        progress: Callable[[str], None] | None = None,
        timeout_s: float = 10.0,
        max_attempts_factor: int = 10,
        max_timeouts: int = 3,
        max_link_failures: int = 8,
        resume_hits: Sequence[Any] = (),
        gate: Callable[[Measurement, MeasurementAverage, SessionResult, bool], bool] | None = None,
        on_hit: Callable[[HitSummary], None] | None = None,
    ) -> None:
        self.analyser = analyser
        self.setup = setup
        self.plan = plan
        self.writer = writer
        self.windows = windows.resolved(setup.block_size, setup.sample_rate_hz, setup.trigger.pretrigger_samples)
        self.operator: Operator = operator if operator is not None else CallbackOperator(decide, progress, on_hit)
        self.gate = gate if gate is not None else getattr(operator, "gate", None)
        self.check_settings = check_settings
        self.timeout_s = timeout_s
        self.max_attempts_factor = max_attempts_factor
        self.max_timeouts = max_timeouts
        self.max_link_failures = int(max_link_failures)
        self.link_faults = 0  # link faults met and recovered from (for reports)
        self.force_channel = force_channel_of(setup)
        self.response_channels = [i for i in range(len(setup.channels)) if i != self.force_channel]
        qs = {setup.channels[i].quantity for i in self.response_channels}
        if len(qs) != 1 or next(iter(qs)) not in FRF_QUANTITY:
            raise SessionError(f"response channels must share one motion quantity; got {sorted(qs)}")
        self.frf_quantity, self.frf_unit = FRF_QUANTITY[next(iter(qs))]
        self.measurements = plan.measurements(setup)
        self.resume_hits = [h for h in resume_hits if h.accepted]
        # every recorded hit (accepted or not): the hit count goes on from them, and the earlier
        # rejections stay in the result's list
        self.resume_rejected = [h for h in resume_hits if not h.accepted]
        self.hits_done = {i: sum(1 for h in resume_hits if h.measurement == i) for i in range(len(self.measurements))}
        for h in self.resume_hits:
            if not 0 <= h.measurement < len(self.measurements) or h.point != self.measurements[h.measurement].point:
                raise SessionError(f"recorded hit {h.index} (measurement {h.measurement}, point {h.point}) does not "
                                   "belong to this test plan: resume with the plan the recording was made with")

    def _event(self, level: str, message: str) -> None:
        getattr(log, level.lower() if level.lower() in ("info", "warning", "error") else "info")(message)
        if self.writer is not None:
            self.writer.log(level, message)

    def run(self) -> SessionResult:
        """Run the whole plan; returns the averages (also written to the recording)."""
        result = SessionResult()
        for h in self.resume_rejected:
            result.rejected.append((h.measurement, h.point, h.index, list(h.reasons)))
        self._event("INFO", f"test plan {self.plan.mode}: {len(self.measurements)} point(s), "
                            f"{self.plan.hits_per_point} hits each; windows: {self.windows.describe()}")
        try:
            for m in self.measurements:
                avg = MeasurementAverage(m.index, m.point, m.reference, m.outputs, self.frf_quantity,
                                         self.frf_unit, self.windows, self.setup.sample_rate_hz,
                                         record_s=self.setup.record_s, pretrigger_s=self.setup.pretrigger_s)
                result.averages.append(avg)
                done = self._resume_into(m, avg, result)
                if done:
                    continue
                self._measure(m, avg, result)
        except OperatorQuit as exc:
            if self._plan_complete(result):
                self._event("INFO", f"test finished with every point complete ({exc})")
            else:
                result.aborted = True
                self._event("WARNING", f"test ended early: {exc}")
            if self.writer is not None and result.averages and result.averages[-1].n_averages > 0:
                result.averages[-1].write(self.writer)
        self._event("INFO", f"session done: {result.accepted} hits accepted, {len(result.rejected)} rejected")
        return result

    def _plan_complete(self, result: SessionResult) -> bool:
        """Every point of the plan has its accepted hits (an operator who ends now ends nothing early)."""
        return (len(result.averages) == len(self.measurements)
                and all(a.n_averages >= self.plan.hits_per_point for a in result.averages))

    def _resume_into(self, m: Measurement, avg: MeasurementAverage, result: SessionResult) -> bool:
        """Add the recorded accepted hits of ``m`` to its average (resume); True when it is complete
        (its FRF results are then written again, so a crash between the last hit and the FRF loses nothing)."""
        mine = [h for h in self.resume_hits if h.measurement == m.index][: self.plan.hits_per_point]
        for h in mine:
            avg.add(h)
            result.accepted += 1
        if mine:
            self._event("INFO", f"resumed point {m.point}: {len(mine)} accepted hit(s) from the recording")
        if avg.n_averages >= self.plan.hits_per_point:
            if self.writer is not None:
                avg.write(self.writer)
            return True
        return False

    def _measure(self, m: Measurement, avg: MeasurementAverage, result: SessionResult) -> None:
        link_faults_here = 0
        try:
            self.analyser.configure(m.setup)
        except LINK_FAULTS as exc:
            link_faults_here = 1
            self._link_fault(m, exc, link_faults_here)
        self._event("INFO", f"point {m.index + 1}/{len(self.measurements)}: {self.plan.mode} at {m.point} "
                            f"(reference {m.reference}, outputs {', '.join(m.outputs)})")
        self.operator.progress(where_to_strike(self.plan.mode, m, len(self.measurements)))
        attempts = self.hits_done.get(m.index, 0)
        timeouts = 0
        while True:
            complete = avg.n_averages >= self.plan.hits_per_point
            if self.gate is not None and not self.gate(m, avg, result, complete):
                break
            if avg.n_averages >= self.plan.hits_per_point:
                break
            if attempts >= self.max_attempts_factor * self.plan.hits_per_point:
                raise SessionError(f"point {m.point}: {attempts} hits without {self.plan.hits_per_point} accepted; "
                                   "check the set-up (ranges, trigger level) and the hammer")
            try:
                self.analyser.arm()
                level = self.plan.level_of(avg.n_averages)
                how, series = ("", "") if level is None else (f" {level[0].upper()}",
                                                              f"; {level[0]} hit {level[1]}/{level[2]}")
                self.operator.progress(f"  strike {m.reference} now{how} (hit {attempts + 1} at this point{series})")
                try:
                    triggered = self.analyser.wait_for_trigger(self.timeout_s)
                except TriggerTimeout:
                    triggered = False
                block = None if triggered is False else self.analyser.read_block()
            except LINK_FAULTS as exc:
                link_faults_here += 1
                self._link_fault(m, exc, link_faults_here)
                continue
            if triggered is False:
                timeouts += 1
                self._event("WARNING", f"no trigger within {self.timeout_s:g} s at {m.point}: {self._trigger_advice()}")
                if timeouts >= self.max_timeouts:
                    raise SessionError(f"no trigger in {timeouts} tries at {m.point}: {self._trigger_advice()}")
                abort = getattr(self.analyser, "abort", None)
                if abort is not None:
                    try:
                        abort()
                    except LINK_FAULTS as exc:
                        link_faults_here += 1
                        self._link_fault(m, exc, link_faults_here)
                continue
            timeouts = 0
            attempts += 1
            assert block is not None  # triggered
            hit = hit_from_block(block, m, self.force_channel, self.response_channels)
            data = hit.data
            check = check_hit(data[self.force_channel], hit.sample_rate_hz, [bool(o) for o in hit.overload],
                              list(hit.channel_names), self.check_settings)
            summary = HitSummary(m.index, len(self.measurements), m.point, attempts, avg.n_averages,
                                 self.plan.hits_per_point, sum(1 for r in result.rejected if r[0] == m.index), check,
                                 average=avg, hit=hit)
            accepted = False
            reasons = list(check.verdict.reasons)
            if check.verdict.accept is not False:
                avg.acc.add(process_hit(hit, self.windows))
                summary.coherence_so_far = avg.mean_coherence(hi_hz=self.setup.bandwidth_hz)
                self.operator.progress(summary.text())
                try:
                    accepted = bool(self.operator.decide(summary))
                except OperatorQuit:
                    avg.acc.rollback()
                    self._write_hit(hit.with_verdict(False, ["test ended by the operator"], check.to_dict()))
                    raise
                if not accepted:
                    avg.acc.rollback()
                    reasons = ["rejected by the operator"]
            else:
                self.operator.progress(summary.text())
            try:
                idx = self._write_hit(hit.with_verdict(accepted, reasons, check.to_dict()))
            except DiskFullError:
                self._keep_point_on_full_disk(avg, accepted)
                raise
            summary.decision, summary.reasons, summary.hit_index = accepted, reasons, idx
            self.operator.on_hit(summary)
            if accepted:
                avg.hits.append(idx)
                result.accepted += 1
            else:
                result.rejected.append((m.index, m.point, idx, reasons))
                self._event("INFO", f"hit {idx + 1} at {m.point} rejected: {'; '.join(reasons)}")  # numbered from 1
            self.operator.progress(f"  progress: point {m.index + 1}/{len(self.measurements)}, "
                                   f"{avg.n_averages}/{self.plan.hits_per_point} accepted here, "
                                   f"{result.accepted} accepted and {len(result.rejected)} rejected in total; "
                                   f"per point {self.tally(result)}")
        if self.writer is not None and avg.n_averages > 0:
            avg.write(self.writer)
        self._event("INFO", f"point {m.point} done: {avg.n_averages} averages")

    def tally(self, result: SessionResult) -> str:
        """Accepted hits of every point of the plan against the hits asked, in plan order:
        ``right:6:-X 3/3, top:4:Z 2/3, left:9:Y 0/3`` (points not reached yet count 0)."""
        got = [a.n_averages for a in result.averages] + [0] * (len(self.measurements) - len(result.averages))
        return ", ".join(f"{m.point} {n}/{self.plan.hits_per_point}" for m, n in zip(self.measurements, got))

    def _trigger_advice(self) -> str:
        """What a missed trigger waited for and how to change it (the set-up's level, channel and unit)."""
        trig = self.setup.trigger
        ch = self.setup.channels[trig.channel]
        return (f"the {ch.name} channel did not cross the trigger level {trig.level:g} {ch.unit} ({trig.slope}); "
                f"strike harder, or lower [trigger] level in a --setup file (capture --print-setup > setup.toml "
                f"writes one); --timeout sets the wait")

    def withdraw_last(self, avg: MeasurementAverage, result: SessionResult, reason: str) -> int:
        """Undo the last accepted hit of ``avg`` (a front end's "undo"): out of the average, marked not
        accepted in the recording with ``reason``; returns its index."""
        if not avg.hits:
            raise SessionError(f"point {avg.point} has no accepted hit to undo")
        idx = avg.hits.pop()
        avg.acc.rollback()
        result.accepted -= 1
        result.rejected.append((avg.index, avg.point, idx, [reason]))
        if self.writer is not None:
            self.writer.withdraw_hit(idx, reason)
        self._event("INFO", f"hit {idx + 1} at {avg.point} withdrawn: {reason}")
        return idx

    def withdraw_point(self, avg: MeasurementAverage, result: SessionResult, reason: str) -> None:
        """Withdraw every accepted hit of ``avg`` (measure the point again)."""
        while avg.hits:
            self.withdraw_last(avg, result, reason)

    def _link_fault(self, m: Measurement, exc: Exception, faults_here: int) -> None:
        """Recover from a link fault at ``m`` (:func:`acquisition.link_recovery.recover_link`); a request
        the analyser refuses (ILLEGAL REQUEST) is raised at once."""
        if isinstance(exc, CommandFailed) and exc.sense_key == ILLEGAL_REQUEST:
            raise exc  # the analyser refuses the request itself: retrying cannot help
        self.link_faults += 1
        recover_link(self.analyser, m.setup, m.point, exc, faults_here,
                     self.max_attempts_factor * self.plan.hits_per_point, self.max_link_failures, self._event)

    def _keep_point_on_full_disk(self, avg: MeasurementAverage, hit_in_average: bool) -> None:
        """The disk is full (the hit was not written): the FRFs of the point's hits written so far go
        to the recording, in the room the writer kept for them, so every accepted hit is in the FRFs."""
        if hit_in_average:
            avg.acc.rollback()
        if self.writer is not None and avg.n_averages > 0:
            try:
                avg.write(self.writer)
            except DiskFullError:
                log.warning("no room left for the FRFs of point %s: resume the test to compute them", avg.point)

    def _write_hit(self, hit: Hit) -> int:
        return -1 if self.writer is None else self.writer.write_hit(hit)
