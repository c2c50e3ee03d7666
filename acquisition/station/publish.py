"""What the station's engine shows: the plan rows, the current point, each hit's plots and verdict,
the set-up panel (a mixin of :class:`acquisition.station.engine.StationEngine`, which owns the
attributes used here: ``state``, ``plan``, ``setup``, ``caps``, ``windows``, ``session``...)."""
from __future__ import annotations

from typing import Any

from ..errors import ImpactlabError
from ..session import HitSummary, force_channel_of
from . import payloads

__all__ = ["PagePublisher"]


class PagePublisher:
    """Publishing half of the station engine (session thread)."""

    state: Any
    plan: Any
    setup: Any
    caps: Any
    windows: Any
    session: Any
    setup_editable: bool
    resume_hits: list
    _pending_hit: Any
    _shown_seq: int
    _block_time: float
    _averages: list

    def _publish_setup(self) -> None:
        self.state.set_blob("setup", payloads.setup_payload(self.setup, self.caps, self.windows,
                                                            self.setup_editable and self.state.get("phase") == "setup"))

    def _plan_rows(self) -> list[dict]:
        try:
            ms = self.plan.measurements(self.setup)
        except ImpactlabError:
            return []
        old = {r["point"]: r for r in (self.state.get("plan") or [])}
        return [{"index": m.index, "point": m.point, "reference": m.reference, "outputs": list(m.outputs),
                 "accepted": old.get(m.point, {}).get("accepted", 0),
                 "done": old.get(m.point, {}).get("done", False)} for m in ms]

    def _measured(self) -> list:
        """The running averages of the points measured so far (the session's result, kept by :meth:`_publish_point`)."""
        return list(getattr(self, "_averages", ()))

    def _publish_frf(self, avg: Any) -> None:
        self.state.set_blob("frf", payloads.frf_payload(avg, self.setup.bandwidth_hz, self._measured()))

    def _publish_point(self, m: Any, avg: Any, result: Any, phase: str) -> None:
        self._averages = result.averages
        rows = self.state.get("plan") or self._plan_rows()
        rows = [dict(r) for r in rows]
        for r in rows:
            if r["index"] == m.index:
                r["accepted"] = avg.n_averages
                r["done"] = avg.n_averages >= self.plan.hits_per_point
            elif r["index"] < m.index and r["accepted"] >= self.plan.hits_per_point:
                r["done"] = True
        self.state.update(phase=phase, current=m.index, current_point=m.point, point_hits=avg.n_averages,
                          total_accepted=result.accepted, total_rejected=len(result.rejected), plan=rows,
                          reference=m.reference, outputs=list(m.outputs))

    def _publish_hit(self, summary: HitSummary, pending: bool) -> None:
        setup = self.setup
        chans = setup.channels
        assert summary.data is not None
        if pending or self._pending_hit is not summary:
            t_block = self._block_time
            seq = self.state.next_hit_seq()
            here = self.plan.measurements(setup)[summary.measurement].setup.channels  # the roving point moves
            names = [f"{c.name} {c.point}" for c in here]
            units = [c.unit for c in chans]
            fch = force_channel_of(setup)
            hit = payloads.hit_payload(summary.data, summary.sample_rate_hz, summary.trigger_index,
                                       setup.trigger.pretrigger_samples, fch,
                                       [i for i in range(len(chans)) if i != fch], names, units,
                                       self.windows.force_width_s)
            hit["seq"] = seq
            self._shown_seq = seq
            hit["t_block"] = t_block
            hit["point"] = summary.point
            self.state.set_blob("hit", hit)
            self._pending_hit = summary
        advice = payloads.range_advice(summary.check, setup, self.caps.ranges_v, summary.data)
        writer = getattr(self.session, "writer", None)
        number = (summary.hit_index + 1 if summary.hit_index >= 0 else None) if not pending else \
            (writer.n_hits + 1 if writer is not None else None)  # a pending hit is written next
        verdict = payloads.verdict_payload(summary, pending, advice, number)
        verdict["seq"] = self._shown_seq
        hits_here = (summary.average.n_averages - (1 if pending else 0)) if summary.average is not None else 0
        if summary.average is not None:
            self.state.set_blob("frf", payloads.frf_payload(summary.average, setup.bandwidth_hz, self._measured()))
        phase = "decide" if pending else "busy"
        self.state.update(verdict=verdict, hit_seq=self._shown_seq, phase=phase, point_hits=hits_here)
        if not pending:
            self._pending_hit = None
            for a in advice:
                self.state.message("WARNING", a)

