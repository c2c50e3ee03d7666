"""Impact-test windows, per-hit spectra and the H1/H2/coherence accumulator.

Windows (applied to one triggered block of ``n`` samples at ``fs`` Hz, trigger at sample ``k0``)
---------------------------------------------------------------------------------------------
* Force window on the hammer channel: 1 from the block start up to ``k0 + W`` (``W`` = width),
  then a half-cosine taper over ``P`` samples, ``w = 0.5 (1 + cos(pi m / P))`` for ``m = 0..P-1``,
  then 0 to the block end. It removes the noise that follows the pulse.
* Exponential window on the responses: ``w(t) = 1`` before the trigger and
  ``w(t) = exp(-(t - t0)/tau)`` from the trigger time ``t0`` on. ``tau`` (s) from "decays to a
  fraction ``r`` at the block end": ``tau = (n - k0) / fs / ln(1/r)`` (:func:`tau_from_end_fraction`).
  By default the force channel gets the same exponential (times its force window), so that the
  windowed FRF is exactly the FRF of the structure with every pole's decay rate increased by
  ``1/tau`` (rad/s); :class:`analysis.frf.FRFSet` carries ``exp_window_tau_s`` for the fitter.

Spectra (one-sided, per hit)
----------------------------
With ``A_k = dt * sum_n a[n] w[n] exp(-2 pi j k n / N)`` (the Fourier transform of the windowed
signal, EU*s) and ``T = N dt`` the block length:

    G_ab[k] = c_k * conj(A_k) * B_k / T,   c_k = 1 at DC (and Nyquist for even N), 2 elsewhere

so ``G_ff`` (N^2/Hz), ``G_xx`` (EU^2/Hz) are real and ``G_fx = conj(F) X`` is the cross spectrum
from force to response (N*EU/Hz). Summed over hits ``i``:

    H1 = sum G_fx / sum G_ff,   H2 = sum G_xx / sum G_xf  (G_xf = conj(G_fx)),
    gamma^2 = |sum G_fx|^2 / (sum G_ff * sum G_xx)   (ordinary coherence, in [0, 1]).

The scale factors cancel in H1, H2 and gamma^2; they matter only for the stored spectra.
All functions are pure: inputs are never modified.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from .frf import FRFSet

__all__ = [
    "excitation_band",
    "excitation_limit_hz",
    "excited_top_hz",
    "EXCITATION_DROP_DB",
    "WindowSettings",
    "AveragedSpectra",
    "tau_from_end_fraction",
    "force_window",
    "exponential_window",
    "HitSpectra",
    "hit_spectra",
    "FRFAccumulator",
    "parse_duration",
    "WINDOW_TAU_RTOL",
    "same_window_tau",
]

#: Exponential windows whose time constants differ by less than this fraction are one window: a window
#: given by its end value gets the time constant of each capture's trigger sample, so hits triggered a few
#: samples apart differ in the fifth digit (a difference of 0.1 % moves a damping ratio by a thousandth of
#: the window's own decay).
WINDOW_TAU_RTOL = 1e-3


def same_window_tau(a: float | None, b: float | None) -> bool:
    """Whether exponential windows of time constants ``a`` and ``b`` (s; None: no window) are one window:
    both absent, or both given and within :data:`WINDOW_TAU_RTOL` of each other."""
    if a is None or b is None:
        return a is None and b is None
    return math.isclose(float(a), float(b), rel_tol=WINDOW_TAU_RTOL, abs_tol=0.0)


def parse_duration(text: str | float | int, fs_hz: float | None = None) -> float:
    """Parse an operator duration into seconds: ``"5ms"``, ``"0.005s"``, ``"0.005"`` (s), ``"200samples"``/``"200smp"``.

    Sample counts need ``fs_hz``; raises ``ValueError`` naming the accepted forms otherwise.
    """
    if isinstance(text, (int, float)):
        value = float(text)
    else:
        s = str(text).strip().lower().replace(" ", "")
        try:
            if s.endswith("ms"):
                value = float(s[:-2]) * 1e-3
            elif s.endswith(("samples", "sample", "smp")):
                for suffix in ("samples", "sample", "smp"):
                    if s.endswith(suffix):
                        num = s[: -len(suffix)]
                        break
                if fs_hz is None:
                    raise ValueError(f"duration {text!r} is in samples but the sample rate is unknown; give it in s or ms")
                value = float(num) / float(fs_hz)
            elif s.endswith("s"):
                value = float(s[:-1])
            else:
                value = float(s)
        except ValueError as exc:
            if "sample rate" in str(exc):
                raise
            raise ValueError(
                f"bad duration {text!r}: write e.g. '5ms', '0.005s', '0.005' (seconds) or '200samples'"
            ) from None
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"bad duration {text!r}: must be a finite, non-negative time")
    return value


def tau_from_end_fraction(exp_window_end_fraction: float, duration_s: float) -> float:
    """Time constant tau (s) of ``exp(-t/tau)`` whose value after ``duration_s`` (s) is
    ``exp_window_end_fraction`` (the window's value at the end of the record, a fraction of 1).

    ``tau = duration_s / ln(1/exp_window_end_fraction)``; e.g. 1 % at the block end: ``0.01``.
    """
    if not (0.0 < exp_window_end_fraction < 1.0):
        raise ValueError(f"exponential window end fraction {exp_window_end_fraction} must lie strictly between "
                         "0 and 1 (the window's value at the block end, e.g. 0.01 for 1 %)")
    if not duration_s > 0:
        raise ValueError(f"exponential window duration {duration_s} s must be positive")
    return float(duration_s / math.log(1.0 / exp_window_end_fraction))


@dataclass(frozen=True)
class WindowSettings:
    """Window parameters of one FRF estimate (all times in seconds).

    force_width_s : rectangular part of the force window after the trigger (None: no force window).
    force_taper_s : length of the cosine taper that follows it (0: hard edge).
    exp_window_tau_s : exponential window time constant (s; None: no exponential window).
    exp_window_end_fraction : alternative to ``exp_window_tau_s``: the window's value at the end of
        the block, a fraction of 1 (e.g. 0.01); resolved to a tau per block by :meth:`tau_for`.
    exp_on_force : apply the exponential to the force channel as well (default True, see module doc).
    """

    force_width_s: float | None = None
    force_taper_s: float = 0.0
    exp_window_tau_s: float | None = None
    exp_window_end_fraction: float | None = None
    exp_on_force: bool = True

    def __post_init__(self) -> None:
        if self.force_width_s is not None and not self.force_width_s > 0:
            raise ValueError(f"force window width {self.force_width_s} s must be positive")
        if self.force_taper_s < 0:
            raise ValueError(f"force window taper {self.force_taper_s} s must be >= 0")
        if self.exp_window_tau_s is not None and self.exp_window_end_fraction is not None:
            raise ValueError("give the exponential window either as a time constant or as an end fraction, not both")
        if self.exp_window_tau_s is not None and not self.exp_window_tau_s > 0:
            raise ValueError(f"exponential window tau {self.exp_window_tau_s} s must be positive")
        if self.exp_window_end_fraction is not None and not (0 < self.exp_window_end_fraction < 1):
            raise ValueError(f"exponential window end fraction {self.exp_window_end_fraction} must lie strictly between 0 and 1")

    def tau_for(self, n_samples: int, fs_hz: float, trigger_index: int) -> float | None:
        """The exponential time constant (s) for a block, or None when there is no exponential window."""
        if self.exp_window_tau_s is not None:
            return float(self.exp_window_tau_s)
        if self.exp_window_end_fraction is not None:
            return tau_from_end_fraction(self.exp_window_end_fraction, (n_samples - trigger_index) / fs_hz)
        return None

    def resolved(self, n_samples: int, fs_hz: float, trigger_index: int) -> WindowSettings:
        """A copy with an end-fraction exponential turned into a fixed tau (s) for this block layout."""
        if self.exp_window_end_fraction is None:
            return self
        tau = self.tau_for(n_samples, fs_hz, trigger_index)
        return WindowSettings(self.force_width_s, self.force_taper_s, tau, None, self.exp_on_force)

    def describe(self) -> str:
        """One line for logs and UFF ID lines, e.g. ``force 10 ms + 2 ms taper; exp tau 0.3 s``."""
        parts = []
        if self.force_width_s is None:
            parts.append("force: none")
        else:
            parts.append(f"force {self.force_width_s * 1e3:.4g} ms + {self.force_taper_s * 1e3:.4g} ms taper")
        if self.exp_window_tau_s is not None:
            parts.append(f"exp tau {self.exp_window_tau_s:.6g} s" + (" (also force)" if self.exp_on_force else ""))
        elif self.exp_window_end_fraction is not None:
            parts.append(f"exp to {100 * self.exp_window_end_fraction:.4g} % at block end")
        else:
            parts.append("exp: none")
        return "; ".join(parts)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> WindowSettings:
        """Settings from :meth:`to_dict`'s keys; recordings written before the exponential window's
        names were settled (``exp_tau_s``, ``exp_decay``) are read as well."""
        d = {_OLD_WINDOW_KEYS.get(k, k): v for k, v in d.items()}
        known = {k: d[k] for k in ("force_width_s", "force_taper_s", "exp_window_tau_s", "exp_window_end_fraction",
                                   "exp_on_force") if k in d}
        return cls(**known)


#: window keys of older recordings and the names they now have
_OLD_WINDOW_KEYS = {"exp_tau_s": "exp_window_tau_s", "exp_decay": "exp_window_end_fraction"}


def force_window(n: int, fs_hz: float, trigger_index: int, width_s: float, taper_s: float = 0.0) -> np.ndarray:
    """Force window (see module doc): ones to ``trigger + width``, half-cosine taper, then zeros."""
    n = int(n)
    k_end = int(trigger_index) + int(round(width_s * fs_hz))
    p = int(round(taper_s * fs_hz))
    w = np.zeros(n)
    w[: max(0, min(n, k_end))] = 1.0
    if p > 0 and k_end < n:
        m = np.arange(p)
        taper = 0.5 * (1.0 + np.cos(np.pi * m / p))
        stop = min(n, k_end + p)
        w[max(0, k_end):stop] = taper[max(0, -k_end): stop - k_end]
    return w


def exponential_window(n: int, fs_hz: float, trigger_index: int, exp_window_tau_s: float) -> np.ndarray:
    """``exp(-(t - t0)/tau)`` from the trigger on, 1 before it (``exp_window_tau_s``: tau, s)."""
    if not exp_window_tau_s > 0:
        raise ValueError(f"exponential window tau {exp_window_tau_s} s must be positive")
    k = np.arange(int(n)) - int(trigger_index)
    return np.exp(-np.maximum(k, 0) / (exp_window_tau_s * fs_hz))


@dataclass(frozen=True)
class HitSpectra:
    """One hit's one-sided spectra (see module doc for the scaling).

    Gff : (n_freq,) N^2/Hz; Gxx : (n_resp, n_freq); Gfx : (n_resp, n_freq) complex.
    exp_window_tau_s : exponential window time constant used (s; None when none).
    """

    freq_hz: np.ndarray
    Gff: np.ndarray
    Gxx: np.ndarray
    Gfx: np.ndarray
    exp_window_tau_s: float | None


@dataclass(frozen=True)
class AveragedSpectra:
    """The averaged spectra of one measurement point, its H2 estimate and the windows used.

    Gff : (n_freq,) N^2/Hz; Gxx : (n_out, n_freq) EU^2/Hz; Gfx : (n_out, n_freq) N*EU/Hz complex;
    H2 : (n_out, n_freq) EU/N; n_averages : number of hits averaged; windows : the window settings
    the hits were processed with.
    """

    Gff: np.ndarray
    Gxx: np.ndarray
    Gfx: np.ndarray
    H2: np.ndarray
    n_averages: int
    windows: WindowSettings


def _one_sided_factor(n: int) -> np.ndarray:
    c = np.full(n // 2 + 1, 2.0)
    c[0] = 1.0
    if n % 2 == 0:
        c[-1] = 1.0
    return c


def hit_spectra(
    force: np.ndarray,
    responses: np.ndarray,
    fs_hz: float,
    trigger_index: int = 0,
    windows: WindowSettings = WindowSettings(),
) -> HitSpectra:
    """Window one hit and return its auto and cross spectra.

    force : (n,) force in N; responses : (n_resp, n) or (n,) in engineering units;
    fs_hz : sample rate (Hz); trigger_index : the trigger sample (window origin).
    """
    f = np.asarray(force, dtype=float)
    x = np.atleast_2d(np.asarray(responses, dtype=float))
    if f.ndim != 1:
        raise ValueError(f"force must be one channel (1-D); got shape {f.shape}")
    n = f.size
    if x.ndim != 2 or x.shape[1] != n:
        raise ValueError(f"responses must have shape (n_resp, {n}) to match the force; got {x.shape}")
    if n < 4:
        raise ValueError(f"a block of {n} samples is too short for spectra")
    if not fs_hz > 0:
        raise ValueError(f"sample rate {fs_hz} Hz must be positive")
    k0 = int(trigger_index)
    if not 0 <= k0 < n:
        raise ValueError(f"trigger index {k0} lies outside the block of {n} samples")
    wf = np.ones(n)
    if windows.force_width_s is not None:
        wf = force_window(n, fs_hz, k0, windows.force_width_s, windows.force_taper_s)
    tau = windows.tau_for(n, fs_hz, k0)
    wx = None
    if tau is not None:
        wx = exponential_window(n, fs_hz, k0, tau)
        if windows.exp_on_force:
            wf = wf * wx
    dt = 1.0 / fs_hz
    F = np.fft.rfft(f * wf) * dt
    X = np.fft.rfft(x * wx if wx is not None else x, axis=1) * dt
    scale = _one_sided_factor(n) / (n * dt)
    Gff = scale * (F.real ** 2 + F.imag ** 2)
    Gxx = scale * (X.real ** 2 + X.imag ** 2)
    Gfx = scale * (np.conj(F) * X)
    freq = np.fft.rfftfreq(n, dt)
    return HitSpectra(freq, Gff, Gxx, Gfx, tau)


class FRFAccumulator:
    """Sum of per-hit spectra with rollback; H1, H2 and coherence on demand.

    ``add(hit)`` appends a hit's :class:`HitSpectra`; ``rollback()`` removes the last one (the
    sums are recomputed from the kept hits in order, so results never drift and equal a fresh
    accumulation of the same hits bit for bit).
    """

    def __init__(self, outputs: Sequence[str], reference: str, quantity: str = "accelerance", unit: str = "") -> None:
        self.outputs = tuple(str(o) for o in outputs)
        self.reference = str(reference)
        self.quantity = quantity
        self.unit = unit
        self._hits: list[HitSpectra] = []
        self._sum: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @property
    def n_averages(self) -> int:
        return len(self._hits)

    @property
    def hits(self) -> tuple:
        """The accumulated hits' :class:`HitSpectra`, in order."""
        return tuple(self._hits)

    def add(self, hit: HitSpectra) -> None:
        """Add one hit's spectra to the average."""
        if hit.Gxx.shape[0] != len(self.outputs):
            raise ValueError(f"hit has {hit.Gxx.shape[0]} responses but the accumulator has {len(self.outputs)} outputs")
        if self._hits:
            first = self._hits[0]
            if hit.freq_hz.shape != first.freq_hz.shape or not np.array_equal(hit.freq_hz, first.freq_hz):
                raise ValueError("hit spectra have a different frequency axis (block length or sample rate changed)")
            if not same_window_tau(hit.exp_window_tau_s, first.exp_window_tau_s):
                raise ValueError(
                    f"hit used exponential tau {hit.exp_window_tau_s} s but earlier hits used {first.exp_window_tau_s} s "
                    f"(more than {WINDOW_TAU_RTOL:.1%} apart); "
                    "use one window per average (a fixed tau rather than an end fraction with varying triggers)"
                )
        self._hits.append(hit)
        if self._sum is None:
            self._sum = (hit.Gff.copy(), hit.Gxx.copy(), hit.Gfx.copy())
        else:
            self._sum = (self._sum[0] + hit.Gff, self._sum[1] + hit.Gxx, self._sum[2] + hit.Gfx)

    def rollback(self) -> None:
        """Remove the last added hit."""
        if not self._hits:
            raise ValueError("no hit to roll back: the average is empty")
        self._hits.pop()
        self._sum = None
        for h in self._hits:
            if self._sum is None:
                self._sum = (h.Gff.copy(), h.Gxx.copy(), h.Gfx.copy())
            else:
                self._sum = (self._sum[0] + h.Gff, self._sum[1] + h.Gxx, self._sum[2] + h.Gfx)

    def _require(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self._sum is None:
            raise ValueError("no hits accumulated yet: add at least one accepted hit")
        return self._sum

    @property
    def freq_hz(self) -> np.ndarray:
        self._require()
        return self._hits[0].freq_hz

    @property
    def exp_window_tau_s(self) -> float | None:
        """The exponential window's time constant (s) of the averaged hits (None: none)."""
        return self._hits[0].exp_window_tau_s if self._hits else None

    def spectra(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Averaged (Gff, Gxx, Gfx) (sums divided by the number of hits)."""
        Sff, Sxx, Sfx = self._require()
        n = len(self._hits)
        return Sff / n, Sxx / n, Sfx / n

    def averaged(self, windows: WindowSettings) -> AveragedSpectra:
        """The averaged spectra with H2 (``windows``: the settings the hits were processed with)."""
        Gff, Gxx, Gfx = self.spectra()
        return AveragedSpectra(Gff, Gxx, Gfx, self.h2(), self.n_averages, windows)

    def h1(self) -> np.ndarray:
        """H1 = Gfx / Gff, shape (n_resp, n_freq); NaN where Gff = 0."""
        Sff, _, Sfx = self._require()
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(Sff > 0, Sfx / np.where(Sff > 0, Sff, 1.0), np.nan)

    def h2(self) -> np.ndarray:
        """H2 = Gxx / Gxf, shape (n_resp, n_freq); NaN where Gxf = 0."""
        _, Sxx, Sfx = self._require()
        Sxf = np.conj(Sfx)
        ok = np.abs(Sxf) > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(ok, Sxx / np.where(ok, Sxf, 1.0), np.nan)

    def coherence(self) -> np.ndarray:
        """Ordinary coherence |Gfx|^2 / (Gff Gxx), shape (n_resp, n_freq), in [0, 1] (0 where undefined)."""
        Sff, Sxx, Sfx = self._require()
        den = Sff[None, :] * Sxx
        ok = den > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            c = np.where(ok, (Sfx.real ** 2 + Sfx.imag ** 2) / np.where(ok, den, 1.0), 0.0)
        return np.clip(c, 0.0, 1.0)

    def frfset(self, estimator: str = "H1", meta: dict | None = None,
               sample_rate_hz: float | None = None, record_s: float | None = None,
               pretrigger_s: float | None = None) -> FRFSet:
        """The averaged FRFs as an :class:`FRFSet` with one reference (``H[n_out, 1, n_freq]``);
        ``sample_rate_hz`` (Hz), ``record_s`` and ``pretrigger_s`` (s): the acquisition's, carried by the set."""
        est = estimator.upper()
        if est not in ("H1", "H2"):
            raise ValueError(f"estimator {estimator!r} is not H1 or H2")
        H = self.h1() if est == "H1" else self.h2()
        m = {"estimator": est, "n_averages": self.n_averages,
             "excitation_limit_hz": excitation_limit_hz(self.freq_hz, self.spectra()[0])}
        m.update(meta or {})
        return FRFSet(
            freq_hz=self.freq_hz,
            H=H[:, None, :],
            quantity=self.quantity,
            outputs=self.outputs,
            references=(self.reference,),
            unit=self.unit,
            coherence=self.coherence()[:, None, :],
            exp_window_tau_s=self.exp_window_tau_s,
            meta=m,
            sample_rate_hz=sample_rate_hz,
            record_s=record_s,
            pretrigger_s=pretrigger_s,
        )


def excitation_band(freq_hz: np.ndarray, gff_db: np.ndarray, drops_db: Sequence[float] = (10.0, 20.0)
                    ) -> dict[float, float | None]:
    """Where the force autospectrum has fallen ``drop`` dB below its low-frequency level, for each
    drop (Hz; None when it never falls that far): the usable excitation band of a hammer hit.

    ``gff_db``: the force autospectrum in dB (any reference) at ``freq_hz``. The low-frequency level
    is the largest value over the lowest 2 % of the lines (at least 3) without the DC line: a
    hammer's spectrum is flat from DC, but a DC offset on the force channel puts a spike there (and
    an AC-coupled channel loses it). The edge is the first line below ``level - drop``, refined by
    linear interpolation in dB with the line before.
    """
    f = np.asarray(freq_hz, dtype=float)
    g = np.asarray(gff_db, dtype=float)
    g = np.where(np.isfinite(g), g, -np.inf)
    first = 1 if f.size > 3 and f[0] == 0.0 else 0
    level = float(np.max(g[first:first + max(3, int(0.02 * f.size))]))
    out: dict[float, float | None] = {}
    for drop in drops_db:
        below = np.flatnonzero(g < level - drop)
        below = below[below > first]
        if not below.size:
            out[drop] = None
            continue
        k = int(below[0])
        d0, d1 = g[k - 1], g[k]
        frac = (level - drop - d0) / (d1 - d0) if np.isfinite(d1) and d1 != d0 else 1.0
        out[drop] = float(f[k - 1] + (f[k] - f[k - 1]) * frac)
    return out


#: the force spectrum's fall (dB below its low-frequency level) taken as the end of the band a fit may use
EXCITATION_DROP_DB = 20.0


def excited_top_hz(freq_hz: np.ndarray, gff: np.ndarray, drop_db: float = EXCITATION_DROP_DB) -> float | None:
    """Upper end (Hz) of a shaker's excitation band in a force autospectrum ``gff`` (linear) at
    ``freq_hz``: the last line within ``drop_db`` of the spectrum's peak (a multisine or a sweep
    excites a band that need not start at DC, unlike a hammer's pulse, :func:`excitation_limit_hz`);
    None for an all-zero spectrum."""
    g = np.asarray(gff, dtype=float)
    peak = float(np.nanmax(g)) if g.size else 0.0
    if not peak > 0:
        return None
    within = np.flatnonzero(g >= peak * 10.0 ** (-drop_db / 10.0))
    return float(np.asarray(freq_hz, dtype=float)[within[-1]])


def excitation_limit_hz(freq_hz: np.ndarray, gff: np.ndarray, drop_db: float = EXCITATION_DROP_DB) -> float | None:
    """Upper end (Hz) of the excitation band of a force autospectrum ``gff`` (linear, e.g. N^2/Hz)
    at ``freq_hz``: where it has fallen ``drop_db`` below its low-frequency level
    (:func:`excitation_band`); None when it never falls that far (the hammer excites every line)."""
    g = np.asarray(gff, dtype=float)
    peak = float(np.nanmax(g)) if g.size else 0.0
    if not peak > 0:
        return None
    db = 10.0 * np.log10(np.maximum(g, peak * 1e-30))
    return excitation_band(freq_hz, db, (drop_db,))[drop_db]

