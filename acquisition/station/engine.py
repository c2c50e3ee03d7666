"""The station's engine: the capture session (:class:`acquisition.session.CaptureSession`, the same
loop as ``capture``) run in a thread, steered by the page's actions through the session's hooks.

Phases (``state["phase"]``) and the actions each allows:

=============  ==================================================================================
``setup``      before the first hit: ``setup`` (change the set-up), ``test-hit`` (one hit shown, not
               recorded: set ranges and trigger), ``arm`` (starts the test)
``ready``      before each arm: ``arm``, ``undo``, ``remeasure``, ``next-point`` (skip), ``finish``
``armed``      waiting for the hit (nothing to decide; ``finish`` ends after it)
``decide``     a hit that passed the checks: ``accept``, ``reject``, ``finish``
``busy``       the hit is being written (``finish``)
``complete``   the point has its hits: ``next-point``, ``undo``, ``remeasure``, ``finish``
``finished``   the plan is done or ended; ``error``: the session stopped (message says why)
=============  ==================================================================================

Actions that act on a hit or a point name it, so a click made on a page that is out of date (a
double click, a second key press before the page caught up) is refused (409) instead of acting on
the next hit or point: ``accept``/``reject`` carry ``"hit": N`` (the number of the hit waiting for
the decision, ``verdict.number``), ``next-point``, ``undo`` and ``remeasure`` carry ``"point":
INDEX`` (the plan row, ``current`` for the point on now), ``arm`` may carry it; ``undo`` also carries
``"hits": N`` (the point's accepted hits on screen, ``point_hits``), so a second click sent after the first
was carried out is refused as well. While one such action waits for the session (or is being carried out:
phase ``busy``), the next is refused too.

``pause``/``resume`` and ``auto`` (on/off) are allowed in every running phase. Auto mode arms,
accepts every hit that passed the checks and moves to the next point; pause holds it before the
next arm (the arm action too, until resume). One tab controls at a time (:class:`acquisition.station.state.Lease`).
"""
from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from analysis.spectra import WindowSettings

from ..errors import ImpactlabError, SetupError
from ..session import CaptureSession, HitSummary, OperatorQuit, SessionError, TestPlan
from ..setup import AcquisitionSetup, validate_setup
from ..window_options import parse_windows
from .adapters import LogToPage, Timed
from .publish import PagePublisher
from .state import StationState
from .testhit import take_test_hit

__all__ = ["ACTIONS", "ActionRefused", "StationEngine"]

log = logging.getLogger(__name__)

ACTIONS = ("arm", "accept", "reject", "undo", "remeasure", "next-point", "finish", "pause", "resume", "auto",
           "setup", "test-hit")
_ANYTIME = ("pause", "resume", "auto")
#: actions that must name the hit (``"hit"``: its number) or the point (``"point"``: its plan index) they act on
TARGET_OF = {"accept": "hit", "reject": "hit", "next-point": "point", "undo": "point", "remeasure": "point"}
_ALLOWED = {
    "setup": ("setup", "test-hit", "arm", "finish"),
    "ready": ("arm", "undo", "remeasure", "next-point", "finish"),
    "armed": ("finish",),
    "decide": ("accept", "reject", "finish"),
    "complete": ("next-point", "undo", "remeasure", "finish"),
    "finished": ("remeasure",),
    "error": (),
    "starting": ("finish",),
    "busy": ("finish",),
}


#: triggers missed in a row before the session gives up: none here (the operator at the page sees each
#: "no trigger" message and decides; ``capture`` without an operator stops after a few)
NO_TRIGGER_LIMIT = 1_000_000


class ActionRefused(ImpactlabError, ValueError):
    """An action the session cannot take now (HTTP 409) or a malformed one (HTTP 400); ``status`` says which."""

    def __init__(self, message: str, status: int = 409) -> None:
        super().__init__(message)
        self.status = status


class StationEngine(PagePublisher):
    """Drive a test plan from the page.

    ``open_writer(setup, windows)`` returns the recording writer (a new file, or the resumed one)
    once the test starts; the engine closes it when the session ends. ``capabilities``: the
    analyser's (``acquisition.setup.Capabilities``), for validating set-up changes.
    ``windows``: the window settings (a set-up panel may change them, as texts); they are resolved
    once for the set-up's block layout when the test starts, and the same settings go to the
    recording and the session.
    """

    def __init__(self, analyser: Any, setup: AcquisitionSetup, plan: TestPlan, *, capabilities: Any,
                 windows: WindowSettings, open_writer: Callable[[AcquisitionSetup, WindowSettings], Any],
                 resume_hits: Sequence[Any] = (), setup_editable: bool = True, timeout_s: float = 10.0,
                 geometry: dict | None = None, auto: bool = False) -> None:
        self.analyser = analyser
        self.setup = setup
        self.plan = plan
        self.caps = capabilities
        self.windows = windows
        self.open_writer = open_writer
        self.resume_hits = list(resume_hits)
        self.setup_editable = bool(setup_editable)
        self.timeout_s = float(timeout_s)
        self.state = StationState()
        self.session: CaptureSession | None = None
        self._cond = self.state.cond
        self._cmds: list[tuple[str, dict]] = []
        self._quit = False
        self._auto = bool(auto)
        self._paused = False
        self._thread: threading.Thread | None = None
        self._log_handler = LogToPage(self.state)
        self._pending_hit: HitSummary | None = None
        self._shown_seq = 0
        self._accepted: dict[int, Any] = {}  # recording index -> accepted hit (for a pass that goes back)
        self._redo: int | None = None
        self._block_time = 0.0
        self.geometry = geometry or {"nodes": {}, "lines": []}
        rows = self._plan_rows()
        for r in rows:  # a resumed recording's hits
            r["accepted"] = min(plan.hits_per_point, sum(1 for h in self.resume_hits
                                                          if h.accepted and h.measurement == r["index"]))
            r["done"] = r["accepted"] >= plan.hits_per_point
        first = next((r for r in rows if not r["done"]), rows[-1] if rows else None)
        self.state.update(phase="setup", auto=self._auto, paused=False, plan=rows, mode=plan.mode,
                          hits_per_point=plan.hits_per_point, current=first["index"] if first else 0,
                          current_point=first["point"] if first else "", point_hits=first["accepted"] if first else 0,
                          total_accepted=sum(r["accepted"] for r in rows), total_rejected=0,
                          outputs=first["outputs"] if first else [], reference=first["reference"] if first else "")
        self._publish_setup()

    # -- life cycle ------------------------------------------------------------------------------
    def start(self) -> None:
        session_log = logging.getLogger("acquisition.session")
        if session_log.level == logging.NOTSET or session_log.level > logging.INFO:
            session_log.setLevel(logging.INFO)  # the page shows the session's events
        session_log.addHandler(self._log_handler)
        self._thread = threading.Thread(target=self._run, name="station-session", daemon=True)
        self._thread.start()

    def join(self, timeout: float | None = None) -> None:
        if self._thread is not None:
            self._thread.join(timeout)

    def stop(self) -> None:
        """End the session (as the finish action) and wait for it."""
        with self._cond:
            self._quit = True
            self._cond.notify_all()
        self.join(30.0)

    @property
    def done(self) -> bool:
        return self.state.get("phase") in ("finished", "error")

    def _run(self) -> None:
        try:
            if not self._wait_start():
                self.state.update(phase="finished", summary="ended before the first hit; nothing recorded")
                return
            self.state.update(phase="starting")
            self._publish_setup()
            windows = self.windows.resolved(self.setup.block_size, self.setup.sample_rate_hz,
                                            self.setup.trigger.pretrigger_samples)
            writer = self.open_writer(self.setup, windows)
            try:
                self._accepted = {h.index: h for h in self.resume_hits if h.accepted}
                while True:
                    self._redo = None
                    self.session = CaptureSession(
                        Timed(self.analyser, self), self.setup, self.plan, writer=writer, windows=windows,
                        decide=self.decide, gate=self.gate, on_hit=self.on_hit, progress=self.progress, timeout_s=self.timeout_s,
                        max_timeouts=NO_TRIGGER_LIMIT,
                        resume_hits=sorted(self._accepted.values(), key=lambda h: h.index))
                    result = self.session.run()
                    if self._redo is None:
                        self.state.update(phase="finished", summary=f"{result.accepted} hits accepted, "
                                          f"{len(result.rejected)} rejected; recording {getattr(writer, 'path', '')}"
                                          + (" (ended early)" if result.aborted else ""), plan=self._plan_rows())
                        self.state.message(*(("WARNING", "test ended early: restart the station with --resume to "
                                                      "measure the points still missing") if result.aborted else
                                             ("INFO", "test finished: the recording is complete")))
                        self._redo = self._wait_redo()
                        if self._redo is None:
                            break
                    self._withdraw_measurement(writer, self._redo)
            finally:
                writer.close()
        except SessionError as exc:
            self.state.message("ERROR", str(exc))
            self.state.update(phase="error", error=str(exc))
        except (ImpactlabError, OSError, ValueError) as exc:
            self.state.message("ERROR", f"{type(exc).__name__}: {exc}")
            self.state.update(phase="error", error=f"{type(exc).__name__}: {exc}; every accepted hit is in the "
                                                   "recording: restart the station to resume it")
        finally:
            logging.getLogger("acquisition.session").removeHandler(self._log_handler)

    def _wait_start(self) -> bool:
        """The set-up phase: wait for arm (start) or finish, applying set-up changes meanwhile."""
        while True:
            with self._cond:
                while not self._cmds and not self._quit and not (self._auto and not self._paused):
                    self._cond.wait()
                if self._quit:
                    return False
                if not self._cmds:  # auto mode starts at once
                    return True
                action = self._cmds[0][0]
                if action == "arm":
                    return True  # left queued: the first gate arms at once
                self._cmds.pop(0)
            if action == "test-hit":
                self._test_hit()

    def _test_hit(self) -> None:
        self.state.update(phase="armed")
        got = take_test_hit(Timed(self.analyser, self), self.setup, self.plan, self.timeout_s)
        if isinstance(got, str):
            self.state.message("WARNING", got)
        else:
            self._publish_hit(got, pending=False)
        self.state.update(phase="setup")

    def _wait_redo(self) -> int | None:
        """After the plan: wait for a point to measure again (its index) or the end (None)."""
        with self._cond:
            while True:
                if self._quit:
                    return None
                if self._cmds:
                    action, params = self._cmds.pop(0)
                    if action == "remeasure" and isinstance(params.get("point"), int):
                        self.state.update(phase="busy")
                        return int(params["point"])

                self._cond.wait()

    def _withdraw_measurement(self, writer: Any, index: int) -> None:
        """Take every accepted hit of measurement ``index`` out (the session then measures it again)."""
        mine = sorted(i for i, h in self._accepted.items() if h.measurement == index)
        for i in mine:
            writer.withdraw_hit(i, "point measured again by the operator")
            del self._accepted[i]
        rows = [dict(r, accepted=0, done=False) if r["index"] == index else r for r in self.state.get("plan") or []]
        self.state.update(plan=rows)
        self.state.message("INFO", f"measuring point {index + 1} again ({len(mine)} hits withdrawn)")

    # -- actions (HTTP threads) -------------------------------------------------------------------
    def allowed(self) -> tuple:
        phase = self.state.get("phase")
        base = tuple(a for a in _ALLOWED.get(phase, ()) if not (self._paused and a == "arm"))
        return base + (_ANYTIME if phase not in ("finished", "error") else ())

    def submit(self, action: str, params: dict | None = None) -> str:
        """Queue or apply an action; raises :class:`ActionRefused` when it is unknown (400) or not
        possible in the current phase (409). Returns a short description for the page."""
        params = dict(params or {})
        if action not in ACTIONS:
            raise ActionRefused(f"unknown action {action!r}; known: {', '.join(ACTIONS)}", 400)
        with self._cond:
            allowed = self.allowed()
            if action not in allowed:
                phase = self.state.get("phase")
                if phase == "busy":
                    raise ActionRefused(f"{action} refused: the previous action is still being carried out; look at "
                                        "the page again and repeat it if it is still wanted")
                raise ActionRefused(f"{action} is not possible now (phase {phase}; possible: "
                                    f"{', '.join(allowed) or 'nothing'})")
            if action == "pause":
                self._paused = True
            elif action == "resume":
                self._paused = False
            elif action == "auto":
                on = params.get("on", not self._auto)
                if not isinstance(on, bool):
                    raise ActionRefused("auto needs {\"on\": true|false}", 400)
                self._auto = on
            elif action == "setup":
                self._apply_setup(params)
            elif action == "finish":
                self._quit = True
            else:
                self._check_target(action, params)
                self._cmds.append((action, params))
            self.state.update(auto=self._auto, paused=self._paused)
            self._cond.notify_all()
        return action

    def _check_target(self, action: str, params: dict) -> None:
        """Refuse a queued action made on a page that is out of date (409) or that does not name what it
        acts on (400): the hit waiting for the decision, the point on now (or, for ``remeasure``, the
        point to go back to); and any such action while an earlier one still waits for the session."""
        if self._cmds:
            raise ActionRefused(f"{action} refused: the previous action ({self._cmds[0][0]}) is still being carried "
                                "out; look at the page again and repeat it if it is still wanted")
        key = TARGET_OF.get(action)
        if key is None and "point" not in params:
            return
        if key is not None and key not in params:
            raise ActionRefused(f"{action} must name the {key} it acts on: give {{\"{key}\": "
                                + ("N}} (the number of the hit on screen, verdict.number)" if key == "hit" else
                                   "INDEX}} (the plan row's index; current for the point on now)"), 400)
        value = params[key or "point"]
        if not isinstance(value, int) or isinstance(value, bool):
            raise ActionRefused(f"{action}: {key or 'point'} must be an integer, not {value!r}", 400)
        if key == "hit":
            verdict = self.state.get("verdict") or {}
            waiting = verdict.get("number") if verdict.get("state") == "decide" else None
            if value != waiting:
                raise ActionRefused(f"{action} refused: hit {value} is not waiting for a decision"
                                    + (f" (hit {waiting} is)" if waiting is not None else "")
                                    + "; look at the page again")
            return
        n = len(self.state.get("plan") or [])
        if not 0 <= value < n:
            raise ActionRefused(f"{action}: point must be an index 0..{n - 1}", 400)
        current = self.state.get("current")
        if action == "remeasure" and (value != current or self.state.get("phase") == "finished"):
            return  # go back to a point measured earlier (or, after the end, to any point)
        if value != current:
            raise ActionRefused(f"{action} refused: it names point {value + 1} but point {int(current or 0) + 1} "
                                "is on now; look at the page again")
        if action in ("undo", "remeasure") and not self.state.get("point_hits"):
            raise ActionRefused(f"{action}: this point has no accepted hit")
        if action == "undo":
            self._check_hits_shown(params)

    def _check_hits_shown(self, params: dict) -> None:
        """An ``undo`` names the point's accepted hits the page shows (``"hits": N``, the state's ``point_hits``):
        a second click sent after the first was carried out names a count the point no longer has and is
        refused (409) instead of withdrawing a second hit, however quickly the first was done."""
        shown = params.get("hits")
        if shown is None:
            raise ActionRefused("undo must name the accepted hits the page shows: give {\"hits\": N} (the state's "
                                "point_hits)", 400)
        if not isinstance(shown, int) or isinstance(shown, bool):
            raise ActionRefused(f"undo: hits must be an integer, not {shown!r}", 400)
        now = int(self.state.get("point_hits") or 0)
        if shown != now:
            raise ActionRefused(f"undo refused: the page showed {shown} accepted hits at this point but it has {now} "
                                "now (an undo was already carried out); look at the page again")

    # -- set-up ------------------------------------------------------------------------------------
    def check_setup(self, params: dict) -> tuple[AcquisitionSetup, WindowSettings]:
        """The set-up and windows a set-up panel asks for, validated against the analyser's
        capabilities (raises :class:`ActionRefused` 422 naming the problem)."""
        try:
            setup = AcquisitionSetup.from_dict(params.get("setup", self.setup.to_dict()))
            validate_setup(setup, self.caps)
            self.plan.measurements(setup)  # one force channel, responses of one quantity
            windows = self.windows
            w = params.get("windows")
            if w is not None:
                if not isinstance(w, dict):
                    raise SetupError("windows must be {\"force\": TEXT, \"exp\": TEXT}")
                windows = parse_windows(w.get("force"), w.get("exp"), setup.sample_rate_hz)
        except (SetupError, ValueError, TypeError) as exc:
            raise ActionRefused(str(exc), 422) from None
        return setup, windows

    def _apply_setup(self, params: dict) -> None:
        if not self.setup_editable:
            raise ActionRefused("a resumed recording keeps its set-up")
        self.setup, self.windows = self.check_setup(params)
        self.state.update(plan=self._plan_rows())
        self._publish_setup()
        self.state.message("INFO", "set-up changed: " + ", ".join(f"{c.name} {c.range_v:g} V" for c in self.setup.channels)
                           + f"; trigger {self.setup.trigger.level:g} at channel {self.setup.trigger.channel}, "
                           f"pre-trigger {self.setup.trigger.pretrigger_samples}; windows {self.windows.describe()}")

    # -- the session's operator (session thread): decide, progress, on_hit, gate ----------------------
    def _next_command(self, wanted: tuple, auto_answer: str | None) -> tuple[str, dict]:
        with self._cond:
            while True:
                if self._quit:
                    raise OperatorQuit("finished from the station page")
                if self._cmds:
                    action, params = self._cmds.pop(0)
                    if action in wanted:
                        self.state.update(phase="busy")  # no action acts on what the page showed until it is redrawn
                        return action, params
                    self.state.message("WARNING", f"{action} ignored: not possible now")
                    continue
                if auto_answer is not None and self._auto and not self._paused:
                    self.state.update(phase="busy")
                    return auto_answer, {}
                self._cond.wait()

    def gate(self, m: Any, avg: Any, result: Any, complete: bool) -> bool:
        session = self.session
        assert session is not None
        while True:
            complete = avg.n_averages >= self.plan.hits_per_point
            self._publish_point(m, avg, result, "complete" if complete else "ready")
            if complete:
                action, params = self._next_command(("next-point", "undo", "remeasure"), "next-point")
            else:
                action, params = self._next_command(("arm", "undo", "remeasure", "next-point"), "arm")
            if action == "arm":
                self.state.update(phase="armed")
                return True
            if action == "next-point":
                if not complete:
                    session._event("INFO", f"point {m.point} skipped by the operator with {avg.n_averages} "
                                           f"of {self.plan.hits_per_point} hits")
                return False
            if action == "remeasure" and "point" in params and params["point"] != m.index:
                self._redo = int(params["point"])  # ends this pass; the next one resumes and measures it
                raise OperatorQuit(f"going back to point {self._redo + 1}")
            if action == "undo" and avg.hits:
                self._accepted.pop(session.withdraw_last(avg, result, "withdrawn by the operator (undo)"), None)
            elif action == "remeasure" and avg.hits:
                session.withdraw_point(avg, result, "point measured again by the operator")
                for i in [i for i, h in self._accepted.items() if h.measurement == m.index]:
                    del self._accepted[i]
            self._publish_frf(avg)

    def progress(self, text: str) -> None:
        """The session's terminal lines: the page shows the same facts from the state instead."""

    def decide(self, summary: HitSummary) -> bool:
        self._publish_hit(summary, pending=True)
        action, _ = self._next_command(("accept", "reject"), "accept")
        return action == "accept"

    def on_hit(self, summary: HitSummary) -> None:
        if summary.decision and self.session is not None:
            assert summary.hit is not None  # the session's summaries carry their hit
            self._accepted[summary.hit_index] = summary.hit.with_verdict(True, summary.reasons).with_index(
                summary.hit_index)
        self._publish_hit(summary, pending=False)

    def mark_block(self) -> None:
        self._block_time = time.time()
