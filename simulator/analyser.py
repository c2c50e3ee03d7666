"""The one factory of simulated analysers: firmware + stand (+ fault injection) from URL options.

Every simulator door (``sim://``, ``usbsim://``, ``python -m simulator serve``) builds its device
here, so a URL's options mean the same thing whatever the door.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

from simulator.faults import FaultPlan, FaultyFirmware
from simulator.firmware import DEFAULT_SERIAL, Firmware, StandLike

__all__ = ["create_analyser", "FIRMWARE_OPTIONS", "FAULT_OPTIONS"]

#: options the plain firmware understands
FIRMWARE_OPTIONS = frozenset({"seed", "config", "noise", "plan", "packetized", "serial", "polls", "max_strikes",
                              "replay"})
#: options of the fault injection (``simulator.faults``)
FAULT_OPTIONS = ("faults", "fault_seed", "fault_gone_calls", "fault_slow_s")


def create_analyser(options: "Mapping[str, Any] | None" = None, stand: "StandLike | None" = None) -> Any:
    """A simulated analyser from URL query options: a :class:`~simulator.firmware.Firmware`, wrapped
    in a :class:`~simulator.faults.FaultyFirmware` (same interface) when ``faults`` is given.

    Options (all optional): ``seed`` (int, default 0), ``config`` (path of a frame TOML file),
    ``noise`` (bool, default True: sensor and ADC noise on), ``plan`` (ignored by the firmware;
    the stand uses it), ``replay`` (path of a recording: ``simulator.replay_stand.ReplayStand``
    plays its hits back instead of simulating), ``packetized`` (bool), ``serial`` (str), ``polls``
    (GET STATUS polls before the strike, default 1), ``max_strikes`` (default 3); ``faults``,
    ``fault_seed``, ``fault_gone_calls``, ``fault_slow_s``: fault injection
    (``docs/reliability.md``). ``stand`` injects a ready stand (e.g. a
    :class:`~simulator.firmware.PrecomputedStand`); otherwise ``simulator.stand.TestStand`` is built.
    Raises ``ValueError`` naming an unknown option or a bad value.
    """
    opts = dict(options or {})
    fault_opts = {k: opts.pop(k) for k in FAULT_OPTIONS if k in opts}
    if fault_opts and not fault_opts.get("faults"):
        extra = sorted(set(fault_opts) - {"faults"})
        if extra:
            raise ValueError(f"simulator option(s) {extra} need faults=KIND:P,... as well")
    unknown = set(opts) - FIRMWARE_OPTIONS
    if unknown:
        raise ValueError(f"unknown simulator option(s) {sorted(unknown)}; known: "
                         f"{', '.join(sorted(FIRMWARE_OPTIONS | set(FAULT_OPTIONS)))}")
    if stand is None:
        stand = _build_stand(opts)
    try:
        polls = int(opts.get("polls", 1))
        max_strikes = int(opts.get("max_strikes", 3))
    except (TypeError, ValueError):
        raise ValueError("simulator options 'polls' and 'max_strikes' must be integers") from None
    fw = Firmware(stand, packetized=_as_bool(opts.get("packetized", False), "packetized"),
                  serial=str(opts.get("serial", DEFAULT_SERIAL)), strike_after_polls=polls,
                  max_strikes=max_strikes)
    fw.prepare()
    if not fault_opts.get("faults"):
        return fw
    if "seed" in opts and "fault_seed" not in fault_opts:
        fault_opts["seed"] = opts["seed"]
    return FaultyFirmware(fw, FaultPlan.from_options(fault_opts))


def _as_bool(value: Any, name: str) -> bool:
    if isinstance(value, str):
        if value.lower() in ("1", "on", "true", "yes"):
            return True
        if value.lower() in ("0", "off", "false", "no"):
            return False
        raise ValueError(f"simulator option {name}={value!r}: use on or off")
    return bool(value)


def _build_stand(opts: Mapping[str, Any]) -> StandLike:
    if opts.get("replay"):
        from simulator.replay_stand import ReplayStand

        return ReplayStand(str(opts["replay"]))
    from simulator.config import FrameConfig
    from simulator.stand import TestStand

    cfg = FrameConfig.load(opts.get("config") or None)
    if "noise" in opts:
        cfg = dataclasses.replace(cfg, noise=dataclasses.replace(cfg.noise, enabled=_as_bool(opts["noise"], "noise")))
    return TestStand(config=cfg, seed=int(opts.get("seed", 0)))
