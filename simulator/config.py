"""Configuration of the simulated frame: ``simulator/frame.toml`` defaults, merged with a user file.

The defaults file is also the schema: a user file may only use keys that exist there (except new
named entries under ``[sections.*]`` and ``[components.*]``, which start from the first default
entry of their table). Tables merge key by key; other values replace. Every section becomes a
plain frozen dataclass; :attr:`FrameConfig.raw` keeps the merged dictionary.
"""
from __future__ import annotations

import copy
import dataclasses
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from analysis.input_limits import DOCUMENT_LIMIT_BYTES, NESTING_LIMIT, read_bounded_text, too_deeply_nested
from analysis.points import PointLabelError, parse_point

from .errors import ConfigError

_toml: Any
if sys.version_info >= (3, 11):
    import tomllib as _toml
else:  # pragma: no cover - Python 3.10
    try:
        import tomli as _toml
    except ModuleNotFoundError:
        _toml = None


__all__ = [
    "ConfigError",
    "DEFAULT_CONFIG_PATH",
    "FrameConfig",
    "MaterialConfig",
    "SectionConfig",
    "ComponentConfig",
    "SupportsConfig",
    "JointsConfig",
    "DamageConfig",
    "DampingConfig",
    "ModesConfig",
    "AccelerometerConfig",
    "ForceSensorConfig",
    "SensorsConfig",
    "HammerConfig",
    "FrontendConfig",
    "SamplingConfig",
    "TestPlanConfig",
    "NoiseConfig",
    "NonlinearConfig",
    "NONLINEAR_LAWS",
    "overrides_to_toml",
    "check_fe_memory",
]

DEFAULT_CONFIG_PATH = Path(__file__).with_name("frame.toml")
_NAMED_TABLES = ("sections", "components")


@dataclass(frozen=True)
class MaterialConfig:
    """Isotropic material: E (Pa), Poisson ratio (-), density (kg/m^3)."""

    youngs_modulus_pa: float
    poisson_ratio: float
    density_kg_m3: float


@dataclass(frozen=True)
class SectionConfig:
    """A cross section; see :func:`simulator.fem.section_properties` for the shapes."""

    shape: str
    width_m: float
    depth_m: float
    wall_m: float
    area_m2: float
    iy_m4: float
    iz_m4: float
    j_m4: float


@dataclass(frozen=True)
class ComponentConfig:
    """A straight member from ``start_m`` to ``end_m`` (m), ``n_elements`` elements, section roll (deg)."""

    section: str
    start_m: tuple
    end_m: tuple
    n_elements: int
    roll_deg: float


@dataclass(frozen=True)
class SupportsConfig:
    """Ground springs at ``nodes`` (``component:node``): 3 x N/m, 3 x N m/rad."""

    nodes: tuple
    stiffness: tuple


@dataclass(frozen=True)
class JointsConfig:
    """Springs joining node pairs: 3 x N/m, 3 x N m/rad."""

    pairs: tuple
    stiffness: tuple


@dataclass(frozen=True)
class DamageConfig:
    """Local damage: cracked elements (bending stiffness factor), soft joints and loose supports
    (factor on their six springs); see ``[damage]`` in frame.toml."""

    cracked_elements: tuple
    crack_bending_factor: tuple
    soft_joints: tuple
    soft_joint_factor: tuple
    loose_supports: tuple
    loose_support_factor: tuple

    def bending_factors(self, component: str, n_elements: int) -> list[float]:
        """Bending stiffness factor (-) of each element of ``component`` (1 where undamaged)."""
        f = [1.0] * n_elements
        for where, k in zip(self.cracked_elements, self.crack_bending_factor):
            comp, _, e = str(where).partition(":")
            if comp == component:
                f[int(e)] *= float(k)
        return f

    def spring_factor(self, kind: str, nodes: tuple[str, ...]) -> float:
        """Factor (-) on the springs of a support (``kind="support"``, its node) or a joint
        (``kind="joint"``, its two nodes)."""
        places, factors = ((self.loose_supports, self.loose_support_factor) if kind == "support"
                           else (self.soft_joints, self.soft_joint_factor))
        f = 1.0
        for where, k in zip(places, factors):
            if where in nodes:
                f *= float(k)
        return f


@dataclass(frozen=True)
class DampingConfig:
    """Proportional damping: per-mode list (``model="modal"``) or Rayleigh."""

    model: str
    zeta: tuple
    zeta_default: float
    rayleigh_alpha: float
    rayleigh_beta: float

    def ratios(self, freq_hz: np.ndarray) -> np.ndarray:
        """Damping ratio of each mode (ascending ``freq_hz``, Hz). Rigid-body (0 Hz) modes get 0 and
        do not use up an entry of the ``zeta`` list."""
        f = np.asarray(freq_hz, dtype=float)
        out = np.zeros(f.size)
        flex = np.flatnonzero(f > 0)
        if self.model == "rayleigh":
            w = 2 * np.pi * f[flex]
            out[flex] = self.rayleigh_alpha / (2 * w) + self.rayleigh_beta * w / 2
        else:
            z = list(self.zeta)
            out[flex] = [z[i] if i < len(z) else self.zeta_default for i in range(flex.size)]
        return out


@dataclass(frozen=True)
class ModesConfig:
    """Modal truncation: keep modes up to ``max_freq_hz`` (Hz)."""

    max_freq_hz: float


@dataclass(frozen=True)
class AccelerometerConfig:
    """Accelerometer: mass (kg), sensitivity (mV/g), noise density (g/sqrt(Hz)), IEPE high-pass corner (Hz)."""

    mass_kg: float
    sensitivity_mv_per_g: float
    noise_density_g_per_rthz: float
    iepe_highpass_hz: float


@dataclass(frozen=True)
class ForceSensorConfig:
    """Hammer force sensor: sensitivity (mV/N), noise density (N/sqrt(Hz)), IEPE high-pass corner (Hz)."""

    sensitivity_mv_per_n: float
    noise_density_n_per_rthz: float
    iepe_highpass_hz: float


@dataclass(frozen=True)
class SensorsConfig:
    mass_loading: bool
    accelerometer: AccelerometerConfig
    force: ForceSensorConfig


@dataclass(frozen=True)
class HammerConfig:
    """Impact hammer; see ``[hammer]`` in frame.toml for the meaning of each field."""

    tip: str
    shape: str
    amplitude_n: float
    amplitude_scatter: float
    width_scatter: float
    neighbour_probability: float
    double_hit_probability: float
    double_hit_delay_s: tuple
    double_hit_ratio: tuple
    trigger_offset_samples: tuple
    tips: Mapping[str, float]

    @property
    def width_s(self) -> float:
        """Nominal pulse width (s) of the selected tip."""
        return float(self.tips[self.tip])


@dataclass(frozen=True)
class FrontendConfig:
    """Analyser front-end defaults (anti-alias filter, AC coupling, ADC)."""

    anti_alias: str
    anti_alias_order: int
    anti_alias_passband_ripple_db: float
    anti_alias_stopband_db: float
    anti_alias_cutoff_fraction: float
    ac_coupling_hz: float
    adc_bits: int
    ranges_v: tuple
    #: the converter's own noise (transition noise and the input amplifier), rms in counts; it
    #: dithers the quantizer, as in every real ADC (see ``[frontend]`` in frame.toml)
    adc_noise_lsb_rms: float = 0.5


@dataclass(frozen=True)
class SamplingConfig:
    """The stand's sampling model (see ``[sampling]`` in frame.toml and :mod:`simulator.frontend`)."""

    band_limit: bool
    oversample: int
    fir_half_length: int
    stopband_db: float


@dataclass(frozen=True)
class TestPlanConfig:
    """Default test plan: roving hammer or roving sensor."""

    __test__ = False  # not a pytest test class

    mode: str
    reference: str
    sensors: tuple
    points: tuple
    averages: int


@dataclass(frozen=True)
class NoiseConfig:
    """Master switch of the sensor noise (``TestStand.strike(noise=...)`` overrides it)."""

    enabled: bool


NONLINEAR_LAWS = ("none", "iwan", "cubic")
_ROTATION_AXES = ("rx", "ry", "rz")


@dataclass(frozen=True)
class NonlinearConfig:
    """An amplitude-dependent rotational spring at one joint or support (see ``[nonlinear]`` in
    frame.toml and :mod:`simulator.nonlinear_joint`).

    law : "none" (linear frame), "iwan" (micro-slip friction: a bank of ``n_sliders`` Jenkins elements,
    stiffness falls and damping rises with amplitude) or "cubic" (``M = k0 theta + k3 theta^3``).
    joint : a node of a ``[joints]`` pair (the relative rotation of the pair) or a ``[supports]`` node
    (its rotation against the ground). axis : "rx", "ry" or "rz", the rotation about global X, Y, Z.
    slip_moment_nm : moment (N m) the slider bank carries in full slip (Iwan).
    residual_stiffness_fraction : share (-) of the joint's linear stiffness that never slips (Iwan).
    cubic_nm_per_rad3 : k3 (N m/rad^3) of the cubic law (> 0 hardening, < 0 softening).
    stiffness_nm_per_rad : the spring's small-amplitude stiffness k0 (N m/rad), replacing the joint's or
        support's rotational stiffness about ``axis`` in the linear model; 0 keeps that stiffness.
    integration_rate_hz : the lowest rate (Hz) of the time integration: a record sampled at fs is
        integrated with ``ceil(integration_rate_hz / fs)`` steps per sample.
    """

    law: str
    joint: str
    axis: str
    slip_moment_nm: float
    residual_stiffness_fraction: float
    n_sliders: int
    cubic_nm_per_rad3: float
    stiffness_nm_per_rad: float
    integration_rate_hz: float

    @property
    def active(self) -> bool:
        return self.law != "none"

    @property
    def axis_index(self) -> int:
        """0, 1 or 2: the rotation DOF (after the three translations) of ``axis``."""
        return _ROTATION_AXES.index(self.axis)

    def substeps(self, fs_hz: float) -> int:
        """Integration steps per sample at the sample rate ``fs_hz`` (Hz)."""
        return max(1, int(np.ceil(self.integration_rate_hz / fs_hz - 1e-9)))

    def spring_stiffness(self, nodes: tuple[str, ...], k6: tuple | list) -> list[float]:
        """The six stiffnesses of the support or joint at ``nodes``: ``k6`` with the rotational one about
        ``axis`` set to ``stiffness_nm_per_rad`` when this is the active nonlinear spring and the value is given."""
        k = [float(x) for x in k6]
        if self.active and self.stiffness_nm_per_rad > 0 and self.joint in nodes:
            k[3 + self.axis_index] = float(self.stiffness_nm_per_rad)
        return k


@dataclass(frozen=True)
class FrameConfig:
    """All parameters of the simulated frame (see ``simulator/frame.toml``)."""

    material: MaterialConfig
    sections: Mapping[str, SectionConfig]
    components: Mapping[str, ComponentConfig]
    supports: SupportsConfig
    joints: JointsConfig
    damage: DamageConfig
    damping: DampingConfig
    modes: ModesConfig
    sensors: SensorsConfig
    hammer: HammerConfig
    frontend: FrontendConfig
    sampling: SamplingConfig
    test_plan: TestPlanConfig
    noise: NoiseConfig
    nonlinear: NonlinearConfig
    raw: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)
    source: str = "defaults"

    @classmethod
    def load(cls, path: str | Path | None = None) -> FrameConfig:
        """Defaults from frame.toml, merged with the TOML file ``path`` if given."""
        if path is None:
            return cls.from_dict(None)
        user = _read_toml(Path(path))
        return cls.from_dict(user, source=str(path))

    @classmethod
    def from_dict(cls, overrides: Mapping[str, Any] | None = None, source: str = "overrides") -> FrameConfig:
        """Defaults merged with a nested dictionary shaped like frame.toml."""
        base = _defaults()
        merged = _merge(base, copy.deepcopy(dict(overrides or {})), source, ())
        return _build(merged, source if overrides else "defaults")

    def with_overrides(self, overrides: Mapping[str, Any]) -> FrameConfig:
        """A new config: this one's values merged with ``overrides`` (same rules as a user file)."""
        merged = _merge(copy.deepcopy(dict(self.raw)), copy.deepcopy(dict(overrides)), "overrides", ())
        return _build(merged, self.source)


def overrides_to_toml(overrides: Mapping[str, Any]) -> str:
    """TOML text of an overrides dictionary shaped like frame.toml (nested tables of numbers,
    strings, booleans and lists), readable by :meth:`FrameConfig.load`."""
    import json

    lines: list[str] = []

    def val(v: Any) -> str:
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(val(x) for x in v) + "]"
        if isinstance(v, (int, np.integer)):
            return str(int(v))
        return repr(float(v))

    def table(prefix: str, t: Mapping[str, Any]) -> None:
        scalars = {k: v for k, v in t.items() if not isinstance(v, Mapping)}
        if scalars and prefix:
            lines.append(f"[{prefix}]")
        lines.extend(f"{k} = {val(v)}" for k, v in scalars.items())
        for k, v in t.items():
            if isinstance(v, Mapping):
                table(f"{prefix}.{k}" if prefix else k, v)

    table("", overrides)
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------- reading and merging
def _read_toml(path: Path) -> dict:
    if _toml is None:  # pragma: no cover
        raise ConfigError("reading TOML needs Python 3.11+ (tomllib) or the 'tomli' package: pip install tomli")
    try:
        text = read_bounded_text(path, "config file", DOCUMENT_LIMIT_BYTES, ConfigError)
    except FileNotFoundError:
        raise ConfigError(f"config file {path} not found: give the path of a TOML file like simulator/frame.toml") from None
    except OSError as exc:
        raise ConfigError(f"config file {path} cannot be read ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"config file {path} is not UTF-8 text ({exc})") from None
    if too_deeply_nested(text, toml=True):
        raise ConfigError(f"config file {path} is nested too deeply to be a frame configuration (more than "
                          f"{NESTING_LIMIT} levels)")
    try:
        return _toml.loads(text)
    except _toml.TOMLDecodeError as exc:
        raise ConfigError(f"config file {path} is not valid TOML: {exc}") from None


_DEFAULTS_CACHE: dict | None = None


def _defaults() -> dict:
    global _DEFAULTS_CACHE
    if _DEFAULTS_CACHE is None:
        _DEFAULTS_CACHE = _read_toml(DEFAULT_CONFIG_PATH)
    return copy.deepcopy(_DEFAULTS_CACHE)


def _merge(base: dict, user: Mapping[str, Any], source: str, path: tuple) -> dict:
    if not isinstance(user, Mapping):
        raise ConfigError(f"{source}: [{'.'.join(path)}] must be a table")
    out = dict(base)
    for key, val in user.items():
        where = ".".join(path + (key,))
        if key not in base:
            if len(path) == 1 and path[0] in _NAMED_TABLES and isinstance(val, Mapping):
                template = copy.deepcopy(next(iter(base.values())))
                out[key] = _merge(template, val, source, path + (key,))
                continue
            known = ", ".join(sorted(base)) if base else "(none)"
            raise ConfigError(f"{source}: unknown key '{where}'; known keys here: {known}")
        if isinstance(base[key], dict):
            out[key] = _merge(base[key], val, source, path + (key,))
        else:
            if isinstance(val, Mapping):
                raise ConfigError(f"{source}: '{where}' must be a value, not a table")
            out[key] = val
    return out


# ---------------------------------------------------------------------------- building and checks
def _coerce(cls: type, d: Mapping[str, Any], where: str) -> Any:
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name not in d:
            continue
        v = d[f.name]
        t = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
        try:
            if t == "float":
                if isinstance(v, bool):
                    raise TypeError
                v = float(v)
            elif t == "int":
                if isinstance(v, bool) or int(v) != v:
                    raise TypeError
                v = int(v)
            elif t == "bool":
                if not isinstance(v, bool):
                    raise TypeError
            elif t == "str":
                if not isinstance(v, str):
                    raise TypeError
            elif t == "tuple":
                if not isinstance(v, (list, tuple)):
                    raise TypeError
                v = tuple(tuple(x) if isinstance(x, list) else x for x in v)
        except (TypeError, ValueError, OverflowError):
            raise ConfigError(f"'{where}.{f.name}' = {v!r} must be of type {t}") from None
        kwargs[f.name] = v
    return cls(**kwargs)


def _bool(v: Any, where: str) -> bool:
    if not isinstance(v, bool):
        raise ConfigError(f"'{where}' = {v!r} must be true or false")
    return v


def _check(cond: bool, message: str) -> None:
    if not cond:
        raise ConfigError(message)


def _build(d: dict, source: str) -> FrameConfig:
    try:
        cfg = FrameConfig(
            material=_coerce(MaterialConfig, d["material"], "material"),
            sections={k: _coerce(SectionConfig, v, f"sections.{k}") for k, v in d["sections"].items()},
            components={k: _coerce(ComponentConfig, v, f"components.{k}") for k, v in d["components"].items()},
            supports=_coerce(SupportsConfig, d["supports"], "supports"),
            joints=_coerce(JointsConfig, d["joints"], "joints"),
            damage=_coerce(DamageConfig, d["damage"], "damage"),
            damping=_coerce(DampingConfig, d["damping"], "damping"),
            modes=_coerce(ModesConfig, d["modes"], "modes"),
            sensors=SensorsConfig(
                mass_loading=_bool(d["sensors"]["mass_loading"], "sensors.mass_loading"),
                accelerometer=_coerce(AccelerometerConfig, d["sensors"]["accelerometer"], "sensors.accelerometer"),
                force=_coerce(ForceSensorConfig, d["sensors"]["force"], "sensors.force"),
            ),
            hammer=_coerce(HammerConfig, {**d["hammer"], "tips": {k: float(v) for k, v in d["hammer"]["tips"].items()}},
                           "hammer"),
            frontend=_coerce(FrontendConfig, d["frontend"], "frontend"),
            sampling=_coerce(SamplingConfig, d["sampling"], "sampling"),
            test_plan=_coerce(TestPlanConfig, d["test_plan"], "test_plan"),
            noise=_coerce(NoiseConfig, d["noise"], "noise"),
            nonlinear=_coerce(NonlinearConfig, d["nonlinear"], "nonlinear"),
            raw=d,
            source=source,
        )
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None
    _validate(cfg, source)
    _validate_bounds(cfg, source)
    return cfg


#: the largest magnitude of any number in a configuration: far beyond every physical value the keys
#: name (stiffnesses of 1e9 N/m, E of 2e11 Pa), far below where squares and products overflow
MAX_CONFIG_MAGNITUDE = 1e20
#: the range of ``[modes] max_freq_hz`` (Hz): from the lowest mode the eigen-solver keeps (omega^2 > 1) to
#: beyond every analyser's band by far
MODES_FREQ_RANGE_HZ = (1.0, 1e6)
#: the largest coordinate (m) of a member's end: a laboratory structure, not a bridge across a continent
MAX_COORDINATE_M = 1e3


def _first_bad_number(d: Any, prefix: str = "") -> tuple[str, Any] | None:
    """The dotted key and value of the first NaN, infinite or larger than :data:`MAX_CONFIG_MAGNITUDE`
    number in a parsed TOML document, or None."""
    items = d.items() if isinstance(d, Mapping) else enumerate(d) if isinstance(d, (list, tuple)) else ()
    for k, v in items:
        key = f"{prefix}.{k}" if prefix and isinstance(k, str) else f"{prefix}[{k}]" if prefix else str(k)
        if isinstance(v, (int, float)) and not isinstance(v, bool) and not abs(v) <= MAX_CONFIG_MAGNITUDE:
            return key, v
        found = _first_bad_number(v, key) if isinstance(v, (Mapping, list, tuple)) else None
        if found:
            return found
    return None


#: bytes per squared degree of freedom of the dense eigenproblem (K, M, shapes and the solver's copies)
FE_BYTES_PER_DOF2 = 5 * 8


def check_fe_memory(cfg: FrameConfig, bytes_per_dof2: float, what: str, source: str | None = None) -> None:
    """Refuse (:class:`ConfigError`) a frame whose FE work, ``bytes_per_dof2`` bytes per squared degree of
    freedom (``what`` it is in the message), does not fit in the memory one computation may use now
    (:func:`analysis.work_limits.memory_budget_bytes`); the message gives the largest accepted total of
    elements."""
    from analysis.work_limits import memory_budget_bytes

    n_dof = 6.0 * sum(float(c.n_elements) + 1 for c in cfg.components.values())
    budget = memory_budget_bytes()
    max_dof = (budget / bytes_per_dof2) ** 0.5
    if n_dof > max_dof:
        largest = int(max_dof) // 6 - len(cfg.components)
        gib = bytes_per_dof2 * n_dof * n_dof / 2**30  # inf, not an error, beyond float range
        _check(False, f"{source or cfg.source}: the components' n_elements add up to "
                      f"{n_dof / 6 - len(cfg.components):.6g} elements ({n_dof:.6g} degrees of freedom, {gib:.3g} GiB "
                      f"for {what}, {budget / 2**30:.3g} GiB may be used now); the largest accepted total here is "
                      f"{max(largest, 0)} elements")


def _structure_mass_kg(cfg: FrameConfig) -> float:
    total = 0.0
    for c in cfg.components.values():
        s = cfg.sections[c.section]
        area = (s.area_m2 if s.shape == "explicit" else s.width_m * s.depth_m if s.shape == "rect"
                else s.width_m * s.depth_m - (s.width_m - 2 * s.wall_m) * (s.depth_m - 2 * s.wall_m))
        total += cfg.material.density_kg_m3 * area * float(np.linalg.norm(np.subtract(c.end_m, c.start_m)))
    return total


def _validate_bounds(cfg: FrameConfig, source: str) -> None:
    """Finite numbers everywhere, an FE model whose eigenproblem fits in memory, a sensor lighter
    than the structure (checked before anything is built)."""
    bad = _first_bad_number(cfg.raw)
    if bad is not None:
        key, value = bad
        what = ("is not a finite number" if isinstance(value, float) and not np.isfinite(value) else
                f"= {value:.6g} is beyond the {MAX_CONFIG_MAGNITUDE:.0e} accepted for any value")
        _check(False, f"{source}: {key} {what}; give a value in the units the key names")
    check_fe_memory(cfg, FE_BYTES_PER_DOF2, "the eigenproblem", source)
    mass = _structure_mass_kg(cfg)
    _check(cfg.sensors.accelerometer.mass_kg < mass,
           f"{source}: sensors.accelerometer.mass_kg = {cfg.sensors.accelerometer.mass_kg:g} kg is not below the "
           f"structure's mass ({mass:.4g} kg); give the accelerometer's mass in kg")


def _validate(cfg: FrameConfig, source: str) -> None:
    p = f"{source}:"
    m = cfg.material
    _check(m.youngs_modulus_pa > 0 and m.density_kg_m3 > 0 and -1 < m.poisson_ratio < 0.5,
           f"{p} [material] needs youngs_modulus_pa > 0, density_kg_m3 > 0, -1 < poisson_ratio < 0.5")
    for name, s in cfg.sections.items():
        _check(s.shape in ("rect", "rhs", "explicit"),
               f"{p} sections.{name}.shape = {s.shape!r}; use 'rect', 'rhs' or 'explicit'")
        if s.shape in ("rect", "rhs"):
            _check(s.width_m > 0 and s.depth_m > 0, f"{p} sections.{name}: width_m and depth_m must be > 0")
        if s.shape == "rhs":
            _check(0 < 2 * s.wall_m < min(s.width_m, s.depth_m),
                   f"{p} sections.{name}: wall_m must be > 0 and less than half the width and depth")
        if s.shape == "explicit":
            _check(min(s.area_m2, s.iy_m4, s.iz_m4, s.j_m4) > 0,
                   f"{p} sections.{name}: explicit sections need area_m2, iy_m4, iz_m4, j_m4 > 0")
    for name, c in cfg.components.items():
        _check(c.section in cfg.sections,
               f"{p} components.{name}.section = {c.section!r} is not one of [sections.*]: {', '.join(cfg.sections)}")
        _check(len(c.start_m) == 3 and len(c.end_m) == 3,
               f"{p} components.{name}: start_m and end_m must be [x, y, z] in metres")
        _check(all(isinstance(x, (int, float)) and abs(x) <= MAX_COORDINATE_M for x in (*c.start_m, *c.end_m)),
               f"{p} components.{name}: start_m and end_m must be numbers within +-{MAX_COORDINATE_M:g} m")
        _check(c.n_elements >= 1, f"{p} components.{name}.n_elements must be >= 1")
        _check(float(np.linalg.norm(np.subtract(c.end_m, c.start_m))) > 0,
               f"{p} components.{name}: start_m and end_m coincide")

    def node_ok(key: str, where: str) -> None:
        parts = str(key).split(":")
        ok = len(parts) == 2 and parts[0] in cfg.components and parts[1].isdigit()
        ok = ok and int(parts[1]) <= cfg.components[parts[0]].n_elements
        _check(ok, f"{p} {where}: node {key!r} must be 'component:node' with component in "
                   f"{list(cfg.components)} and node within 0..n_elements")

    for n in cfg.supports.nodes:
        node_ok(n, "supports.nodes")
    for pair in cfg.joints.pairs:
        _check(len(pair) == 2, f"{p} joints.pairs: each entry must be [node_a, node_b]")
        node_ok(pair[0], "joints.pairs")
        node_ok(pair[1], "joints.pairs")
    for where, k in (("supports.stiffness", cfg.supports.stiffness), ("joints.stiffness", cfg.joints.stiffness)):
        _check(len(k) == 6 and all(isinstance(x, (int, float)) and x >= 0 for x in k),
               f"{p} {where} must be 6 values >= 0: [kx, ky, kz] N/m, [krx, kry, krz] N m/rad")
    _check(len(cfg.supports.nodes) > 0 and all(float(x) > 0 for x in cfg.supports.stiffness[:3]),
           f"{p} [supports] holds the frame in no direction or not in all three (nodes {list(cfg.supports.nodes)}, "
           f"stiffness {list(cfg.supports.stiffness)}): the frame would float free with a singular stiffness; give "
           "support nodes and kx, ky, kz > 0 N/m")
    dm = cfg.damage
    for places, factors, name, what in (
        (dm.cracked_elements, dm.crack_bending_factor, "cracked_elements", "element"),
        (dm.soft_joints, dm.soft_joint_factor, "soft_joints", "joint node"),
        (dm.loose_supports, dm.loose_support_factor, "loose_supports", "support node"),
    ):
        _check(len(places) == len(factors),
               f"{p} damage.{name} and its factor list must have the same length (one factor per {what})")
        _check(all(isinstance(k, (int, float)) and 0 < k <= 10 for k in factors),
               f"{p} damage: the factors of {name} must be numbers in (0, 10]")
    for e in dm.cracked_elements:
        comp, _, i = str(e).partition(":")
        _check(comp in cfg.components and i.isdigit() and int(i) < cfg.components[comp].n_elements,
               f"{p} damage.cracked_elements: {e!r} must be 'component:element' with element in 0..n_elements-1")
    for n in dm.soft_joints:
        _check(any(n in pair for pair in cfg.joints.pairs),
               f"{p} damage.soft_joints: {n!r} is not a node of any [joints] pair ({list(cfg.joints.pairs)})")
    for n in dm.loose_supports:
        _check(n in cfg.supports.nodes,
               f"{p} damage.loose_supports: {n!r} is not one of supports.nodes {list(cfg.supports.nodes)}")
    d = cfg.damping
    _check(d.model in ("modal", "rayleigh"), f"{p} damping.model = {d.model!r}; use 'modal' or 'rayleigh'")
    _check(all(0 <= z < 1 for z in d.zeta) and 0 <= d.zeta_default < 1,
           f"{p} damping ratios must be in [0, 1) (ratios, not percent)")
    _check(d.rayleigh_alpha >= 0 and d.rayleigh_beta >= 0, f"{p} rayleigh_alpha and rayleigh_beta must be >= 0")
    lo, hi = MODES_FREQ_RANGE_HZ
    _check(lo <= cfg.modes.max_freq_hz <= hi,
           f"{p} modes.max_freq_hz = {cfg.modes.max_freq_hz:.6g} must be in [{lo:g}, {hi:.0e}] Hz")
    a, fs = cfg.sensors.accelerometer, cfg.sensors.force
    _check(a.mass_kg >= 0 and a.sensitivity_mv_per_g > 0 and a.noise_density_g_per_rthz >= 0 and a.iepe_highpass_hz >= 0,
           f"{p} [sensors.accelerometer] values must be >= 0 (sensitivity > 0)")
    _check(fs.sensitivity_mv_per_n > 0 and fs.noise_density_n_per_rthz >= 0 and fs.iepe_highpass_hz >= 0,
           f"{p} [sensors.force] values must be >= 0 (sensitivity > 0)")
    h = cfg.hammer
    _check(h.tip in h.tips, f"{p} hammer.tip = {h.tip!r} is not one of hammer.tips: {', '.join(h.tips)}")
    _check(all(w > 0 for w in h.tips.values()), f"{p} hammer.tips widths must be > 0 s")
    _check(h.shape in ("half_sine", "hann"), f"{p} hammer.shape = {h.shape!r}; use 'half_sine' or 'hann'")
    _check(h.amplitude_n > 0, f"{p} hammer.amplitude_n must be > 0 N")
    _check(h.amplitude_scatter >= 0 and h.width_scatter >= 0, f"{p} hammer scatters must be >= 0")
    for name in ("neighbour_probability", "double_hit_probability"):
        _check(0 <= getattr(h, name) <= 1, f"{p} hammer.{name} must be a probability in [0, 1]")
    for name in ("double_hit_delay_s", "double_hit_ratio", "trigger_offset_samples"):
        v = getattr(h, name)
        _check(len(v) == 2 and 0 <= v[0] <= v[1], f"{p} hammer.{name} must be [low, high] with 0 <= low <= high")
    fe = cfg.frontend
    _check(fe.anti_alias in ("elliptic", "butterworth"),
           f"{p} frontend.anti_alias = {fe.anti_alias!r}; use 'elliptic' or 'butterworth'")
    _check(0 < fe.anti_alias_cutoff_fraction < 1 and fe.anti_alias_order >= 1,
           f"{p} frontend.anti_alias_cutoff_fraction must be in (0, 1) and anti_alias_order >= 1")
    _check(2 <= fe.adc_bits <= 24 and len(fe.ranges_v) > 0 and all(r > 0 for r in fe.ranges_v),
           f"{p} frontend.adc_bits must be 2..24 and ranges_v positive volts")
    _check(0 <= fe.adc_noise_lsb_rms <= 100, f"{p} frontend.adc_noise_lsb_rms must be 0..100 counts rms")
    sm = cfg.sampling
    _check(2 <= sm.oversample <= 64 and 1 <= sm.fir_half_length <= 256 and sm.stopband_db > 20,
           f"{p} [sampling] needs 2 <= oversample <= 64, 1 <= fir_half_length <= 256, stopband_db > 20")
    tp = cfg.test_plan
    _check(tp.mode in ("roving_hammer", "roving_sensor"),
           f"{p} test_plan.mode = {tp.mode!r}; use 'roving_hammer' or 'roving_sensor'")
    try:
        for lab in (tp.reference, *tp.sensors, *tp.points):
            pt = parse_point(lab)
            node_ok(f"{pt.component}:{pt.node}", "test_plan")
    except PointLabelError as exc:
        raise ConfigError(f"{p} test_plan: {exc}") from None
    _check(tp.averages >= 1, f"{p} test_plan.averages must be >= 1")
    _validate_nonlinear(cfg, p)


def _validate_nonlinear(cfg: FrameConfig, p: str) -> None:
    nl = cfg.nonlinear
    _check(nl.law in NONLINEAR_LAWS, f"{p} nonlinear.law = {nl.law!r}; use one of {', '.join(NONLINEAR_LAWS)}")
    _check(nl.axis in _ROTATION_AXES, f"{p} nonlinear.axis = {nl.axis!r}; use 'rx', 'ry' or 'rz' (rotation about "
                                      "global X, Y or Z)")
    _check(nl.stiffness_nm_per_rad >= 0, f"{p} nonlinear.stiffness_nm_per_rad must be >= 0 N m/rad (0: keep the "
                                         "joint's own stiffness)")
    _check(nl.integration_rate_hz > 0, f"{p} nonlinear.integration_rate_hz must be > 0 Hz")
    if not nl.active:
        return
    joint_nodes = {str(n) for pair in cfg.joints.pairs for n in pair}
    _check(nl.joint in joint_nodes or nl.joint in cfg.supports.nodes,
           f"{p} nonlinear.joint = {nl.joint!r} is neither a node of a [joints] pair ({sorted(joint_nodes)}) nor a "
           f"support node ({list(cfg.supports.nodes)}); name the joint or support whose spring is nonlinear")
    if nl.law == "iwan":
        _check(nl.slip_moment_nm > 0, f"{p} nonlinear.slip_moment_nm must be > 0 N m (the moment of full slip)")
        _check(0 <= nl.residual_stiffness_fraction < 1,
               f"{p} nonlinear.residual_stiffness_fraction must be in [0, 1) (share of the stiffness that never slips)")
        _check(1 <= nl.n_sliders <= 200, f"{p} nonlinear.n_sliders must be 1..200")
    if nl.law == "cubic":
        _check(nl.cubic_nm_per_rad3 != 0, f"{p} nonlinear.cubic_nm_per_rad3 must be non-zero for law = 'cubic'")
