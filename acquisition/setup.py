"""The operator's vocabulary for an impact test set-up, validated against the analyser's capabilities.

A set-up is plain data (dataclasses) that round-trips through a plain dict (JSON/TOML, the
``--setup FILE`` option and the recording's stored set-up). :func:`validate_setup` checks every
value against :class:`Capabilities` *before* anything is written to the analyser and raises
:class:`acquisition.errors.SetupError` naming the value and the allowed ones.

Units: sample rate Hz; ranges volts peak at the analyser input; sensitivities mV/N (force) or
mV/g (acceleration, g = 9.80665 m/s^2); trigger level in the trigger channel's engineering unit
(N for force, m/s^2 for acceleration); pre-trigger in samples. Engineering units of the data are
SI: N and m/s^2. Bandwidth = fs / 2.56.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from acquisition import protocol
from acquisition.errors import SetupError
from analysis.frf import analyser_band_hz
from analysis.modal import decay_time_s
from analysis.points import PointLabelError, parse_point

__all__ = [
    "G", "ChannelSetup", "TriggerSetup", "AcquisitionSetup", "Capabilities", "validate_setup",
    "default_setup", "setup_to_wire", "setup_from_wire", "load_setup", "DEFAULT_SLOWEST_MODE", "DEFAULT_DECAY_DB",
    "block_size_for_decay", "setup_to_toml",
]

#: standard gravity, m/s^2 (mV/g -> mV/(m/s^2))
G = 9.80665
_UNIT_OF = {"force": "mV/N", "acceleration": "mV/g"}
_EU_OF = {"force": "N", "acceleration": "m/s^2"}


@dataclass(frozen=True)
class ChannelSetup:
    """One analyser input as the operator sets it up.

    ``sensitivity`` in ``sensitivity_unit`` (mV/N for force, mV/g for acceleration);
    ``range_v`` volts peak; ``point`` a label ``component:node:direction``.
    """

    name: str
    point: str
    quantity: str = "acceleration"
    sensitivity: float = 100.0
    sensitivity_unit: str = "mV/g"
    coupling: str = "AC"
    iepe: bool = True
    range_v: float = 5.0

    @property
    def volts_per_unit(self) -> float:
        """Sensitivity in volts per SI engineering unit: V/N, or V/(m/s^2) (mV/g * 1e-3 / 9.80665)."""
        v = self.sensitivity * 1e-3
        return v / G if self.sensitivity_unit == "mV/g" else v

    @property
    def unit(self) -> str:
        """The SI engineering unit of this channel's data: ``"N"`` or ``"m/s^2"``."""
        return _EU_OF.get(self.quantity, "?")


@dataclass(frozen=True)
class TriggerSetup:
    """Trigger on channel index ``channel`` crossing ``level`` (engineering units) with ``slope``;
    the block keeps ``pretrigger_samples`` samples before the crossing."""

    channel: int = 0
    level: float = 10.0
    slope: str = "rising"
    pretrigger_samples: int = 128


@dataclass(frozen=True)
class AcquisitionSetup:
    """Sample rate (Hz), block size (samples per channel), channels and trigger."""

    sample_rate_hz: float
    block_size: int
    channels: tuple[ChannelSetup, ...]
    trigger: TriggerSetup = field(default_factory=TriggerSetup)

    def __post_init__(self) -> None:
        object.__setattr__(self, "channels", tuple(self.channels))

    @property
    def bandwidth_hz(self) -> float:
        """Alias-free bandwidth (Hz): :func:`analysis.frf.analyser_band_hz` of the sample rate."""
        return analyser_band_hz(self.sample_rate_hz)

    @property
    def record_s(self) -> float:
        """Length of one record (block), s."""
        return self.block_size / self.sample_rate_hz

    @property
    def pretrigger_s(self) -> float:
        """Time recorded before the trigger, s."""
        return self.trigger.pretrigger_samples / self.sample_rate_hz

    @property
    def duration_s(self) -> float:
        """Block length in seconds."""
        return self.block_size / self.sample_rate_hz

    def to_dict(self) -> dict[str, Any]:
        """A plain dict (JSON/TOML-able)."""
        return {
            "sample_rate_hz": self.sample_rate_hz,
            "block_size": self.block_size,
            "channels": [asdict(ch) for ch in self.channels],
            "trigger": asdict(self.trigger),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> AcquisitionSetup:
        """Inverse of :meth:`to_dict`; unknown or missing keys raise SetupError naming them."""
        if not isinstance(data, Mapping):
            raise SetupError(f"a set-up must be a mapping (JSON object / TOML table), got {type(data).__name__}")
        _check_keys("set-up", data, {"sample_rate_hz", "block_size", "channels"}, {"trigger"})
        chans = data["channels"]
        if not isinstance(chans, (list, tuple)) or not chans:
            raise SetupError("set-up 'channels' must be a non-empty list of channel tables")
        channels = []
        for i, ch in enumerate(chans):
            if not isinstance(ch, Mapping):
                raise SetupError(f"set-up channel {i} must be a table, got {type(ch).__name__}")
            _check_keys(f"channel {i}", ch, {"name", "point"}, set(ChannelSetup.__dataclass_fields__) - {"name", "point"})
            channels.append(ChannelSetup(**ch))
        trig = data.get("trigger", {})
        if not isinstance(trig, Mapping):
            raise SetupError("set-up 'trigger' must be a table")
        _check_keys("trigger", trig, set(), set(TriggerSetup.__dataclass_fields__))
        try:
            setup = cls(float(data["sample_rate_hz"]), int(data["block_size"]), tuple(channels), TriggerSetup(**trig))
        except (TypeError, ValueError, OverflowError) as exc:
            raise SetupError(f"set-up has a value of the wrong type: {exc}") from None
        _check_timing(setup, data["block_size"])
        return setup


def _check_timing(setup: AcquisitionSetup, block_size: Any) -> None:
    """The sample rate and the block read from a file, each with its own message, before anything (a
    window, the analyser's offer) is derived from them: a positive rate, a whole block that holds samples
    after the trigger's pre-trigger samples."""
    if not (math.isfinite(setup.sample_rate_hz) and setup.sample_rate_hz > 0):
        raise SetupError(f"set-up sample_rate_hz = {setup.sample_rate_hz:g} must be a positive number of Hz")
    pre = setup.trigger.pretrigger_samples
    if isinstance(block_size, bool) or block_size != setup.block_size or setup.block_size <= max(pre, 1):
        raise SetupError(f"set-up block_size = {block_size!r} must be a whole number of samples above the "
                         f"trigger's pretrigger_samples ({pre}): give one of the analyser's block sizes, e.g. 8192")


def _check_keys(what: str, data: Mapping[str, Any], required: set[str], optional: set[str]) -> None:
    missing = required - set(data)
    unknown = set(data) - required - optional
    if missing:
        raise SetupError(f"{what} is missing {sorted(missing)}")
    if unknown:
        raise SetupError(f"{what} has unknown key(s) {sorted(unknown)}; allowed: {sorted(required | optional)}")


@dataclass(frozen=True)
class Capabilities:
    """The analyser's capabilities in operator units (volts, Hz)."""

    n_inputs: int
    sample_rates_hz: tuple[float, ...]
    ranges_v: tuple[float, ...]
    block_sizes: tuple[int, ...]
    couplings: tuple[str, ...] = ("AC", "DC")
    iepe: bool = True
    trigger_any_channel: bool = True
    adc_bits: int = 16
    max_pretrigger: int = 32768
    max_transfer: int = protocol.MAX_TRANSFER

    @classmethod
    def from_wire(cls, caps: protocol.CapabilitiesData) -> Capabilities:
        couplings = tuple(c for c, ok in (("AC", caps.ac), ("DC", caps.dc)) if ok)
        return cls(caps.n_inputs, tuple(float(r) for r in caps.sample_rates_hz),
                   tuple(m / 1000.0 for m in caps.ranges_mv), tuple(caps.block_sizes), couplings, caps.iepe,
                   caps.trigger_any_channel, caps.adc_bits, caps.max_pretrigger, caps.max_transfer)

    def bandwidths_hz(self) -> tuple[float, ...]:
        """The alias-free bandwidth (Hz) of each allowed rate."""
        return tuple(analyser_band_hz(fs) for fs in self.sample_rates_hz)


def _fmt(values: Any) -> str:
    return ", ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in values)


def validate_setup(setup: AcquisitionSetup, caps: Capabilities) -> None:
    """Raise SetupError for the first value outside ``caps`` (the message lists the allowed values)."""
    if not any(math.isclose(setup.sample_rate_hz, r, rel_tol=1e-9) for r in caps.sample_rates_hz):
        raise SetupError(f"sample rate {setup.sample_rate_hz:g} Hz is not offered; choose one of "
                         f"{_fmt(caps.sample_rates_hz)} Hz")
    if setup.block_size not in caps.block_sizes:
        raise SetupError(f"block size {setup.block_size} is not offered; choose one of {_fmt(caps.block_sizes)}")
    n = len(setup.channels)
    if not 1 <= n <= caps.n_inputs:
        raise SetupError(f"{n} channels set up; the analyser has 1..{caps.n_inputs} inputs")
    names = [ch.name for ch in setup.channels]
    if len(set(names)) != n:
        raise SetupError(f"channel names must be unique, got {names}")
    for i, ch in enumerate(setup.channels):
        where = f"channel {i} ({ch.name!r})"
        try:
            parse_point(ch.point)
        except PointLabelError as exc:
            raise SetupError(f"{where}: {exc}") from None
        if len(ch.point.encode("ascii", errors="replace")) > 24:
            raise SetupError(f"{where}: point label {ch.point!r} is longer than 24 characters")
        if ch.quantity not in _UNIT_OF:
            raise SetupError(f"{where}: quantity {ch.quantity!r} must be 'force' or 'acceleration'")
        if ch.sensitivity_unit != _UNIT_OF[ch.quantity]:
            raise SetupError(f"{where}: a {ch.quantity} sensor's sensitivity is given in "
                             f"{_UNIT_OF[ch.quantity]}, not {ch.sensitivity_unit!r}")
        if not (math.isfinite(ch.sensitivity) and ch.sensitivity > 0):
            raise SetupError(f"{where}: sensitivity {ch.sensitivity} {ch.sensitivity_unit} must be positive")
        if ch.coupling not in caps.couplings:
            raise SetupError(f"{where}: coupling {ch.coupling!r} is not offered; choose one of {_fmt(caps.couplings)}")
        if ch.iepe and not caps.iepe:
            raise SetupError(f"{where}: this analyser has no IEPE supply; set iepe = false")
        if ch.iepe and ch.coupling != "AC":
            raise SetupError(f"{where}: IEPE sensors need AC coupling (the IEPE bias is DC); set coupling = 'AC'")
        if not any(math.isclose(ch.range_v, r, rel_tol=1e-9) for r in caps.ranges_v):
            raise SetupError(f"{where}: input range {ch.range_v:g} V is not offered; choose one of "
                             f"{_fmt(caps.ranges_v)} V")
    trig = setup.trigger
    if not 0 <= trig.channel < n:
        raise SetupError(f"trigger channel {trig.channel} does not exist; choose 0..{n - 1}")
    if trig.slope not in protocol.SLOPES:
        raise SetupError(f"trigger slope {trig.slope!r} must be one of {_fmt(protocol.SLOPES)}")
    limit = min(caps.max_pretrigger, setup.block_size - 1)
    if not 0 <= trig.pretrigger_samples <= limit:
        raise SetupError(f"pre-trigger of {trig.pretrigger_samples} samples is outside 0..{limit}")
    ch = setup.channels[trig.channel]
    level_v = trig.level * ch.volts_per_unit
    if not math.isfinite(level_v) or abs(level_v) >= ch.range_v:
        raise SetupError(f"trigger level {trig.level:g} {ch.unit} is {level_v:g} V at the input, outside the "
                         f"{ch.range_v:g} V range of channel {trig.channel}; lower the level or raise the range")


def setup_to_wire(setup: AcquisitionSetup) -> protocol.SetupData:
    """The wire set-up (sensitivity in V per SI unit, range in mV, trigger level in volts)."""
    trig = setup.trigger
    level_v = trig.level * setup.channels[trig.channel].volts_per_unit
    chans = tuple(protocol.ChannelRecord(i, ch.coupling, ch.iepe, ch.quantity, int(round(ch.range_v * 1000)),
                                         ch.volts_per_unit, ch.point) for i, ch in enumerate(setup.channels))
    return protocol.SetupData(int(round(setup.sample_rate_hz)), setup.block_size, trig.pretrigger_samples,
                              trig.channel, trig.slope, level_v, chans)


def _decimal(x: float) -> float:
    """Undo float round-off of a unit conversion (operator values have far fewer than 12 digits)."""
    return float(f"{x:.12g}")


def setup_from_wire(data: protocol.SetupData, names: list[str] | None = None) -> AcquisitionSetup:
    """Rebuild an operator set-up from the wire (names default to ``ch0``...; sensitivities back in mV/N, mV/g)."""
    chans = []
    for i, rec in enumerate(data.channels):
        unit = _UNIT_OF[rec.quantity]
        sens = _decimal(rec.sensitivity * 1e3 * (G if unit == "mV/g" else 1.0))
        chans.append(ChannelSetup(names[i] if names else f"ch{i}", rec.point, rec.quantity, sens, unit,
                                  rec.coupling, rec.iepe, rec.range_mv / 1000.0))
    trig_ch = data.trigger_channel
    vpu = chans[trig_ch].volts_per_unit if trig_ch < len(chans) else 1.0
    trig = TriggerSetup(trig_ch, _decimal(data.trigger_level_v / vpu), data.trigger_slope, data.pretrigger)
    return AcquisitionSetup(float(data.sample_rate_hz), data.block_size, tuple(chans), trig)


#: the slowest-decaying mode of the simulated frame in the default band: natural frequency (Hz) and
#: damping ratio (simulator/frame.toml: 12.9 Hz at 0.86 %; decay time constant 1/(zeta omega) = 1.43 s)
DEFAULT_SLOWEST_MODE = (12.9, 0.0086)
#: how far (dB) the slowest mode's free decay falls within the default record: 30 dB leaves about 3 % of
#: its amplitude at the block end, so the truncation's leakage stays a few per cent of its peak
DEFAULT_DECAY_DB = 30.0
#: the SigLab-like analyser's block sizes (samples per channel)
_BLOCK_SIZES = tuple(protocol.SIGLAB_2042.block_sizes)


def block_size_for_decay(sample_rate_hz: float, freq_hz: float, damping: float, *,
                         decay_db: float = DEFAULT_DECAY_DB, pretrigger_samples: int = 0,
                         block_sizes: tuple[int, ...] = _BLOCK_SIZES) -> int:
    """The smallest of ``block_sizes`` whose samples after the trigger (block minus pre-trigger)
    span :func:`analysis.modal.decay_time_s` of the mode at ``sample_rate_hz`` (Hz): a record in which
    that mode decays by ``decay_db`` dB. SetupError when even the largest block is too short (lower the
    sample rate or use an exponential window), or the mode or decay is not positive."""
    try:
        need = decay_time_s(freq_hz, damping, decay_db) * sample_rate_hz + pretrigger_samples
    except ValueError as exc:
        raise SetupError(f"{exc}: give the slowest mode's frequency and damping") from exc
    for n in sorted(block_sizes):
        if n >= need:
            return int(n)
    raise SetupError(f"a {freq_hz:g} Hz mode with {100 * damping:.3g} % damping needs {need / sample_rate_hz:.3g} s "
                     f"to decay {decay_db:g} dB; the largest block ({max(block_sizes)} samples) at "
                     f"{sample_rate_hz:g} Hz is {max(block_sizes) / sample_rate_hz:.3g} s: lower the sample rate or "
                     "use an exponential window")


def default_setup() -> AcquisitionSetup:
    """The simulated frame's default test plan: hammer at right:6:-X (2.25 mV/N, 1 V range =
    444 N), accelerometers at left:9:Y, top:4:X, right:4:-Z (100 mV/g, 5 V range = 51 g), all IEPE
    with AC coupling; 6400 Hz (2500 Hz bandwidth, above the frame's modes of interest); 8192 samples
    (1.28 s, df 0.78 Hz); trigger on the force at 20 N rising with 128 samples pre-trigger.

    The slowest mode of the band (:data:`DEFAULT_SLOWEST_MODE`, 12.9 Hz) keeps about half its
    amplitude at the end of this record, so its peak leaks; a record in which it decays by
    :data:`DEFAULT_DECAY_DB` is :func:`block_size_for_decay` (32768 samples, 5.12 s), at four times
    the lines to fit and with more noise per line unless a force window and an exponential window are
    used. Measured on the default capture (``benchmarks/accuracy/bench_record_length.py``,
    docs/fitting.md): the leakage shows as +5 % on that mode's damping; 2.56 s and 5.12 s records
    lower the coherence (their tails add noise after the responses have decayed) and double or
    quadruple the fit's lines, so this record stays the default; ``--exp-window 5%`` gives the
    damping within 0.5 % and a higher coherence. ``capture --print-setup`` writes this set-up as a
    template to edit.

    The ranges leave generous headroom over the simulated frame's peaks with the default hammer
    (about 107 N, 0.24 V; accelerations up to about 38 m/s^2, 0.39 V, over the test plan's points),
    so a hard or double hit does not overload."""
    hammer = ChannelSetup("force", "right:6:-X", "force", 2.25, "mV/N", "AC", True, 1.0)
    accels = tuple(ChannelSetup(f"acc{i + 1}", p, "acceleration", 100.0, "mV/g", "AC", True, 5.0)
                   for i, p in enumerate(("left:9:Y", "top:4:X", "right:4:-Z")))
    fs, pre = 6400.0, 128
    return AcquisitionSetup(fs, 8192, (hammer,) + accels, TriggerSetup(0, 20.0, "rising", pre))


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    return '"' + str(v).replace("\\", "\\\\").replace('"', '\\"') + '"'


def setup_to_toml(setup: AcquisitionSetup) -> str:
    """The set-up as a commented TOML document that ``--setup FILE.toml`` reads back
    (:func:`load_setup`): a template to edit."""
    d = setup.to_dict()
    lines = ["# impact test set-up (capture --setup FILE.toml); units: Hz, samples, mV/N or mV/g, V peak,",
             "# trigger level in the trigger channel's unit (N or m/s^2)",
             f"# record length {setup.duration_s:g} s, bandwidth {setup.bandwidth_hz:g} Hz",
             f"sample_rate_hz = {_toml_value(d['sample_rate_hz'])}",
             f"block_size = {_toml_value(d['block_size'])}", "", "[trigger]"]
    lines += [f"{k} = {_toml_value(v)}" for k, v in d["trigger"].items()]
    for ch in d["channels"]:
        lines += ["", "[[channels]]"] + [f"{k} = {_toml_value(v)}" for k, v in ch.items()]
    return "\n".join(lines) + "\n"


def load_setup(path: str | Path) -> AcquisitionSetup:
    """Read a set-up from a ``.json`` or ``.toml`` file (the layout of :meth:`AcquisitionSetup.to_dict`)."""
    from .textdoc import read_document

    data = read_document(path, "set-up file (--setup)", SetupError)
    return AcquisitionSetup.from_dict(data)
