"""A test hit before the test starts: one block with the set-up as it stands, checked and shown but
not recorded, so the operator can set ranges and the trigger (an overload names the range to use).

This is one acquisition (configure, arm, wait, read), not a capture loop: the test itself always runs
in :class:`acquisition.session.CaptureSession`.
"""
from __future__ import annotations

from typing import Any

from ..errors import SetupError, TriggerTimeout
from ..hitcheck import HitCheckSettings, check_hit
from ..session import LINK_FAULTS, HitSummary, force_channel_of, hit_from_block

__all__ = ["take_test_hit"]


def take_test_hit(analyser: Any, setup: Any, plan: Any, timeout_s: float) -> HitSummary | str:
    """The first measurement's hit with ``setup`` as a :class:`HitSummary` (outcome "test hit: not
    recorded"), or a sentence saying why there is none (no trigger, link fault, set-up refused)."""
    m = plan.measurements(setup)[0]
    try:
        analyser.configure(m.setup)
        analyser.arm()
        try:
            triggered = analyser.wait_for_trigger(timeout_s)
        except TriggerTimeout:
            triggered = False
        if triggered is False:
            abort = getattr(analyser, "abort", None)
            if abort is not None:
                abort()
            return f"test hit: no trigger within {timeout_s:g} s; check the trigger level and hit the structure"
        block = analyser.read_block()
    except SetupError as exc:
        return f"test hit: the analyser refuses the set-up: {exc}"
    except LINK_FAULTS as exc:
        return f"test hit: link fault ({type(exc).__name__}: {exc}); try again"
    fch = force_channel_of(m.setup)
    hit = hit_from_block(block, m, fch, [i for i in range(len(m.setup.channels)) if i != fch])
    check = check_hit(hit.force, hit.sample_rate_hz, [bool(o) for o in hit.overload], list(hit.channel_names),
                      HitCheckSettings())
    return HitSummary(m.index, len(plan.measurements(setup)), m.point, 0, 0, plan.hits_per_point, 0, check,
                      hit=hit, decision=False, reasons=["test hit: not recorded"])
