"""An empirical spread of the fitted poles: the scatter of refits on independent FRF groups.

The standard deviations of :class:`analysis.lsfd.LSFDResult` (``freq_hz_std``,
``damping_std``) assume white noise and a perfect model; on real data model error dominates
and they are lower bounds (``docs/fitting.md``, section 9). This module measures the spread
directly: the FRFs are split into groups that each see the modes on their own, every group is
refitted by LSFD from the global result's raw poles, and the spread of the group estimates is
reported as the standard deviation *of the global estimate*:

    s_f(r) = std_g(f_g,r) / sqrt(G_r)        (ddof = 1; likewise for zeta)

with ``G_r`` the groups whose fit kept mode r (a group's pole that ends on its frequency
trust region edge, or with damping outside (0, 0.2), did not see the mode: it is left out).

Groups: one per reference when there are at least two references (each reference's FRFs
are a complete single-reference test); otherwise the outputs in ``min(3, n_out)`` interleaved
groups. Each group refit is a full LSFD: the cost is about ``G`` times the global fit.
"""
from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .fit_checks import MIGRATE_BANDWIDTHS, bandwidth_hz
from .frf import FRFSet

if TYPE_CHECKING:
    from .lsfd import LSFDResult

__all__ = ["SubsetScatter", "subset_scatter"]

log = logging.getLogger(__name__)

MAX_DAMPING = 0.2


@dataclass(frozen=True)
class SubsetScatter:
    """Spread of per-group refits.

    groups : description of each group ("reference right:6:-X", "outputs 1, 4").
    freq_hz, damping : (n_groups, m) estimates per group (NaN where the group lost the mode).
    freq_hz_std, damping_std : (m,) std of the global estimate, ``std_g / sqrt(G_r)`` (NaN when
        fewer than two groups kept the mode).
    n_groups : (m,) groups that kept each mode.
    """

    groups: tuple
    freq_hz: np.ndarray
    damping: np.ndarray
    freq_hz_std: np.ndarray
    damping_std: np.ndarray
    n_groups: np.ndarray


def _groups(frf: FRFSet) -> list[tuple[str, FRFSet]]:
    if frf.n_references >= 2:
        return [(f"reference {r}", frf.select(references=[r])) for r in frf.references]
    if frf.n_outputs >= 2:
        k = min(3, frf.n_outputs)
        out = []
        for g in range(k):
            names = list(frf.outputs[g::k])
            out.append((f"outputs {', '.join(names)}", frf.select(outputs=names)))
        return out
    raise ValueError("a scatter estimate needs at least two references or two outputs (one FRF cannot be split)")


def subset_scatter(frf: FRFSet, result: LSFDResult, *, max_iter: int = 50) -> SubsetScatter:
    """Refit every FRF group (see module docstring) from ``result.poles_raw``; ``frf`` is the set the
    result was fitted to (same outputs and references)."""
    from .lsfd import LSFDConvergenceWarning, fit_lsfd

    if not isinstance(frf, FRFSet):
        raise TypeError(f"frf must be an analysis.frf.FRFSet; got {type(frf).__name__}")
    start = np.asarray(result.poles_raw, dtype=complex)
    df = frf.line_spacing_hz
    window = MIGRATE_BANDWIDTHS * bandwidth_hz(start, df)
    groups = _groups(frf)
    F = np.full((len(groups), start.size), np.nan)
    Z = np.full_like(F, np.nan)
    for g, (name, sub) in enumerate(groups):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", LSFDConvergenceWarning)
                r = fit_lsfd(sub, start, method=result.method, band=result.band,
                             residual_form=result.model.residual_form, max_iter=max_iter, freq_window_hz=window)
        except (ValueError, np.linalg.LinAlgError) as exc:
            log.info("scatter: the refit of %s failed (%s)", name, exc)
            continue
        moved = np.abs(r.poles_raw.imag - start.imag) / (2 * np.pi)
        ok = (moved < 0.99 * window) & (r.damping > 0) & (r.damping < MAX_DAMPING)
        F[g, ok] = r.freq_hz[ok]
        Z[g, ok] = r.damping[ok]
    n = np.sum(np.isfinite(F), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        fs = np.where(n >= 2, np.nanstd(np.where(n >= 2, F, 0.0), axis=0, ddof=1) / np.sqrt(np.maximum(n, 1)), np.nan)
        zs = np.where(n >= 2, np.nanstd(np.where(n >= 2, Z, 0.0), axis=0, ddof=1) / np.sqrt(np.maximum(n, 1)), np.nan)
    return SubsetScatter(tuple(name for name, _ in groups), F, Z, fs, zs, n)
