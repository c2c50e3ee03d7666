"""The options ``capture`` and ``station`` share, turned into what a capture job needs: the device
URL with ``--seed``, the test plan of ``--points``/``--reference``/``--mode``/``--hits``, and what
``--resume REC.h5`` continues."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .errors import SetupError, UsageError

__all__ = ["with_seed", "with_levels", "recorded_auto", "SOFT_HARD", "continue_stream", "plan_from_options",
           "recorded_plan", "recorded_test"]


def with_seed(url: str, seed: int | None) -> str:
    """``url`` with ``--seed`` added (simulated devices only; None: unchanged)."""
    if seed is None:
        return url
    if not url.startswith(("sim://", "usbsim://")):
        raise UsageError(f"--seed applies to simulated devices (sim://, usbsim://), not {url!r}")
    if "seed=" in url:
        raise UsageError(f"the URL {url!r} already has a seed; drop --seed or the URL's seed")
    return url + ("&" if "?" in url else "?") + f"seed={seed}"


#: the force levels of ``--soft-hard``, struck in this order at each point
SOFT_HARD = ("soft", "hard")
#: the simulated operator's strikes of a soft-then-hard plan (``levels``: amplitude scales; the
#: simulated hammer's hard hits are about 95 N, so soft ones about 38 N, above the 20 N trigger)
SIM_SOFT_HARD_SCALES = "0.4,1"


def with_levels(url: str, plan: Any) -> str:
    """``url`` of a simulated device with its operator striking ``plan``'s force levels in series
    (``levels=`` and ``per_level=``), unless the URL sets them; other devices and plans: unchanged (a
    real operator follows the prompts)."""
    if not getattr(plan, "levels", ()) or not url.startswith(("sim://", "usbsim://")) or "levels=" in url \
            or "replay=" in url:
        return url
    if len(plan.levels) != 2:
        raise UsageError(f"the simulated operator strikes soft then hard; {len(plan.levels)} levels need levels= in "
                         "the URL")
    per = plan.hits_per_point // len(plan.levels)
    return url + ("&" if "?" in url else "?") + f"levels={SIM_SOFT_HARD_SCALES}&per_level={per}"


def continue_stream(url: str, n_recorded: int) -> str:
    """A simulated device resumed after ``n_recorded`` hits continues its random stream instead of
    playing the same strikes again: its seed moves on by the number of hits already recorded."""
    if not url.startswith(("sim://", "usbsim://")) or n_recorded <= 0 or "replay=" in url:
        return url
    import re

    m = re.search(r"([?&])seed=(-?\d+)", url)
    if m is None:
        return url + ("&" if "?" in url else "?") + f"seed={n_recorded}"
    return url[:m.start()] + f"{m.group(1)}seed={int(m.group(2)) + n_recorded}" + url[m.end():]


def plan_from_options(args: argparse.Namespace, replay_plan: dict | None = None) -> Any:
    """The test plan of the ``--points``, ``--reference``, ``--mode`` and ``--hits`` options (a replayed
    recording's plan fills those not given)."""
    from .session import TestPlan

    points: tuple = ()
    if args.points:
        points = tuple(p.strip() for p in args.points.split(",") if p.strip())
    mode = args.mode.replace("-", "_") if args.mode else ("roving_accelerometer" if args.reference else "roving_hammer")
    hits = args.hits if args.hits is not None else 5
    reference = args.reference
    if replay_plan and not args.points and not args.mode and not args.reference:
        mode = replay_plan.get("mode", mode)
        points = tuple(replay_plan.get("points", ()))
        if args.hits is None:
            hits = int(replay_plan.get("hits_per_point", hits))
        if mode == "roving_accelerometer":
            reference = replay_plan.get("reference")
    if hits < 1:
        raise UsageError(f"--hits {hits}: need at least one hit per point")
    levels = SOFT_HARD if getattr(args, "soft_hard", False) else ()
    try:
        return TestPlan(mode=mode, points=points, hits_per_point=hits * max(len(levels), 1), reference=reference,
                        levels=levels)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def recorded_plan(rec: Any) -> dict:
    """The plan of a recording to replay: as stored, completed from its accepted hits."""
    plan = dict(rec.plan)
    hits = list(rec.hits(accepted_only=True, skip_damaged=True))
    order: list = []
    for h in hits:
        if h.measurement not in [m for m, _, _ in order]:
            order.append((h.measurement, h.point, h.reference))
    if plan.get("mode") not in ("roving_hammer", "roving_accelerometer"):
        refs = {r for _, _, r in order}
        plan["mode"] = "roving_hammer" if len(refs) > 1 or len(order) == 1 else "roving_accelerometer"
        plan.pop("reference", None)
        if plan["mode"] == "roving_accelerometer":
            plan["reference"] = order[0][2]
    if not plan.get("points"):
        plan["points"] = [p for _, p, _ in order]
    if "hits_per_point" not in plan and order:
        plan["hits_per_point"] = min(sum(1 for h in hits if h.measurement == m) for m, _, _ in order)
    return plan


def recorded_test(args: argparse.Namespace) -> tuple:
    """What ``--resume REC.h5`` continues: (set-up, plan, windows, recorded hits, device URL or None),
    after checking that no option tries to change the recorded plan (capture and station alike)."""
    from analysis.recording import Recording

    from .session import TestPlan
    from .setup import AcquisitionSetup

    if args.out or args.points or args.reference or args.mode or args.setup or args.hits is not None:
        raise UsageError("--resume continues the recorded test as it was planned: drop --out, --points, --reference, "
                         "--mode, --hits and --setup")
    path = Path(args.resume)
    with Recording(path) as rec:
        try:
            setup = AcquisitionSetup.from_dict(rec.setup)
            planned = dict(rec.plan)
            device = planned.pop("device", None)
            fields: dict[str, Any] = {k: (tuple(v) if k == "points" else v) for k, v in planned.items()
                                      if k in ("mode", "points", "hits_per_point", "reference", "levels")}
            fields["levels"] = tuple(fields.get("levels", ()))
            plan = TestPlan(**fields)
        except (SetupError, TypeError, ValueError) as exc:
            raise UsageError(f"{path} does not hold a capture plan and set-up to resume ({exc})") from None
        windows = rec.windows
        hits = list(rec.hits(skip_damaged=True))
    return setup, plan, windows, hits, device


def recorded_auto(path: str | Path) -> bool:
    """Whether the recording's hits were accepted automatically (``capture --auto``): its resume then
    goes on without asking the operator."""
    from analysis.recording import Recording

    with Recording(path) as rec:
        return bool(dict(rec.plan).get("auto", False))
