"""Time-data effects as simulator configuration: hits recorded by the stand under a given effect.

``simulate_hits(effect, ...)`` strikes the simulated frame (:class:`simulator.stand.TestStand`) a few
times at two force levels and returns the hits in engineering units (:class:`HitRecord`: force N,
accelerations m/s^2, the analyser's full scale and overload flags) with one time-data effect, given as
``{"effect": name, **params}``:

* ``amplitude_nonlinearity``, ``k_per_n`` (1/N): a softening (k > 0) or hardening (k < 0) frame whose
  natural frequencies are ``f_r (1 - k F_pk)`` during a hit of peak force ``F_pk`` (the peak of the
  sampled force, N): stiffness times ``(1 - k F_pk)^2``, masses, mode shapes and damping ratios kept.
  Each hit is simulated with that scaled modal model (:class:`NonlinearStand`).
* ``input_noise``, ``noise_rms_n`` (N rms): white Gaussian noise on the force channel (a noisy force
  sensor / wrong input range), added to the whole record.
* ``double_hit``, ``fraction``: that fraction of the hits (rounded, at least one) bounces: a second pulse
  with the hammer's delay and ratio (``[hammer] double_hit_delay_s``, ``double_hit_ratio``).
* ``overload``, ``fraction``: that fraction of the hits (rounded, at least one) is struck 2-3 times harder
  and the force channel clips at its full scale ``full_scale_n`` (the input range; by default 1.3 x the
  largest normal peak); the analyser flags those hits.

Without an effect the hits are clean (no double hit, no neighbour hit). Every record also carries the
stand's own sensor noise (force and acceleration noise densities of the configuration), drawn from a
generator seeded by ``seed``. The effects are the diagnosis' time-data rows
(:data:`analysis.diagnosis.timedata.TIME_EFFECTS`); their test oracle (random physical parameters, the
tolerance of their recovery) is :mod:`simulator.effect_oracle`.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from analysis.diagnosis.timedata import TIME_EFFECTS
from analysis.modal import ModalModel

from .config import FrameConfig
from .sensors import G_M_S2
from .stand import StandError, TestStand

__all__ = ["HitRecord", "NonlinearStand", "simulate_hits"]


@dataclass(frozen=True)
class HitRecord:
    """Hits at one reference in engineering units.

    force : (n_hits, n) N; responses : (n_hits, n_out, n) m/s^2; fs_hz : sample rate (Hz);
    pretrigger : samples before the trigger; outputs / reference : point labels;
    full_scale : (1 + n_out,) full scale of the force and response channels (N, m/s^2);
    overload : (n_hits, 1 + n_out) bool, the analyser's flags; base : receptance :class:`ModalModel`
    of the linear frame at (outputs, reference) as instrumented (accelerometer masses included);
    effect : the injected effect (None for clean hits); info : the stand's per-hit info dicts.

    Not a set of :class:`analysis.hit.Hit`: these hits never pass an analyser's ADC. They are the
    stand's float values (with the clipping at ``full_scale`` the effect asks for) beside the truth
    they were made from (``base``, ``effect``), which is what the time-data diagnosis is scored
    against; quantising them to int16 counts would change the diagnosis figures its tests and
    benchmarks hold. Hits that go through the simulated analyser are :class:`analysis.hit.Hit`.
    """

    force: np.ndarray
    responses: np.ndarray
    fs_hz: float
    pretrigger: int
    outputs: tuple
    reference: str
    full_scale: np.ndarray
    overload: np.ndarray
    base: ModalModel
    effect: dict | None
    info: list = field(default_factory=list)

    @property
    def n_hits(self) -> int:
        return int(self.force.shape[0])


class _ScaledModel:
    """A :class:`simulator.fem.FrameModel` seen with all natural frequencies times ``factor``."""

    def __init__(self, model, factor: float) -> None:
        self._model = model
        self._factor = float(factor)

    def modes(self, *args, **kwargs):
        ms = self._model.modes(*args, **kwargs)
        return replace(ms, freq_hz=ms.freq_hz * self._factor)

    def __getattr__(self, name: str):
        return getattr(self._model, name)


class NonlinearStand(TestStand):
    """The test stand with an amplitude-dependent frame: during a hit of sampled peak force ``F_pk`` (N)
    every natural frequency is ``f_r (1 - k_per_n F_pk)`` (mode shapes and damping ratios kept).
    ``analytic_frf`` and ``model`` between strikes are the linear frame's."""

    __test__ = False

    def __init__(self, config: FrameConfig | str | Path | None = None, seed: int = 0, k_per_n: float = 0.0) -> None:
        self.k_per_n = float(k_per_n)
        self._factor = 1.0
        super().__init__(config, seed)

    def _force(self, hit, fs_hz, n_samples, start):
        out = super()._force(hit, fs_hz, n_samples, start)
        factor = 1.0 - self.k_per_n * float(np.max(np.abs(out[0])))
        if not factor > 0:
            raise StandError(f"k_per_n = {self.k_per_n} 1/N makes the frequencies non-positive at this force; "
                             "lower it or the force")
        self._factor = factor
        return out

    def strike(self, *args, **kwargs):
        try:
            ev = super().strike(*args, **kwargs)
        finally:
            factor, self._factor = self._factor, 1.0
        return replace(ev, info=dict(ev.info, frequency_factor=factor))

    @property
    def model(self):
        m = self._model(self._mass_layout())
        return m if self._factor == 1.0 else _ScaledModel(m, self._factor)


def _count(fraction: float, n_hits: int) -> int:
    return int(min(n_hits - 1, max(1, round(float(fraction) * n_hits))))


def simulate_hits(
    effect: Mapping | None = None,
    *,
    n_hits: int = 8,
    levels: Sequence[float] = (0.4, 1.0),
    fs_hz: float = 2048.0,
    n_samples: int = 4096,
    pretrigger: int = 128,
    seed: int = 0,
    config: FrameConfig | str | Path | None = None,
    stand: TestStand | None = None,
) -> HitRecord:
    """``n_hits`` hits (force levels cycling through ``levels`` x the nominal amplitude) with one
    time-data ``effect`` (module docstring), in engineering units. ``stand`` may be a ready linear
    :class:`TestStand` (reused to save the model build; its generator advances)."""
    eff: dict = dict(effect) if effect else {}
    name = eff.get("effect")
    if name is not None and name not in TIME_EFFECTS:
        raise ValueError(f"unknown time-data effect {name!r}; known: {', '.join(TIME_EFFECTS)}")
    if n_hits < 3:
        raise ValueError(f"need at least 3 hits, got {n_hits}")
    if name == "amplitude_nonlinearity":
        st: TestStand = NonlinearStand(config if stand is None else stand.config, seed, float(eff["k_per_n"]))
    else:
        st = TestStand(config, seed) if stand is None else stand
    rng = np.random.default_rng([int(seed), 12])
    special = set()
    if name in ("double_hit", "overload"):
        special = set(int(i) for i in rng.choice(n_hits, _count(eff["fraction"], n_hits), replace=False))
    force, resp, info = [], [], []
    for i in range(n_hits):
        scale = float(levels[i % len(levels)])
        if name == "overload" and i in special:
            scale = float(max(levels)) * float(rng.uniform(2.0, 3.0))
        st.next_strike(double_hit=(name == "double_hit" and i in special), neighbour=False, amplitude_scale=scale)
        ev = st.strike(fs_hz, n_samples, pretrigger, noise=False)
        force.append(ev.force_n)
        resp.append(ev.response[1:] if st.channels[0].quantity == "force" else ev.response)
        info.append(ev.info)
    chans = st.channels
    if chans[0].quantity != "force" or any(c.quantity != "acceleration" for c in chans[1:]):
        raise StandError("simulate_hits needs the stand's channels as force first, then accelerations")
    F, X = np.array(force), np.array(resp)
    s = st.config.sensors
    nyq = fs_hz / 2.0
    F = F + s.force.noise_density_n_per_rthz * np.sqrt(nyq) * rng.standard_normal(F.shape)
    X = X + s.accelerometer.noise_density_g_per_rthz * G_M_S2 * np.sqrt(nyq) * rng.standard_normal(X.shape)
    if name == "input_noise":
        F = F + float(eff["noise_rms_n"]) * rng.standard_normal(F.shape)
    normal = [i for i in range(n_hits) if not (name == "overload" and i in special)]
    peak_normal = float(np.max(np.abs(F[normal])))
    fs_force = float(eff.get("full_scale_n", 1.3 * peak_normal)) if name == "overload" else 3.0 * peak_normal
    if name == "overload":
        eff["full_scale_n"] = fs_force
    full_scale = np.concatenate([[fs_force], 5.0 * np.max(np.abs(X), axis=(0, 2))])
    F = np.clip(F, -fs_force, fs_force)
    over = np.zeros((n_hits, 1 + X.shape[1]), bool)
    over[:, 0] = np.any(np.abs(F) >= 0.999 * fs_force, axis=1)
    outputs = tuple(c.point for c in chans[1:])
    reference = chans[0].point
    base = st.model.modal_model(list(outputs), [reference], "receptance")
    return HitRecord(force=F, responses=X, fs_hz=float(fs_hz), pretrigger=int(pretrigger), outputs=outputs,
                     reference=reference, full_scale=full_scale, overload=over, base=base, effect=eff or None, info=info)
