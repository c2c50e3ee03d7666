"""The one factory of the simulated analyser: :func:`create_analyser` builds the firmware from URL
query options (``sim://``, ``usbsim://``) and wraps it with fault injection when asked."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from simulator.capture import StandLike
from simulator.commands import DEFAULT_SERIAL
from simulator.faults import FAULT_OPTION_KEYS, FaultPlan, FaultyFirmware
from simulator.firmware import Firmware

__all__ = ["create_analyser"]


def create_analyser(options: Mapping[str, Any] | None = None,
                    stand: StandLike | None = None) -> Firmware | FaultyFirmware:
    """A firmware from URL query options.

    Options (all optional): ``seed`` (int, default 0), ``config`` (path of a frame TOML file),
    ``noise`` (bool, default True: sensor and ADC noise on), ``plan`` (ignored by the firmware;
    the stand uses it), ``replay`` (path of a recording: ``simulator.replay_stand.ReplayStand``
    plays its hits back instead of simulating), ``packetized`` (bool), ``serial`` (str), ``polls`` (GET STATUS polls
    before the strike, default 1), ``max_strikes`` (default 3); ``levels``, ``per_level``: the
    simulated operator strikes ``per_level`` hits at each of these factors of the usual force in turn
    (:mod:`simulator.operator_levels`); ``faults``, ``fault_seed``, ``fault_gone_calls``,
    ``fault_slow_s``: fault injection, the firmware comes wrapped in
    :class:`simulator.faults.FaultyFirmware` (same interface). ``stand`` injects a ready stand
    (e.g. a :class:`PrecomputedStand`); otherwise ``simulator.stand.TestStand`` is built.
    """
    opts = dict(options or {})
    fault_opts = {k: opts.pop(k) for k in FAULT_OPTION_KEYS if k in opts}
    fw = _create_firmware(opts, stand)
    if not fault_opts.get("faults"):
        extra = sorted(set(fault_opts) - {"faults"})
        if extra:
            raise ValueError(f"simulator option(s) {extra} need faults=KIND:P,... as well")
        return fw
    if "seed" in opts and "fault_seed" not in fault_opts:
        fault_opts["seed"] = opts["seed"]
    return FaultyFirmware(fw, FaultPlan.from_options(fault_opts))


def _create_firmware(opts: Mapping[str, Any], stand: StandLike | None) -> Firmware:
    """The plain firmware from the options without the fault keys."""
    from simulator.operator_levels import LEVEL_OPTION_KEYS, LevelledStand, levels_from_options

    known = {"seed", "config", "noise", "plan", "packetized", "serial", "polls", "max_strikes", "replay",
             *LEVEL_OPTION_KEYS}
    unknown = set(opts) - known
    if unknown:
        raise ValueError(f"unknown simulator option(s) {sorted(unknown)}; known: {', '.join(sorted(known))}")
    levels = levels_from_options(opts)
    if stand is None:
        stand = _build_stand(opts)
    if levels is not None:
        stand = LevelledStand(stand, *levels)
    try:
        polls = int(opts.get("polls", 1))
        max_strikes = int(opts.get("max_strikes", 3))
    except (TypeError, ValueError):
        raise ValueError("simulator options 'polls' and 'max_strikes' must be integers") from None
    fw = Firmware(stand, packetized=_as_bool(opts.get("packetized", False), "packetized"),
                  serial=str(opts.get("serial", DEFAULT_SERIAL)), strike_after_polls=polls,
                  max_strikes=max_strikes)
    fw.prepare()
    return fw


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
    import dataclasses

    from simulator.config import FrameConfig
    from simulator.nonlinear_joint import make_stand

    cfg = FrameConfig.load(opts.get("config") or None)
    if "noise" in opts:
        cfg = dataclasses.replace(cfg, noise=dataclasses.replace(cfg.noise, enabled=_as_bool(opts["noise"], "noise")))
    return make_stand(cfg, seed=int(opts.get("seed", 0)))
