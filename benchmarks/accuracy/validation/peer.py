"""The peer: sdypy-EMA (LSCF poles + its linear LSFD for the modal constants) on the same FRFs.

sdypy-EMA is never a dependency of impactlab: it lives in its own venv (``../peer-venv``). When
it cannot be imported, :func:`fit_peer` returns a :class:`PeerFit` with ``ok=False`` and the reason,
and the reports say the peer was unavailable.

How the peer is driven (its documented non-interactive path)
------------------------------------------------------------
``Model(frf[n_frf, n_freq], freq, lower=lo, upper=hi, pol_order_high=N, frf_form=quantity)``,
``get_poles("lscf")``, ``select_closest_poles(hints, f_window=F_WINDOW_HZ)`` with ``hints`` = the natural frequencies
impactlab found (sdypy has no automatic selection; this favours the peer), then
``get_constants("lsfd")`` (linear: the poles stay those of LSCF) with upper and lower residuals.
sdypy drops the line at ``upper`` (it keeps ``freq < upper``), so it is handed one extra line.

Pole bookkeeping
----------------
sdypy reports ``nat_freq``/``nat_xi`` from its stabilization matrix, but ``get_constants`` uses
``all_poles[pole_ind]``. Both are recorded here (``freq_hz``/``damping`` = reported,
``used_freq_hz``/``used_damping`` = the poles its LSFD actually used) so a mismatch shows.
"""
from __future__ import annotations

import contextlib
import io
import logging
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from analysis.frf import FRFSet

from .common import synthesis_error

log = logging.getLogger(__name__)

__all__ = ["PeerFit", "fit_peer", "peer_available", "F_WINDOW_HZ"]

#: sdypy's ``select_closest_poles`` search window (its default is 50 Hz); see :func:`fit_peer`
F_WINDOW_HZ = 4.0


@dataclass
class PeerFit:
    """sdypy-EMA's result on one FRF set (``ok=False`` with ``reason`` when it could not run)."""

    ok: bool
    reason: str = ""
    freq_hz: np.ndarray = field(default_factory=lambda: np.zeros(0))
    damping: np.ndarray = field(default_factory=lambda: np.zeros(0))
    used_freq_hz: np.ndarray = field(default_factory=lambda: np.zeros(0))
    used_damping: np.ndarray = field(default_factory=lambda: np.zeros(0))
    H_band: np.ndarray | None = None
    synth_err_pct: float = float("nan")
    time_s: float = float("nan")
    version: str = ""


def _import_ema():
    try:
        from sdypy import EMA  # noqa: F401
    except ImportError as exc:
        return None, f"sdypy-EMA not importable ({exc}); run the scripts with ../peer-venv/bin/python"
    return EMA, ""


def peer_available() -> bool:
    """True when sdypy-EMA can be imported in this interpreter."""
    return _import_ema()[0] is not None


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("sdypy-EMA")
    except Exception:  # noqa: BLE001 - metadata lookup is best effort
        return "?"


def _repair_pole_ind(m) -> np.ndarray:
    """``pole_ind`` pointing at the model order the reported poles come from (see module doc)."""
    fixed = []
    for (c, _k), f, z in zip(np.asarray(m.pole_ind, int), m.nat_freq, m.nat_xi):
        c1 = min(int(c) + 1, len(m.all_poles) - 1)
        target = -z * 2 * np.pi * f + 1j * 2 * np.pi * f * np.sqrt(max(1 - z * z, 0.0))
        fixed.append([c1, int(np.argmin(np.abs(m.all_poles[c1] - target)))])
    return np.asarray(fixed, int)


def fit_peer(frf: FRFSet, band: Sequence[float], max_modes: int, hints_hz: Sequence[float], *,
             repair: bool = False) -> PeerFit:
    """Run sdypy-EMA on ``frf`` (all FRFs flattened to rows) in ``band`` (Hz).

    max_modes : largest number of modes; sdypy's ``pol_order_high`` (its LSCF gives orders
        2, 4, ..., 2 pol_order_high, i.e. up to ``pol_order_high`` modes).
    hints_hz : approximate natural frequencies for ``select_closest_poles``.
    repair : point ``pole_ind`` at the model order the reported poles come from before the LSFD
        (our fix of the bookkeeping defect, to separate its effect from the method's).
    Returns a :class:`PeerFit`; any exception of the peer is caught and reported in ``reason``.
    """
    EMA, why = _import_ema()
    if EMA is None:
        return PeerFit(False, why)
    hints = [float(h) for h in hints_hz]
    if not hints:
        return PeerFit(False, "no hint frequencies (impactlab found no mode)")
    lo, hi = float(band[0]), float(band[1])
    f = frf.freq_hz
    k_hi = int(np.searchsorted(f, hi, side="right"))  # first line above hi
    # sdypy keeps freq[:argmin|freq - upper|]: hand it the first line above hi as "upper" so
    # every line <= hi stays (when hi is the last line, that line is lost)
    k_top = min(k_hi + 1, f.size)
    upper = float(f[k_top - 1])
    H = frf.H.reshape(-1, f.size)[:, :k_top]
    ff = f[:k_top]
    # sdypy's default search window (50 Hz, refined down to 2 Hz) lets a hint drift to a dense cluster
    # of stable poles (ULiege: 5 of 10 hints end on 89.64 Hz, one on 0 Hz); the hints are accurate, so a
    # narrow window (a +-2 Hz search) just takes the nearest stable LSCF pole
    f_window = F_WINDOW_HZ
    t0 = time.perf_counter()
    sink = io.StringIO()
    try:
        with contextlib.redirect_stderr(sink), contextlib.redirect_stdout(sink), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m = EMA.Model(frf=H, freq=ff, lower=lo, upper=upper, pol_order_high=int(max_modes),
                          frf_form=frf.quantity)
            m.get_poles("lscf", show_progress=False)
            m.select_closest_poles(hints, f_window=f_window)
            if repair:
                m.pole_ind = _repair_pole_ind(m)
            Hrec, _A = m.get_constants(method="lsfd", whose_poles="own", upper_r=True, lower_r=True)
    except Exception as exc:  # noqa: BLE001 - the peer's failures are results, reported in the table
        return PeerFit(False, f"sdypy-EMA raised {type(exc).__name__}: {exc}", time_s=time.perf_counter() - t0,
                       version=_version())
    dt = time.perf_counter() - t0
    pi = np.asarray(m.pole_ind, int)
    used = np.array([m.all_poles[a][b] for a, b in pi])
    used_f = np.abs(used) / (2 * np.pi)
    used_z = -used.real / np.abs(used)
    sub = frf.band(lo, hi)
    meas = sub.H.reshape(-1, sub.freq_hz.size)
    rec_f = np.asarray(m.freq)
    common = np.isin(sub.freq_hz, rec_f)
    Hb = np.full(meas.shape, np.nan + 0j)
    idx = np.searchsorted(rec_f, sub.freq_hz[common])
    Hb[:, common] = np.asarray(Hrec)[:, idx]
    err = synthesis_error(meas, Hb)
    return PeerFit(True, "", np.asarray(m.nat_freq, float), np.asarray(m.nat_xi, float), used_f, used_z,
                   Hb, err, dt, _version())
