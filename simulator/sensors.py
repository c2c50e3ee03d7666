"""Transducers: accelerometer and hammer force sensor, from engineering units to volts.

A sensor's output voltage is ``v = S * (x + n)`` then, for IEPE sensors, a first-order high-pass
at ``iepe_highpass_hz`` (the discharge time constant of the built-in electronics). ``x`` is the
physical signal (m/s^2 or N), ``S`` the sensitivity in V per engineering unit and ``n`` white noise
with one-sided spectral density ``d`` (EU/sqrt(Hz)), i.e. standard deviation ``d sqrt(fs / 2)`` at
sample rate ``fs``. 1 g = 9.80665 m/s^2.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .frontend import highpass_first_order

__all__ = ["G_M_S2", "SENSITIVITY_UNITS", "sensitivity_v_per_eu", "Transducer"]

G_M_S2 = 9.80665
SENSITIVITY_UNITS = ("mV/N", "mV/g", "V/EU")


def sensitivity_v_per_eu(value: float, unit: str) -> float:
    """Sensitivity in volts per SI engineering unit (V/N or V/(m/s^2)) from the operator's unit.

    mV/N -> value * 1e-3 V/N; mV/g -> value * 1e-3 / 9.80665 V/(m/s^2); V/EU -> value.
    """
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"sensitivity must be a positive number, got {value!r}")
    if unit == "mV/N":
        return value * 1e-3
    if unit == "mV/g":
        return value * 1e-3 / G_M_S2
    if unit == "V/EU":
        return float(value)
    raise ValueError(f"sensitivity unit {unit!r} is unknown; use one of {', '.join(SENSITIVITY_UNITS)}")


@dataclass(frozen=True)
class Transducer:
    """A sensor: ``v_per_eu`` (V per N or per m/s^2), noise density (EU/sqrt(Hz)), IEPE high-pass (Hz, 0 = none)."""

    v_per_eu: float
    noise_density: float
    highpass_hz: float = 0.0

    def volts(self, x: np.ndarray, fs_hz: float, rng: np.random.Generator | None = None) -> np.ndarray:
        """Output voltage (V) for the physical signal ``x`` (EU) sampled at ``fs_hz`` (Hz).

        Noise is added only when ``rng`` is given (noise-free otherwise). ``x`` is not modified.
        """
        sig = np.asarray(x, dtype=float)
        if rng is not None and self.noise_density > 0:
            sig = sig + self.noise_density * np.sqrt(fs_hz / 2.0) * rng.standard_normal(sig.shape)
        v = self.v_per_eu * sig
        return highpass_first_order(v, fs_hz, self.highpass_hz) if self.highpass_hz > 0 else v
