"""The catalogue's FRF-level effects: they act on the synthesised FRFs (residual terms, a sensor's
high-pass, a channel delay, a channel's calibration); see :mod:`analysis.diagnosis.effects`."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from ..frf import FRFSet
from ..modal import residual_basis
from .effect_types import EffectError, FitContext
from .effect_types import check_positive as _check_positive
from .effect_types import fit_scalar as _fit_scalar

__all__ = ["apply_residual_modes", "fit_residual_modes", "highpass_response", "apply_sensor_highpass",
           "fit_sensor_highpass", "apply_time_delay", "fit_time_delay", "apply_sensitivity_error",
           "fit_sensitivity_error"]


def apply_residual_modes(frf: FRFSet, params: Mapping) -> FRFSet:
    """Add ``UR (jw)^q + LR (jw)^q / w^2`` per FRF (``upper`` m/N, ``lower`` m/N (rad/s)^2)."""
    shape = frf.H.shape[:2]
    UR = np.asarray(params.get("upper", np.zeros(shape)), float)
    LR = np.asarray(params.get("lower", np.zeros(shape)), float)
    if UR.shape != shape or LR.shape != shape:
        raise EffectError(f"residual_modes: upper and lower must have shape {shape} (outputs x references)")
    B = residual_basis(frf.omega, frf.quantity, "physical")
    return replace(frf, H=frf.H + UR[..., None] * B[0] + LR[..., None] * B[1])


def fit_residual_modes(ctx: FitContext, lines: np.ndarray) -> dict:
    B = residual_basis(ctx.measured.omega, ctx.measured.quantity, "physical")[:, lines]
    E = ctx.measured.H[..., lines] - ctx.sim.H[..., lines]
    W = ctx.weights[..., lines]
    no, nr = E.shape[:2]
    UR, LR = np.zeros((no, nr)), np.zeros((no, nr))
    for o in range(no):
        for r in range(nr):
            sw = np.sqrt(W[o, r])
            A = (B * sw).T
            A = np.vstack([A.real, A.imag])
            y = np.concatenate([(E[o, r] * sw).real, (E[o, r] * sw).imag])
            scale = np.linalg.norm(A, axis=0)
            scale[scale == 0] = 1.0
            x, *_ = np.linalg.lstsq(A / scale, y, rcond=None)
            UR[o, r], LR[o, r] = x / scale
    return {"upper": UR.tolist(), "lower": LR.tolist()}


def highpass_response(freq_hz: np.ndarray, corner_hz: float, order: int) -> np.ndarray:
    """Butterworth-like cascade of ``order`` first-order high-passes: (s/wc / (1 + s/wc))^order."""
    s = 1j * np.asarray(freq_hz, float) / corner_hz
    return (s / (1 + s)) ** order


def apply_sensor_highpass(frf: FRFSet, params: Mapping) -> FRFSet:
    """Response-sensor low-frequency roll-off: ``corner_hz`` (Hz), ``order`` (1 or 2)."""
    fc = _check_positive("corner_hz", params.get("corner_hz"), "sensor_highpass")
    n = int(params.get("order", 1))
    if n not in (1, 2, 3):
        raise EffectError(f"sensor_highpass: order must be 1, 2 or 3, got {n!r}")
    return replace(frf, H=frf.H * highpass_response(frf.freq_hz, fc, n))


def fit_sensor_highpass(ctx: FitContext, lines: np.ndarray) -> dict:
    f = ctx.measured.freq_hz
    f0 = max(f[lines][0], 1e-3)
    best: tuple[float, float, int] | None = None
    for n in (1, 2):
        def cost(lfc: float, n: int = n) -> float:
            return ctx.cost(ctx.sim.H * highpass_response(f, float(np.exp(lfc)), n), lines)
        grid = np.linspace(np.log(f0 / 30), np.log(f0 * 10), 61)
        x = _fit_scalar(cost, grid)
        c = cost(x)
        if best is None or c < best[0]:
            best = (c, float(np.exp(x)), n)
    assert best is not None
    return {"corner_hz": best[1], "order": best[2]}


def apply_time_delay(frf: FRFSet, params: Mapping) -> FRFSet:
    """A delay ``delay_s`` (s) of the responses against the force: ``H *= exp(-j w delay)``."""
    d = float(params.get("delay_s", 0.0))
    if not np.isfinite(d):
        raise EffectError(f"time_delay: delay_s must be a finite number of seconds, got {d!r}")
    return replace(frf, H=frf.H * np.exp(-1j * frf.omega * d))


def fit_time_delay(ctx: FitContext, lines: np.ndarray) -> dict:
    w = ctx.measured.omega
    fmax = ctx.measured.freq_hz[lines][-1]

    def cost(d: float) -> float:
        return ctx.cost(ctx.sim.H * np.exp(-1j * w * d), lines)
    span = 0.45 / fmax
    d = _fit_scalar(cost, np.linspace(-span, span, 91))
    return {"delay_s": d}


#: The largest factor a channel's calibration is taken to be off by (either way): a sensitivity entered
#: twice too large or small is a calibration error, an FRF 30 times smaller than simulated is not.
MAX_GAIN_ERROR = 3.0


def apply_sensitivity_error(frf: FRFSet, params: Mapping) -> FRFSet:
    """Output channel o read with a calibration off by ``gains[o]`` (dict label -> gain, or a list)."""
    g = params.get("gains", {})
    gains = np.ones(frf.n_outputs)
    if isinstance(g, Mapping):
        for label, v in g.items():
            if label not in frf.outputs:
                raise EffectError(f"sensitivity_error: output {label!r} is not one of {list(frf.outputs)}")
            gains[frf.outputs.index(label)] = float(v)
    else:
        gains = np.asarray(g, float).reshape(frf.n_outputs)
    return replace(frf, H=frf.H * gains[:, None, None])


def fit_sensitivity_error(ctx: FitContext, lines: np.ndarray) -> dict:
    Hs, Hm, W = ctx.sim.H[..., lines], ctx.measured.H[..., lines], ctx.weights[..., lines]
    num = np.sum(W * np.real(np.conj(Hs) * Hm), axis=(1, 2))
    den = np.sum(W * np.abs(Hs) ** 2, axis=(1, 2))
    g = np.where(den > 0, num / np.where(den > 0, den, 1), 1.0)
    # a calibration off by more than MAX_GAIN_ERROR either way is not a calibration: a channel the
    # simulation does not match at all (a peak far from its place) would otherwise be "fitted" by a
    # gain near zero, which only predicts a smaller FRF
    g = np.sign(g) * np.clip(np.abs(g), 1 / MAX_GAIN_ERROR, MAX_GAIN_ERROR)
    worst = int(np.argmax(np.abs(np.log(np.abs(g) + 1e-300))))
    return {"gains": {lab: float(v) for lab, v in zip(ctx.measured.outputs, g)},
            "channel": ctx.measured.outputs[worst], "gain": float(g[worst])}
