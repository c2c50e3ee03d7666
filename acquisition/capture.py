"""A capture job: open the analyser, run the test plan through a :class:`CaptureSession` and write
the recording, the library behind ``capture`` and the simulator's fleet. The windows are resolved
once, for the set-up's block layout, and the same settings go to the recording and the session."""
from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

from analysis.recording_writer import RecordingWriter
from analysis.spectra import WindowSettings

from .operator import HitSummary
from .plan import TestPlan, channel_table
from .session import CaptureSession, SessionError, SessionResult, auto_accept, retry_on_link_fault
from .setup import AcquisitionSetup

__all__ = ["open_analyser", "capture_to_file"]

log = logging.getLogger(__name__)


def open_analyser(url: str, timeout_s: float = 10.0) -> Any:
    """An ``Analyser`` on ``url`` (``sim://?replay=REC.h5``: the simulated analyser plays a recording back
    through :class:`simulator.replay_stand.ReplayStand`). ``timeout_s`` bounds each command."""
    from .driver import Analyser

    return Analyser(url, timeout_s=timeout_s)


def capture_to_file(
    url: str,
    out: str | Path,
    setup: AcquisitionSetup,
    plan: TestPlan,
    windows: WindowSettings,
    *,
    decide: Callable[[HitSummary], bool] = auto_accept,
    progress: Callable[[str], None] = lambda text: None,
    timeout_s: float = 10.0,
    overwrite: bool = False,
) -> SessionResult:
    """Run ``plan`` on the analyser at ``url`` and write the recording ``out``; returns the session's
    result. ``progress(text)`` gets the analyser's identity line and the session's lines.

    A :class:`SessionError` is logged in the recording and raised; a recording left without a single
    hit by a failure holds nothing to keep and is removed (a retry needs no ``overwrite``)."""
    out = Path(out)
    resolved = windows.resolved(setup.block_size, setup.sample_rate_hz, setup.trigger.pretrigger_samples)
    measurements = plan.measurements(setup)
    with open_analyser(url) as analyser:
        identity = retry_on_link_fault(analyser.identify)
        instrument = identity.as_dict() if hasattr(identity, "as_dict") else dict(vars(identity))
        progress(f"analyser: {identity}; {len(measurements)} point(s) x {plan.hits_per_point} hits, {plan.mode}")
        writer = RecordingWriter(out, instrument=instrument, setup=setup.to_dict(), channels=channel_table(setup),
                                 windows=resolved, plan={**plan.to_dict(), "device": url, "auto": decide is auto_accept},
                                 overwrite=overwrite)
        result = None
        try:
            session = CaptureSession(analyser, setup, plan, writer=writer, windows=resolved, decide=decide,
                                     progress=progress, timeout_s=timeout_s)
            try:
                result = session.run()
            except SessionError as exc:
                writer.log("ERROR", str(exc))
                raise
        finally:
            empty = result is None and writer.n_hits == 0  # failed before its first hit: nothing to keep
            writer.close(discard=empty)
            if empty:
                log.info("removed %s: the capture failed before its first hit", out)
    return result
