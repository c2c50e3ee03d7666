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
(:func:`analysis.recording.scale_counts`), exactly as a replay of the recording does, so a
replay with the same windows reproduces the FRFs bit for bit.

Plans: ``roving_hammer``: the hammer (force channel) moves over the points, the accelerometers
stay (each point is a new reference); ``roving_accelerometer``: the hammer stays at the reference,
the first response channel moves over the points (each point is a new output).
"""
from __future__ import annotations

import dataclasses
import logging
import sys
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Optional, Sequence, TextIO

import numpy as np

from analysis.frf import FRFSet
from analysis.points import parse_point
from analysis.spectra import FRFAccumulator, HitSpectra, WindowSettings, hit_spectra

from .errors import CommandFailed, ImpactlabError, ProtocolError, TransportError, TriggerTimeout
from .hitcheck import HitCheck, HitCheckSettings, check_hit
from analysis.recording import RecordingWriter, merge_frfsets, scale_counts

__all__ = [
    "FRF_QUANTITY",
    "Measurement",
    "TestPlan",
    "HitSummary",
    "OperatorQuit",
    "SessionError",
    "MeasurementAverage",
    "SessionResult",
    "CaptureSession",
    "auto_accept",
    "terminal_decider",
    "read_key",
    "channel_table",
    "eu_per_count_for",
    "process_hit",
    "retry_on_link_fault",
    "LINK_FAULTS",
]

log = logging.getLogger(__name__)

#: channel quantity -> (FRF quantity, FRF unit for SI data)
FRF_QUANTITY = {
    "acceleration": ("accelerance", "(m/s^2)/N"),
    "velocity": ("mobility", "(m/s)/N"),
    "displacement": ("receptance", "m/N"),
}
PLAN_MODES = ("roving_hammer", "roving_accelerometer")
#: errors after which the session recovers (abort, set up again, re-arm) instead of ending
LINK_FAULTS = (ProtocolError, TransportError, CommandFailed)
ILLEGAL_REQUEST = 0x5  # SCSI sense key: the request itself is wrong (not a link fault)


class OperatorQuit(ImpactlabError):
    """The operator ended the test (key q); the session keeps what it has."""


class SessionError(ImpactlabError, RuntimeError):
    """The session cannot go on (no triggers, every hit rejected...); the message says why."""


def retry_on_link_fault(fn: Callable[[], Any], attempts: int = 5) -> Any:
    """``fn()`` retried up to ``attempts`` times while it fails with a link fault (phase error,
    timeout, transient CHECK CONDITION: :data:`LINK_FAULTS`; the bulk-only layer has already reset
    the link); the last error is raised when every attempt failed. For idempotent calls only
    (identify, capabilities, configure)."""
    for k in range(max(1, attempts)):
        try:
            return fn()
        except LINK_FAULTS as exc:
            if k + 1 >= attempts or (isinstance(exc, CommandFailed) and exc.sense_key == ILLEGAL_REQUEST):
                raise
            log.warning("link fault (%s: %s); trying again (%d/%d)", type(exc).__name__, exc, k + 1, attempts)
    raise AssertionError("unreachable")  # pragma: no cover


# -- plan ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Measurement:
    """One measurement point: the set-up to configure and the FRF labels it yields."""

    index: int
    point: str
    reference: str
    outputs: tuple
    setup: Any  # acquisition.setup.AcquisitionSetup


@dataclass(frozen=True)
class TestPlan:
    """mode: ``roving_hammer`` or ``roving_accelerometer``; points: where the roving item goes
    (empty: the set-up's own points, one measurement); hits_per_point: accepted hits to average;
    reference: the hammer point for a roving accelerometer (default: the set-up's force channel)."""

    __test__ = False  # not a pytest test class despite the name

    mode: str = "roving_hammer"
    points: tuple = ()
    hits_per_point: int = 5
    reference: Optional[str] = None

    def __post_init__(self) -> None:
        if self.mode not in PLAN_MODES:
            raise ValueError(f"test plan mode {self.mode!r} must be one of {PLAN_MODES}")
        if self.hits_per_point < 1:
            raise ValueError(f"hits per point must be >= 1, got {self.hits_per_point}")
        pts = tuple(str(parse_point(p)) for p in self.points)
        object.__setattr__(self, "points", pts)
        if self.reference is not None:
            object.__setattr__(self, "reference", str(parse_point(self.reference)))
        if self.mode == "roving_hammer" and self.reference is not None:
            raise ValueError("a roving-hammer plan moves the reference; give --reference only for a roving accelerometer")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def measurements(self, setup: Any) -> list[Measurement]:
        """The measurement list for a base set-up (``acquisition.setup.AcquisitionSetup``)."""
        fch = force_channel_of(setup)
        rch = [i for i in range(len(setup.channels)) if i != fch]
        if not rch:
            raise SessionError("the set-up has no response channel: add at least one accelerometer")
        chans = list(setup.channels)
        if self.mode == "roving_accelerometer" and self.reference is not None:
            chans[fch] = replace(chans[fch], point=self.reference)
        base = replace(setup, channels=tuple(chans))
        points = self.points or (
            (base.channels[fch].point,) if self.mode == "roving_hammer" else (base.channels[rch[0]].point,)
        )
        out = []
        for k, p in enumerate(points):
            ch = list(base.channels)
            if self.mode == "roving_hammer":
                ch[fch] = replace(ch[fch], point=p)
            else:
                ch[rch[0]] = replace(ch[rch[0]], point=p)
            s = replace(base, channels=tuple(ch))
            out.append(Measurement(k, p, ch[fch].point, tuple(ch[i].point for i in rch), s))
        return out


def force_channel_of(setup: Any) -> int:
    """Index of the (single) force channel of a set-up."""
    idx = [i for i, ch in enumerate(setup.channels) if ch.quantity == "force"]
    if len(idx) != 1:
        raise SessionError(f"the set-up needs exactly one force channel (the hammer); it has {len(idx)}")
    return idx[0]


def channel_table(setup: Any) -> list[dict]:
    """The recording's channel table from an ``AcquisitionSetup``."""
    rows = []
    for ch in setup.channels:
        p = parse_point(ch.point)
        rows.append({"name": ch.name, "point": str(p), "direction": p.direction, "quantity": ch.quantity,
                     "sensitivity": float(ch.sensitivity), "sensitivity_unit": ch.sensitivity_unit,
                     "unit": ch.unit, "range_v": float(ch.range_v), "coupling": ch.coupling, "iepe": bool(ch.iepe)})
    return rows


def eu_per_count_for(setup: Any, volts_per_count: Sequence[float]) -> np.ndarray:
    """Engineering units per count per channel: volts per count / (volts per engineering unit)."""
    vpc = np.asarray(volts_per_count, dtype=float)
    vpu = np.array([ch.volts_per_unit for ch in setup.channels], dtype=float)
    if vpc.shape != vpu.shape:
        raise SessionError(f"block has {vpc.size} channels but the set-up {vpu.size}")
    return vpc / vpu


def process_hit(
    data: np.ndarray, fs_hz: float, trigger_index: int, force_channel: int, response_channels: Sequence[int],
    windows: WindowSettings,
) -> HitSpectra:
    """Windows and spectra of one hit (``data[n_ch, n]`` in EU): the one path used by capture, replay, import."""
    return hit_spectra(data[force_channel], data[list(response_channels)], fs_hz, trigger_index, windows)


# -- averaging per measurement --------------------------------------------------------------------
class MeasurementAverage:
    """The running average of one measurement point and the indices of its accepted hits."""

    def __init__(self, index: int, point: str, reference: str, outputs: Sequence[str], quantity: str, unit: str,
                 windows: WindowSettings) -> None:
        self.index = int(index)
        self.point = str(point)
        self.reference = str(reference)
        self.outputs = tuple(outputs)
        self.quantity = quantity
        self.unit = unit
        self.windows = windows
        self.acc = FRFAccumulator(self.outputs, self.reference, quantity, unit)
        self.hits: list[int] = []

    @property
    def n_averages(self) -> int:
        return self.acc.n_averages

    def frfset(self, estimator: str = "H1") -> FRFSet:
        return self.acc.frfset(estimator, meta={"measurement": f"m{self.index:03d}", "point": self.point,
                                                "windows": self.windows.to_dict()})

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
        )


# -- operator interaction -------------------------------------------------------------------------
@dataclass
class HitSummary:
    """What the operator sees after a hit."""

    measurement: int
    n_measurements: int
    point: str
    attempt: int
    accepted: int
    target: int
    rejected: int
    check: HitCheck
    coherence_so_far: Optional[float] = None
    # for a non-terminal front end (the station page): the hit itself and its outcome
    data: Optional[np.ndarray] = None  # (n_channels, n) in engineering units
    sample_rate_hz: float = 0.0
    trigger_index: int = 0
    average: Optional["MeasurementAverage"] = None  # the point's running average (this hit included while deciding)
    decision: Optional[bool] = None  # the outcome, set once the hit is written: True accepted, False rejected
    reasons: list = field(default_factory=list)
    hit_index: int = -1  # index in the recording

    def text(self) -> str:
        c = self.check
        ovl = ",".join(str(i + 1) for i, o in enumerate(c.overload) if o) or "none"
        coh = "-" if self.coherence_so_far is None else f"{self.coherence_so_far:.3f}"
        s = (f"point {self.measurement + 1}/{self.n_measurements} {self.point}  hit {self.attempt}: "
             f"force peak {c.force_peak_n:.1f} N, pulse {c.pulse_width_ms:.2f} ms, overload {ovl}, "
             f"double hit {'YES' if c.double_hit else 'no'} ({100 * c.second_peak_ratio:.0f} %), coherence {coh}")
        if c.verdict.accept is False:
            s += "  -> REJECTED: " + "; ".join(c.verdict.reasons)
        return s


def auto_accept(summary: HitSummary) -> bool:
    """The ``--auto`` operator: accept every hit that passed the automatic checks."""
    return True


def read_key(prompt: str) -> str:
    """One key press at a terminal (no Enter needed); a whole line when stdin is not a terminal."""
    if not sys.stdin.isatty():
        return input(prompt)
    import termios
    import tty

    print(prompt, end="", flush=True)
    fd = sys.stdin.fileno()
    old = termios.tcgetattr(fd)
    try:
        tty.setcbreak(fd)
        key = sys.stdin.read(1)
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, old)
    print(key)
    if key in ("\x03", "\x04"):  # Ctrl-C, Ctrl-D
        raise EOFError
    return key


def terminal_decider(input_fn: Callable[[str], str] = read_key, out: TextIO = sys.stdout) -> Callable[[HitSummary], bool]:
    """An operator at a terminal: key ``a`` (or Enter) accept, ``r`` reject, ``q`` quit (raises
    :class:`OperatorQuit`). ``input_fn(prompt) -> str`` reads the answer (default :func:`read_key`)."""

    def decide(summary: HitSummary) -> bool:
        while True:
            try:
                key = input_fn("accept (a), reject (r), quit (q)? ").strip().lower()
            except EOFError:
                raise OperatorQuit("input closed: ending the test") from None
            if key in ("a", "", "\n", "\r"):
                return True
            if key == "r":
                return False
            if key == "q":
                raise OperatorQuit("operator pressed q")
            print("please press a, r or q", file=out)

    return decide


# -- the session ----------------------------------------------------------------------------------
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

    ``progress(text)`` receives the lines to show (hit summaries, progress, events).
    """

    def __init__(
        self,
        analyser: Any,
        setup: Any,
        plan: TestPlan,
        *,
        writer: Optional[RecordingWriter] = None,
        windows: WindowSettings = WindowSettings(),
        decide: Callable[[HitSummary], bool] = auto_accept,
        check_settings: HitCheckSettings = HitCheckSettings(),
        progress: Optional[Callable[[str], None]] = None,
        timeout_s: float = 10.0,
        max_attempts_factor: int = 10,
        max_timeouts: int = 3,
        max_link_failures: int = 8,
        resume_hits: Sequence[Any] = (),
        gate: Optional[Callable[[Measurement, "MeasurementAverage", SessionResult, bool], bool]] = None,
        on_hit: Optional[Callable[[HitSummary], None]] = None,
    ) -> None:
        self.analyser = analyser
        self.setup = setup
        self.plan = plan
        self.writer = writer
        self.windows = windows.resolved(setup.block_size, setup.sample_rate_hz, setup.trigger.pretrigger_samples)
        self.decide = decide
        self.check_settings = check_settings
        self.progress = progress or (lambda text: None)
        # front-end hooks: gate(measurement, average, result, complete) -> go on measuring (False: end the
        # point now); called before each arm and once the point has its hits (it may block, undo or restart
        # through withdraw_last/withdraw_point, raise OperatorQuit). on_hit(summary) after each hit is written.
        self.gate = gate
        self.on_hit = on_hit
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
        self._event("INFO", f"test plan {self.plan.mode}: {len(self.measurements)} point(s), "
                            f"{self.plan.hits_per_point} hits each; windows: {self.windows.describe()}")
        try:
            for m in self.measurements:
                avg = MeasurementAverage(m.index, m.point, m.reference, m.outputs, self.frf_quantity,
                                         self.frf_unit, self.windows)
                result.averages.append(avg)
                done = self._resume_into(m, avg, result)
                if done:
                    continue
                self._measure(m, avg, result)
        except OperatorQuit as exc:
            result.aborted = True
            self._event("WARNING", f"test ended early: {exc}")
            if self.writer is not None and result.averages and result.averages[-1].n_averages > 0:
                result.averages[-1].write(self.writer)
        self._event("INFO", f"session done: {result.accepted} hits accepted, {len(result.rejected)} rejected")
        return result

    def _resume_into(self, m: Measurement, avg: MeasurementAverage, result: SessionResult) -> bool:
        """Add the recorded accepted hits of ``m`` to its average (resume); True when it is complete
        (its FRF results are then written again, so a crash between the last hit and the FRF loses nothing)."""
        mine = [h for h in self.resume_hits if h.measurement == m.index][: self.plan.hits_per_point]
        for h in mine:
            spectra = process_hit(h.data, h.sample_rate_hz, h.trigger_index, h.force_channel, h.response_channels,
                                  self.windows)
            avg.acc.add(spectra)
            avg.hits.append(h.index)
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
        attempts = 0
        timeouts = 0
        n_channels = len(m.setup.channels)
        names = [f"{ch.name} {ch.point}" for ch in m.setup.channels]
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
                self._event("WARNING", f"no trigger within {self.timeout_s:g} s at {m.point}")
                if timeouts >= self.max_timeouts:
                    raise SessionError(f"no trigger in {timeouts} tries at {m.point}: check the trigger level and "
                                       "channel, or hit the structure")
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
            counts = np.asarray(block.counts)
            if counts.dtype != np.int16 or counts.shape[0] != n_channels:
                raise SessionError(f"block has counts {counts.dtype} {counts.shape}; expected int16 "
                                   f"({n_channels}, n)")
            eu = eu_per_count_for(m.setup, block.volts_per_count)
            data = scale_counts(counts, eu)
            fs = float(block.sample_rate_hz)
            trig = int(block.trigger_index)
            overload = [bool(o) for o in np.asarray(block.overload).ravel()]
            check = check_hit(data[self.force_channel], fs, overload, names, self.check_settings)
            summary = HitSummary(m.index, len(self.measurements), m.point, attempts, avg.n_averages,
                                 self.plan.hits_per_point, sum(1 for r in result.rejected if r[0] == m.index), check,
                                 data=data, sample_rate_hz=fs, trigger_index=trig, average=avg)
            accepted = False
            reasons = list(check.verdict.reasons)
            if check.verdict.accept is not False:
                spectra = process_hit(data, fs, trig, self.force_channel, self.response_channels, self.windows)
                avg.acc.add(spectra)
                summary.coherence_so_far = avg.mean_coherence(hi_hz=fs / 2.56)
                self.progress(summary.text())
                try:
                    accepted = bool(self.decide(summary))
                except OperatorQuit:
                    avg.acc.rollback()
                    self._write_hit(block, counts, eu, m, False, ["test ended by the operator"], check)
                    raise
                if not accepted:
                    avg.acc.rollback()
                    reasons = ["rejected by the operator"]
            else:
                self.progress(summary.text())
            idx = self._write_hit(block, counts, eu, m, accepted, reasons, check)
            if accepted:
                avg.hits.append(idx)
                result.accepted += 1
            else:
                result.rejected.append((m.index, m.point, idx, reasons))
                self._event("INFO", f"hit {idx} at {m.point} rejected: {'; '.join(reasons)}")
            summary.decision, summary.reasons, summary.hit_index = accepted, reasons, idx
            if self.on_hit is not None:
                self.on_hit(summary)
            self.progress(f"  progress: point {m.index + 1}/{len(self.measurements)}, "
                          f"{avg.n_averages}/{self.plan.hits_per_point} accepted here, "
                          f"{result.accepted} accepted and {len(result.rejected)} rejected in total")
        if self.writer is not None and avg.n_averages > 0:
            avg.write(self.writer)
        self._event("INFO", f"point {m.point} done: {avg.n_averages} averages")

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
        self._event("INFO", f"hit {idx} at {avg.point} withdrawn: {reason}")
        return idx

    def withdraw_point(self, avg: MeasurementAverage, result: SessionResult, reason: str) -> None:
        """Withdraw every accepted hit of ``avg`` (measure the point again)."""
        while avg.hits:
            self.withdraw_last(avg, result, reason)

    def _link_fault(self, m: Measurement, exc: Exception, faults_here: int) -> None:
        """A command failed on the link (phase error, timeout, device gone and back, transient CHECK
        CONDITION...): log it, and bring the analyser back to a known state (abort, set-up again) so
        the next pass re-arms. The hit in flight was not accepted (a hit is accepted only after its
        whole block arrived), so nothing accepted is lost.

        The session ends with :class:`SessionError` saying why (every accepted hit stays in the
        recording) when ``max_link_failures`` recovery attempts in a row fail (the link is dead) or
        the point has met more than ``max_attempts_factor * hits_per_point`` link faults (the link
        is too poor to finish)."""
        if isinstance(exc, CommandFailed) and exc.sense_key == ILLEGAL_REQUEST:
            raise exc  # the analyser refuses the request itself: retrying cannot help
        self.link_faults += 1
        budget = self.max_attempts_factor * self.plan.hits_per_point
        self._event("WARNING", f"link fault {faults_here}/{budget} at {m.point} ({type(exc).__name__}: {exc}); "
                               "recovering")
        if faults_here > budget:
            raise SessionError(f"the analyser link failed {faults_here} times at {m.point} (last: "
                               f"{type(exc).__name__}: {exc}); the recording keeps every accepted hit: check the "
                               "cable or server and resume the test (capture --resume)")
        failures = 0
        while True:
            try:
                abort = getattr(self.analyser, "abort", None)
                if abort is not None:
                    abort()
                self.analyser.configure(m.setup)
                return
            except LINK_FAULTS as again:
                exc = again
                failures += 1
                self._event("WARNING", f"recovery {failures}/{self.max_link_failures} at {m.point} failed "
                                       f"({type(again).__name__}: {again})")
                if failures >= self.max_link_failures:
                    break
        raise SessionError(f"the analyser link keeps failing at {m.point} ({failures} recovery attempts in a row "
                           f"failed, last: {type(exc).__name__}: {exc}); the recording keeps every accepted hit: "
                           "check the cable or server and resume the test (capture --resume)")

    def _write_hit(self, block: Any, counts: np.ndarray, eu: np.ndarray, m: Measurement, accepted: bool,
                   reasons: list, check: HitCheck) -> int:
        if self.writer is None:
            return -1
        return self.writer.write_hit(
            counts=counts, eu_per_count=eu, volts_per_count=np.asarray(block.volts_per_count, float),
            trigger_index=int(block.trigger_index), sample_rate_hz=float(block.sample_rate_hz),
            sequence=int(block.sequence), timestamp=float(block.timestamp), measurement=m.index, point=m.point,
            reference=m.reference, outputs=m.outputs, force_channel=self.force_channel,
            response_channels=self.response_channels, overload=np.asarray(block.overload, bool).ravel(),
            accepted=accepted, reasons=reasons, check=check.to_dict(),
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
            avg = MeasurementAverage(h.measurement, h.point, h.reference, h.outputs, quantity, unit, win)
            groups[h.measurement] = avg
        spectra = process_hit(h.data, h.sample_rate_hz, h.trigger_index, h.force_channel, h.response_channels, win)
        avg.acc.add(spectra)
        avg.hits.append(h.index)
    return [groups[k] for k in sorted(groups)]
