"""The analyser's input front end: AC coupling, anti-alias filter, 16-bit ADC.

* AC coupling / IEPE high-pass: first-order high-pass ``H(s) = s / (s + w_c)``, ``w_c = 2 pi f_c``,
  discretised by the bilinear transform with pre-warping at ``f_c`` (exact corner):
  ``k = tan(pi f_c / fs)``, ``y[n] = (x[n] - x[n-1]) / (1 + k) + (1 - k) / (1 + k) y[n-1]``.
* Anti-alias filter: the same digital IIR on every channel (so it cancels in FRF ratios), applied
  causally like the hardware. Default: 8th-order elliptic, 0.1 dB pass-band ripple up to
  ``0.8 * fs/2``, 80 dB stop-band attenuation (``scipy.signal.ellip``, second-order sections).
  ``butterworth`` gives a maximally flat alternative whose -3 dB point sits at the band edge.
  This is a digital approximation of the analogue filter of a real analyser: the simulator makes its
  signals at the analyser rate, so it cannot remove content above Nyquist, only shape the band.
* Sampling model (used by the test stand, not by the firmware): the continuous signals are made on a
  grid ``q`` times finer than the sample rate and band-limited by a linear-phase (zero-phase, centred)
  Kaiser-windowed sinc FIR with its cut-off at fs/2, as a sigma-delta ADC's decimation filter does:
  ``2 q M + 1`` taps (``M`` output periods each side), pass band flat to ~1e-4 dB up to 0.8 fs/2 and
  ``stopband_db`` attenuation above 1.2 fs/2 for the default ``M = 16``, ``stopband_db = 100``. Every
  channel gets the same filter, so it cancels in FRF ratios; the samples at fs are then free of aliasing
  in the band the analyser protects (0.8 fs/2).
* ADC: ``bits`` (16) signed, full scale ``+-range_v`` maps to ``+-(2^(bits-1) - 1)`` counts (32767);
  samples beyond the range clip at full scale and flag the channel as overloaded.
"""
from __future__ import annotations

import functools

import numpy as np
import scipy.signal

from .config import FrontendConfig

__all__ = [
    "bandlimit_fir",
    "highpass_first_order",
    "highpass_cascade",
    "anti_alias_sos",
    "apply_anti_alias",
    "volts_per_count",
    "quantize",
    "full_scale_counts",
]


def highpass_first_order(x: np.ndarray, fs_hz: float, corner_hz: float) -> np.ndarray:
    """First-order high-pass (corner ``corner_hz``, Hz) along the last axis; corner 0 returns a copy."""
    x = np.asarray(x, dtype=float)
    if corner_hz <= 0:
        return x.copy()
    if corner_hz >= fs_hz / 2:
        raise ValueError(f"high-pass corner {corner_hz} Hz must be below Nyquist ({fs_hz / 2} Hz)")
    k = np.tan(np.pi * corner_hz / fs_hz)
    b = np.array([1.0, -1.0]) / (1.0 + k)
    a = np.array([1.0, -(1.0 - k) / (1.0 + k)])
    return scipy.signal.lfilter(b, a, x, axis=-1)


@functools.lru_cache(maxsize=64)
def _highpass_coeffs(fs_hz: float, corners_hz: tuple) -> tuple[np.ndarray, np.ndarray]:
    b, a = np.ones(1), np.ones(1)
    for fc in corners_hz:
        if fc >= fs_hz / 2:
            raise ValueError(f"high-pass corner {fc} Hz must be below Nyquist ({fs_hz / 2} Hz)")
        k = np.tan(np.pi * fc / fs_hz)
        b = np.convolve(b, np.array([1.0, -1.0]) / (1.0 + k))
        a = np.convolve(a, np.array([1.0, -(1.0 - k) / (1.0 + k)]))
    return b, a


def highpass_cascade(x: np.ndarray, fs_hz: float, corners_hz: tuple[float, ...]) -> np.ndarray:
    """First-order high-passes in series (corners in Hz; zeros skipped) along the last axis, in one filter
    call (e.g. an IEPE sensor's high-pass followed by the input AC coupling). Returns a new array."""
    cs = tuple(float(c) for c in corners_hz if c > 0)
    x = np.asarray(x, dtype=float)
    if not cs:
        return x.copy()
    b, a = _highpass_coeffs(float(fs_hz), cs)
    return scipy.signal.lfilter(b, a, x, axis=-1)


@functools.lru_cache(maxsize=16)
def _bandlimit_taps(q: int, half_length: int, stopband_db: float) -> np.ndarray:
    numtaps = 2 * q * half_length + 1
    beta = scipy.signal.kaiser_beta(stopband_db)
    taps = scipy.signal.firwin(numtaps, 1.0 / q, window=("kaiser", beta))  # cut-off at fs/2 (of q fs)
    taps.setflags(write=False)
    return taps


def bandlimit_fir(oversample: int, half_length: int = 16, stopband_db: float = 100.0) -> np.ndarray:
    """Taps (unit DC gain, symmetric, ``2 q M + 1`` long) of the sampling model's low-pass at rate ``q fs``
    with its cut-off at fs/2; ``M = half_length`` output periods on each side (see module docstring)."""
    q, m = int(oversample), int(half_length)
    if q < 2 or m < 1:
        raise ValueError(f"band limiting needs oversample >= 2 and half_length >= 1 (got {oversample}, {half_length})")
    if not stopband_db > 20:
        raise ValueError(f"stopband_db must be > 20 dB, got {stopband_db}")
    return _bandlimit_taps(q, m, float(stopband_db)).copy()


@functools.lru_cache(maxsize=32)
def _design(fs_hz: float, kind: str, order: int, rp: float, rs: float, frac: float) -> np.ndarray:
    wp = frac  # normalised to Nyquist
    if kind == "elliptic":
        return scipy.signal.ellip(order, rp, rs, wp, btype="low", output="sos")
    if kind == "butterworth":
        return scipy.signal.butter(order, wp, btype="low", output="sos")
    raise ValueError(f"anti-alias kind {kind!r} is unknown; use 'elliptic' or 'butterworth'")


def anti_alias_sos(fs_hz: float, cfg: FrontendConfig | None = None) -> np.ndarray:
    """Second-order sections of the anti-alias filter at sample rate ``fs_hz`` (Hz)."""
    if cfg is None:
        from .config import FrameConfig

        cfg = FrameConfig.load().frontend
    sos = _design(float(fs_hz), cfg.anti_alias, int(cfg.anti_alias_order), float(cfg.anti_alias_passband_ripple_db),
                  float(cfg.anti_alias_stopband_db), float(cfg.anti_alias_cutoff_fraction))
    return sos.copy()


def apply_anti_alias(volts: np.ndarray, fs_hz: float, cfg: FrontendConfig | None = None) -> np.ndarray:
    """Anti-alias filtered copy of ``volts`` ([n_channels, n] or [n]), causal, same filter on all channels."""
    return scipy.signal.sosfilt(anti_alias_sos(fs_hz, cfg), np.asarray(volts, dtype=float), axis=-1)


def full_scale_counts(bits: int = 16) -> int:
    """Largest count magnitude: 2^(bits-1) - 1 (32767 for 16 bits)."""
    return (1 << (bits - 1)) - 1


def volts_per_count(range_v: float | np.ndarray, bits: int = 16) -> float | np.ndarray:
    """Volts per ADC count for an input range of +-``range_v`` V: range_v / (2^(bits-1) - 1)."""
    r = np.asarray(range_v, dtype=float)
    if np.any(r <= 0):
        raise ValueError(f"input range must be > 0 V, got {range_v}")
    v = r / full_scale_counts(bits)
    return float(v) if v.ndim == 0 else v


def quantize(volts: np.ndarray, range_v: float | np.ndarray, bits: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """ADC: volts [n_channels, n] (or [n]) -> (counts int16 same shape, overload bool [n_channels]).

    ``range_v`` is one range (V) or one per channel. counts = round(v / volts_per_count), clipped to
    +-full scale; a channel is overloaded when any sample's magnitude exceeds its range.
    """
    if bits > 16:
        raise ValueError(f"quantize returns int16 counts; bits must be <= 16 (got {bits})")
    v = np.asarray(volts, dtype=float)
    if not np.all(np.isfinite(v)):
        raise ValueError("quantize: input volts contain NaN or inf; the signal chain upstream is broken")
    one = v.ndim == 1
    v2 = v[None, :] if one else v
    r = np.broadcast_to(np.asarray(range_v, dtype=float).reshape(-1), (v2.shape[0],)) if np.ndim(range_v) else \
        np.full(v2.shape[0], float(range_v))
    vpc = np.asarray(volts_per_count(r, bits)).reshape(-1, 1)
    fs = full_scale_counts(bits)
    overload = np.any(np.abs(v2) > r[:, None], axis=-1)
    counts = np.clip(np.rint(v2 / vpc), -fs, fs).astype(np.int16)
    return (counts[0], overload[:1]) if one else (counts, overload)
