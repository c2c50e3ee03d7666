"""The simulated test stand: operator with hammer, the frame, sensors, cables up to the analyser inputs.

The analyser firmware uses it as::

    stand = TestStand(config=None, seed=0)
    stand.set_channels([{"point": "right:6:-X", "quantity": "force", "sensitivity": 2.25,
                         "sensitivity_unit": "mV/N", "iepe": True, "coupling": "AC"}, ...])
    ev = stand.strike(fs_hz=2048.0, n_samples=8192, pretrigger=256)
    ev.volts            # [n_channels, n_samples] V at the analyser inputs (before anti-alias and ADC)
    ev.info             # point, amplitude_n, double_hit, hit_index, ...

Sampling model (``[sampling]``): the hammer pulse is made on a grid ``oversample`` (16) times finer
than fs and band-limited at fs/2 by a centred linear-phase FIR (:func:`simulator.frontend.bandlimit_fir`,
as a sigma-delta ADC's decimation filter); the frame is driven by that force (exact modal
discretisation on the fine grid, :func:`simulator.response.simulate_segment`) and both force and
acceleration are taken at the fs instants. FFT ratios of the volts then match the continuous FRF in
the band up to 0.8 fs/2 (0.2 % at 200 Hz with fs = 512 Hz; the residual is the first-order hold on the
fine grid, (w T / 16)^2 / 12). The pulse rings (Gibbs) for up to ``fir_half_length`` samples before
``hit_index``, a few % of its peak for short pulses, as on a real analyser.

Signal chain per channel: physical signal (hammer force in N, or acceleration in m/s^2 at the channel's
point) + sensor noise -> sensitivity (the channel's own value: the
operator entered the sensor's true calibration) -> IEPE high-pass (``iepe=True``, corner from
``[sensors.*] iepe_highpass_hz``) -> input AC coupling (``coupling="AC"``, ``[frontend] ac_coupling_hz``).
The firmware applies anti-alias, range, ADC and trigger search.

Mass loading: with ``[sensors] mass_loading = true`` every acceleration channel's accelerometer
(``[sensors.accelerometer] mass_kg``) loads the frame at its node, so moving a sensor (roving sensor
test) changes the modes slightly, as on a real structure. Models are cached per sensor layout.

Randomness: one ``numpy.random.Generator`` seeded by ``seed``; every strike draws the same number of
values in the same order, so a seed reproduces a whole session.
"""
from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from analysis.frf import FRFSet
from analysis.points import Point, PointLabelError, parse_point

from .config import ConfigError, FrameConfig
from .errors import StandError
from .fem import FrameModel, ModelError
from .frontend import bandlimit_fir, highpass_cascade
from .hammer import HammerHit, draw_hit, force_signal
from .response import simulate_segment
from .sensors import G_M_S2, SENSITIVITY_UNITS, sensitivity_v_per_eu

__all__ = ["TestStand", "StandEvent", "StandError", "ChannelSpec"]

logger = logging.getLogger(__name__)

_CHANNEL_KEYS = ("point", "quantity", "sensitivity", "sensitivity_unit", "iepe", "coupling")


@dataclass(frozen=True)
class ChannelSpec:
    """One analyser input as the stand sees it (validated copy of a channel dict)."""

    point: str
    quantity: str  # "force" | "acceleration"
    sensitivity: float
    sensitivity_unit: str
    iepe: bool
    coupling: str  # "AC" | "DC"

    @property
    def v_per_eu(self) -> float:
        """Sensitivity in V/N or V/(m/s^2)."""
        return sensitivity_v_per_eu(self.sensitivity, self.sensitivity_unit)


@dataclass(frozen=True)
class StandEvent:
    """One strike: ``volts`` [n_channels, n_samples] (V) at the analyser inputs and ``info``.

    ``info`` keys: ``point`` (struck), ``nominal_point`` (aimed at), ``amplitude_n`` (peak N),
    ``double_hit`` (bool), ``hit_index`` (sample where the pulse starts), ``pulse_width_s``, ``tip``,
    ``neighbour_hit`` (bool), ``second_delay_s``, ``second_ratio``, ``fs_hz``, ``noise`` (bool).
    ``force_n`` and ``response`` hold the noise-free physical signals (N; m/s^2 per acceleration channel,
    NaN rows for force channels) for tests and demos.
    """

    volts: np.ndarray
    info: dict
    force_n: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    response: np.ndarray = field(repr=False, default_factory=lambda: np.zeros((0, 0)))


def _parse_channel(i: int, ch: Mapping[str, Any], model_check: Callable[[str, int], None]) -> ChannelSpec:
    if not isinstance(ch, Mapping):
        raise StandError(f"channel {i}: expected a dict with keys {', '.join(_CHANNEL_KEYS)}, got {type(ch).__name__}")
    missing = [k for k in _CHANNEL_KEYS if k not in ch]
    if missing:
        raise StandError(f"channel {i}: missing keys {', '.join(missing)}; each channel needs {', '.join(_CHANNEL_KEYS)}")
    try:
        point = str(parse_point(ch["point"]))
    except PointLabelError as exc:
        raise StandError(f"channel {i}: {exc}") from None
    q = ch["quantity"]
    if q not in ("force", "acceleration"):
        raise StandError(f"channel {i}: quantity {q!r} must be 'force' or 'acceleration'")
    unit = ch["sensitivity_unit"]
    if unit not in SENSITIVITY_UNITS:
        raise StandError(f"channel {i}: sensitivity_unit {unit!r} must be one of {', '.join(SENSITIVITY_UNITS)}")
    try:
        sens = float(ch["sensitivity"])
        sensitivity_v_per_eu(sens, unit)
    except (TypeError, ValueError):
        raise StandError(f"channel {i}: sensitivity {ch['sensitivity']!r} must be a positive number") from None
    coupling = str(ch["coupling"]).upper()
    if coupling not in ("AC", "DC"):
        raise StandError(f"channel {i}: coupling {ch['coupling']!r} must be 'AC' or 'DC'")
    if q == "acceleration":
        model_check(point, i)
    return ChannelSpec(point, q, sens, unit, bool(ch["iepe"]), coupling)


class TestStand:
    """The simulated operator + frame + sensors (see module docstring).

    ``config``: a :class:`FrameConfig`, a path to a TOML file, or None for the defaults.
    ``seed``: seed of the stand's random generator (hammer scatter, noise).
    """

    __test__ = False  # not a pytest test class

    def __init__(self, config: FrameConfig | str | Path | None = None, seed: int = 0) -> None:
        if config is None or isinstance(config, (str, Path)):
            config = FrameConfig.load(config)
        if not isinstance(config, FrameConfig):
            raise ConfigError(f"config must be a FrameConfig, a TOML path or None, got {type(config).__name__}")
        self.config = config
        self.seed = int(seed)
        self._rng = np.random.default_rng(self.seed)
        self._models: dict[frozenset, FrameModel] = {}
        bare = self._model(frozenset())
        self._max_node: dict[str, int] = {}
        for (comp, node) in bare.node_index:
            self._max_node[comp] = max(self._max_node.get(comp, 0), node)
        self._pending: dict[str, Any] = {}
        plan = config.test_plan
        self._hammer_point = str(parse_point(plan.reference if plan.mode == "roving_sensor" else plan.points[0]))
        self._channels: list[ChannelSpec] = []
        self.set_channels(self.default_channels())
        self.n_strikes = 0

    # ------------------------------------------------------------------ set-up
    def default_channels(self) -> list[dict]:
        """Channel dicts of the configured test plan: the hammer's force channel, then one accelerometer
        per plan sensor (roving hammer) or one at the first plan point (roving sensor)."""
        s = self.config.sensors
        plan = self.config.test_plan
        accel_points = list(plan.sensors) if plan.mode == "roving_hammer" else [plan.points[0]]
        chans = [{"point": plan.reference, "quantity": "force", "sensitivity": s.force.sensitivity_mv_per_n,
                  "sensitivity_unit": "mV/N", "iepe": True, "coupling": "AC"}]
        for p in accel_points:
            chans.append({"point": p, "quantity": "acceleration", "sensitivity": s.accelerometer.sensitivity_mv_per_g,
                          "sensitivity_unit": "mV/g", "iepe": True, "coupling": "AC"})
        return chans

    def set_channels(self, channels: Sequence[Mapping[str, Any]]) -> None:
        """Set the analyser's channel set-up (list of dicts with keys point, quantity, sensitivity,
        sensitivity_unit, iepe, coupling). Acceleration points must lie on the frame."""
        if not isinstance(channels, Sequence) or len(channels) == 0:
            raise StandError("set_channels needs a non-empty list of channel dicts")
        specs = [_parse_channel(i, ch, self._check_point) for i, ch in enumerate(channels)]
        self._channels = specs

    @property
    def channels(self) -> tuple[ChannelSpec, ...]:
        return tuple(self._channels)

    def _check_point(self, point: str, i: int | None = None) -> None:
        p = parse_point(point)
        if p.component not in self._max_node or p.node > self._max_node[p.component]:
            where = f"channel {i}: " if i is not None else ""
            nodes = ", ".join(f"{c}:0..{n}" for c, n in self._max_node.items())
            raise StandError(f"{where}point {point} is not on the frame; nodes are {nodes}")

    def set_hammer_point(self, point: str | Point) -> None:
        """Direct the operator to strike ``point`` (``component:node:direction``) from now on."""
        try:
            label = str(parse_point(point))
        except PointLabelError as exc:
            raise StandError(str(exc)) from None
        self._check_point(label)
        self._hammer_point = label

    @property
    def hammer_point(self) -> str:
        return self._hammer_point

    def next_strike(
        self, *, double_hit: bool | None = None, amplitude_scale: float | None = None,
        neighbour: bool | None = None,
    ) -> None:
        """One-shot overrides for the next strike only: force (True) or forbid (False) a double hit or a
        neighbouring-node hit, scale the peak force (e.g. 20 for an overload)."""
        if amplitude_scale is not None and not amplitude_scale > 0:
            raise StandError(f"amplitude_scale must be > 0, got {amplitude_scale}")
        self._pending = {"double_hit": double_hit, "amplitude_scale": amplitude_scale, "neighbour": neighbour}

    # ------------------------------------------------------------------ physics
    def _mass_layout(self) -> frozenset:
        if not self.config.sensors.mass_loading or self.config.sensors.accelerometer.mass_kg == 0:
            return frozenset()
        nodes = []
        for ch in self._channels:
            if ch.quantity == "acceleration":
                p = parse_point(ch.point)
                nodes.append(f"{p.component}:{p.node}")
        return frozenset(nodes)

    def _model(self, layout: frozenset) -> FrameModel:
        """The frame with accelerometer masses at ``layout`` nodes; the 16 most recent layouts are kept."""
        if layout in self._models:
            self._models[layout] = self._models.pop(layout)  # most recently used last
            return self._models[layout]
        m = self.config.sensors.accelerometer.mass_kg
        try:
            model = FrameModel.from_config(self.config, {n: m for n in sorted(layout)})
        except ModelError as exc:
            raise StandError(str(exc)) from None
        model.modes()
        self._models[layout] = model
        while len(self._models) > 16:
            self._models.pop(next(iter(self._models)))
        return model

    @property
    def model(self) -> FrameModel:
        """The frame model with the current sensor layout (mass loading)."""
        return self._model(self._mass_layout())

    def analytic_frf(
        self, output: str | Sequence[str], reference: str | Sequence[str], freq_hz: np.ndarray,
        quantity: str = "accelerance",
    ) -> FRFSet:
        """Exact FRF of the frame as currently instrumented (see :meth:`FrameModel.analytic_frf`)."""
        outs = [output] if isinstance(output, (str, Point)) else list(output)
        refs = [reference] if isinstance(reference, (str, Point)) else list(reference)
        try:
            return self.model.analytic_frf([str(o) for o in outs], [str(r) for r in refs], freq_hz, quantity)
        except ModelError as exc:
            raise StandError(str(exc)) from None

    def _force(self, hit: HammerHit, fs_hz: float, n_samples: int, start: int
               ) -> tuple[np.ndarray, np.ndarray, int, int]:
        """The hammer force: (samples at fs (N), fine-grid segment driving the frame, its first fine index, q).

        With ``[sampling] band_limit`` the pulse is made at ``q fs`` and filtered by the sampling model's
        centred linear-phase FIR (:func:`simulator.frontend.bandlimit_fir`), so the segment starts
        ``q M`` fine samples before the pulse; the force samples are the segment's values at fs instants.
        Otherwise the pulse is sampled at fs (q = 1) and the frame sees its first-order hold.
        """
        sm = self.config.sampling
        span_s = hit.width_s + (hit.second_delay_s if hit.double_hit else 0.0)
        if not sm.band_limit:
            length = min(n_samples - start, int(np.ceil(span_s * fs_hz)) + 2)
            seg = force_signal(hit, fs_hz, length, 0)
            force = np.zeros(n_samples)
            force[start:start + length] = seg
            return force, seg, start, 1
        q = int(sm.oversample)
        taps = bandlimit_fir(q, sm.fir_half_length, sm.stopband_db)
        half = (taps.size - 1) // 2
        raw = force_signal(hit, q * fs_hz, int(np.ceil(span_s * q * fs_hz)) + 2, 0)
        seg = np.convolve(raw, taps)
        seg_start = start * q - half
        last = min(n_samples * q - 1, seg_start + seg.size - 1)  # nothing after the record end matters
        seg = seg[: last - seg_start + 1]
        force = np.zeros(n_samples)
        n0 = max(0, -(-seg_start // q))
        idx = np.arange(n0, last // q + 1)
        force[idx] = seg[idx * q - seg_start]
        return force, seg, seg_start, q

    def _frame_response(self, model: FrameModel, outputs: Sequence[str], in_point: str, seg: np.ndarray,
                        seg_start: int, q: int, fs_hz: float, n_samples: int) -> np.ndarray:
        """Accelerations (len(outputs), n_samples) m/s^2 of the frame at ``outputs`` to the force segment
        ``seg`` (N, on the grid ``q fs``, first fine index ``seg_start``) at ``in_point``."""
        modes = model.modes()
        flex = modes.freq_hz > 0
        phi_out = model.shape_at(list(outputs), modes)[:, flex]
        phi_in = model.shape_at([in_point], modes)[0, flex]
        return simulate_segment(seg, seg_start, q, fs_hz, n_samples, modes.poles[flex], phi_out, phi_in,
                                "acceleration")

    def strike(
        self,
        fs_hz: float,
        n_samples: int,
        pretrigger: int = 0,
        *,
        noise: bool | None = None,
        double_hit: bool | None = None,
        amplitude_scale: float | None = None,
    ) -> StandEvent:
        """One hammer strike recorded by the configured channels.

        fs_hz : sample rate (Hz); n_samples : record length; pretrigger : samples before the trigger;
        the pulse starts at ``hit_index = pretrigger + offset`` (offset drawn from
        ``[hammer] trigger_offset_samples``). ``noise`` overrides ``[noise] enabled``; ``double_hit`` and
        ``amplitude_scale`` override the pending :meth:`next_strike` values for this strike.
        """
        if not (np.isfinite(fs_hz) and fs_hz > 0):
            raise StandError(f"fs_hz must be a positive sample rate, got {fs_hz}")
        n_samples, pretrigger = int(n_samples), int(pretrigger)
        if n_samples < 2 or not 0 <= pretrigger < n_samples:
            raise StandError(f"need n_samples >= 2 and 0 <= pretrigger < n_samples (got {n_samples}, {pretrigger})")
        pend, self._pending = self._pending, {}
        dh = double_hit if double_hit is not None else pend.get("double_hit")
        scale = amplitude_scale if amplitude_scale is not None else pend.get("amplitude_scale")
        use_noise = self.config.noise.enabled if noise is None else bool(noise)

        nominal = parse_point(self._hammer_point)
        hit: HammerHit = draw_hit(self.config.hammer, str(nominal), self._max_node[nominal.component], self._rng,
                                  double_hit=dh, amplitude_scale=1.0 if scale is None else float(scale),
                                  neighbour=pend.get("neighbour"))
        start = pretrigger + hit.offset_samples
        if start >= n_samples:
            raise StandError(f"the hit would start at sample {start}, after the record end ({n_samples}); "
                             "lower pretrigger or lengthen the record")
        force, seg, seg_start, q = self._force(hit, fs_hz, n_samples, start)

        model = self.model
        acc_idx = [i for i, ch in enumerate(self._channels) if ch.quantity == "acceleration"]
        response = np.full((len(self._channels), n_samples), np.nan)
        if acc_idx:
            response[acc_idx] = self._frame_response(model, [self._channels[i].point for i in acc_idx], hit.point,
                                                     seg, seg_start, q, fs_hz, n_samples)

        # sensor chain, vectorised over channels: EU (+ noise) -> V -> IEPE high-pass -> AC coupling
        s = self.config.sensors
        n_ch = len(self._channels)
        eu = np.where(np.isnan(response), force[None, :], response)
        v_per_eu = np.array([ch.v_per_eu for ch in self._channels])
        density = np.array([s.force.noise_density_n_per_rthz if ch.quantity == "force"
                            else s.accelerometer.noise_density_g_per_rthz * G_M_S2 for ch in self._channels])
        # the noise is always drawn, so the random sequence does not depend on the noise switch
        noise_draw = self._rng.standard_normal((n_ch, n_samples))
        if use_noise:
            eu = eu + (density * np.sqrt(fs_hz / 2.0))[:, None] * noise_draw
        volts = v_per_eu[:, None] * eu
        ac = self.config.frontend.ac_coupling_hz
        corners = [((s.force.iepe_highpass_hz if ch.quantity == "force" else s.accelerometer.iepe_highpass_hz)
                    if ch.iepe else 0.0, ac if ch.coupling == "AC" else 0.0) for ch in self._channels]
        for key in set(corners):
            rows = [i for i, c in enumerate(corners) if c == key]
            if any(c > 0 for c in key):
                volts[rows] = highpass_cascade(volts[rows], fs_hz, key)
        self.n_strikes += 1
        info = {
            "point": hit.point,
            "nominal_point": hit.nominal_point,
            "amplitude_n": hit.amplitude_n,
            "double_hit": hit.double_hit,
            "hit_index": start,
            "pulse_width_s": hit.width_s,
            "tip": self.config.hammer.tip,
            "neighbour_hit": hit.point != hit.nominal_point,
            "second_delay_s": hit.second_delay_s,
            "second_ratio": hit.second_ratio,
            "fs_hz": float(fs_hz),
            "noise": use_noise,
        }
        logger.debug("strike %d at %s: %.1f N%s", self.n_strikes, hit.point, hit.amplitude_n,
                     " (double hit)" if hit.double_hit else "")
        return StandEvent(volts=volts, info=info, force_n=force, response=response)
