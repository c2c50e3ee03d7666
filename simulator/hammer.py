"""The impact hammer: force pulse shape, hit-to-hit scatter, double hits.

Pulse of width ``T`` (s, set by the tip: soft/medium/hard) and peak ``F`` (N), starting at t = 0:

* ``half_sine``: ``F sin(pi t / T)`` for 0 <= t <= T (impulse ``2 F T / pi``, spectrum first zero at 1.5/T);
* ``hann``: ``F sin^2(pi t / T)`` (impulse ``F T / 2``, smoother, faster spectral roll-off).

Scatter per hit (all drawn from the ``numpy.random.Generator`` passed in, in a fixed order):
peak ``F = F0 * exp(s_a N(0,1))`` (lognormal), width ``T = T0 * exp(s_w N(0,1))``, a hit on a
neighbouring node with probability ``p_n``, and a double hit with probability ``p_d``: a second pulse
``delay`` s later (uniform in ``double_hit_delay_s``) with peak ``ratio * F`` (uniform in
``double_hit_ratio``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis.points import parse_point

from .config import HammerConfig

__all__ = ["HammerHit", "pulse", "draw_hit", "force_signal"]


@dataclass(frozen=True)
class HammerHit:
    """One strike: struck ``point`` (where the operator meant: ``nominal_point``), peak ``amplitude_n`` (N),
    pulse ``width_s`` (s), pulse ``shape``, optional second pulse (``double_hit``, ``second_delay_s``,
    ``second_ratio``) and the delay of the pulse start after the pre-trigger (``offset_samples``)."""

    point: str
    nominal_point: str
    amplitude_n: float
    width_s: float
    shape: str
    double_hit: bool
    second_delay_s: float
    second_ratio: float
    offset_samples: int


def pulse(t_s: np.ndarray, width_s: float, shape: str = "half_sine") -> np.ndarray:
    """Unit-peak pulse at times ``t_s`` (s) after its start; zero outside [0, width_s]."""
    t = np.asarray(t_s, dtype=float)
    inside = (t >= 0) & (t <= width_s)
    s = np.sin(np.pi * np.clip(t, 0.0, width_s) / width_s)
    if shape == "half_sine":
        y = s
    elif shape == "hann":
        y = s ** 2
    else:
        raise ValueError(f"pulse shape {shape!r} is unknown; use 'half_sine' or 'hann'")
    return np.where(inside, y, 0.0)


def draw_hit(
    cfg: HammerConfig,
    nominal_point: str,
    max_node: int,
    rng: np.random.Generator,
    *,
    double_hit: bool | None = None,
    amplitude_scale: float = 1.0,
    neighbour: bool | None = None,
) -> HammerHit:
    """Draw one strike aimed at ``nominal_point`` (``max_node``: last node of its component).

    ``double_hit`` / ``neighbour`` force (True) or forbid (False) those events; None draws them with the
    configured probabilities. ``amplitude_scale`` multiplies the peak (e.g. 20 for an overload-size hit).
    The same number of random draws is made whatever the overrides, so a seed gives the same sequence.
    """
    if amplitude_scale <= 0:
        raise ValueError(f"amplitude_scale must be > 0, got {amplitude_scale}")
    p = parse_point(nominal_point)
    z = rng.standard_normal(2)
    u = rng.random(6)
    amp = cfg.amplitude_n * float(np.exp(cfg.amplitude_scatter * z[0])) * amplitude_scale
    width = cfg.width_s * float(np.exp(cfg.width_scatter * z[1]))
    is_neighbour = bool(u[0] < cfg.neighbour_probability) if neighbour is None else bool(neighbour)
    point = p
    if is_neighbour and max_node > 0:
        step = -1 if u[1] < 0.5 else 1
        node = p.node + step
        if node < 0 or node > max_node:
            node = p.node - step
        point = type(p)(p.component, node, p.direction)
    is_double = bool(u[2] < cfg.double_hit_probability) if double_hit is None else bool(double_hit)
    lo, hi = cfg.double_hit_delay_s
    delay = lo + (hi - lo) * float(u[3])
    rlo, rhi = cfg.double_hit_ratio
    ratio = rlo + (rhi - rlo) * float(u[4])
    olo, ohi = (int(v) for v in cfg.trigger_offset_samples)
    offset = olo + int(np.floor(u[5] * (ohi - olo + 1)))
    return HammerHit(
        point=str(point),
        nominal_point=str(p),
        amplitude_n=amp,
        width_s=width,
        shape=cfg.shape,
        double_hit=is_double,
        second_delay_s=delay if is_double else 0.0,
        second_ratio=ratio if is_double else 0.0,
        offset_samples=min(offset, ohi),
    )


def force_signal(hit: HammerHit, fs_hz: float, n_samples: int, start_index: int) -> np.ndarray:
    """Hammer force (N) sampled at ``fs_hz`` (Hz), ``n_samples`` long, the pulse starting at sample
    ``start_index`` (value 0 there). The analytic pulse is sampled exactly at t_k = k / fs."""
    if fs_hz <= 0 or n_samples < 1:
        raise ValueError(f"need fs_hz > 0 and n_samples >= 1 (got {fs_hz}, {n_samples})")
    t = (np.arange(n_samples) - start_index) / fs_hz
    f = hit.amplitude_n * pulse(t, hit.width_s, hit.shape)
    if hit.double_hit:
        f = f + hit.second_ratio * hit.amplitude_n * pulse(t - hit.second_delay_s, hit.width_s, hit.shape)
    return f
