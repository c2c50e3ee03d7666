"""The outcome of the automatic fit (:func:`analysis.pipeline.fit_auto`): the LSFD result, the
stabilization diagram, the band, the warnings, and an honest verdict.

``success`` means *converged and physically sensible*, not just "the iteration stopped":

- converged: the LSFD met its tolerances (``LSFDResult.success``);
- sensible (:func:`assess_fit`): every pole's natural frequency lies in the fitted band, every
  damping ratio in ``(0, MAX_DAMPING)``, and every frequency is determined by the data (a
  finite standard deviation smaller than ``MAX_FREQ_STD_FRACTION`` of the frequency).

- complete (:func:`analysis.missing_modes.unfitted_resonances`, called by the pipeline): every
  resonance the data show (:mod:`analysis.visibility`: a peak >= 10 dB above its neighbouring
  minima, clean in the coherence) has a pole of its own or is reproduced by the model; a peak
  left over is named with its frequency (or as a possible close pair). Suspension modes (the
  structure as a rigid body on its supports, far below its first elastic mode:
  :mod:`analysis.suspension`) are named as such in ``suspension_hz`` and the warnings, not as missed.

Anything else is reported in ``problems`` and ``success`` is False. FRFs of a single average are
flagged in the warnings: their coherence is 1 everywhere and says nothing about the noise.
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .fit_messages import verdict_message

__all__ = ["FitResult", "assess_fit", "MAX_DAMPING", "MAX_FREQ_STD_FRACTION"]

#: largest damping ratio taken as a structural mode (above it a pole is noise or a fitting artefact)
MAX_DAMPING = 0.2
#: a frequency whose standard deviation exceeds this fraction of it is not determined by the data
MAX_FREQ_STD_FRACTION = 0.1


def assess_fit(lsfd: Any, band: tuple[float, float]) -> list[str]:
    """Reasons why a fitted model is not physically sensible (empty: it is). ``lsfd`` is an
    :class:`analysis.lsfd.LSFDResult`; ``band`` (lo, hi) Hz the fitted band."""
    problems = []
    f = np.asarray(lsfd.freq_hz, float)
    z = np.asarray(lsfd.damping, float)
    fstd = np.asarray(lsfd.freq_hz_std, float)
    lo, hi = float(band[0]), float(band[1])
    if f.size == 0:
        return ["no mode was fitted"]
    for i in range(f.size):
        name = f"mode {i + 1} ({f[i]:.5g} Hz)"
        if not lo <= f[i] <= hi:
            problems.append(f"{name} lies outside the fitted band {lo:.5g}..{hi:.5g} Hz")
        if not 0.0 < z[i] < MAX_DAMPING:
            problems.append(f"{name} has a damping ratio of {100 * z[i]:.3g} %, outside 0..{100 * MAX_DAMPING:g} %")
        if not (np.isfinite(fstd[i]) and fstd[i] < MAX_FREQ_STD_FRACTION * f[i]):
            problems.append(f"{name} is not determined by the data (standard deviation {fstd[i]:.3g} Hz)")
    return problems


@dataclass(frozen=True)
class FitResult:
    """What :func:`analysis.pipeline.fit_auto` found.

    lsfd : the :class:`analysis.lsfd.LSFDResult` (poles, model, standard deviations...).
    stabilization : the :class:`analysis.stabilization.StabilizationResult`, or None when the
        poles were given.
    band : (lo, hi) Hz of the lines fitted (after moving the edges off resonances).
    selected_poles : (m,) complex rad/s, the poles the LSFD started from.
    warnings : what the user should know (band edges, dropped or added poles, non-convergence,
        a single average), each once.
    problems : why the model is not physically sensible (:func:`assess_fit`) or not complete (a
        visible resonance left without a pole); empty when it is both.
    suspension_hz : the suspension (rigid-body) modes, Hz (:mod:`analysis.suspension`): resonances
        of the structure on its supports below its first elastic mode, fitted or not; they are
        named in the warnings and are no problem.

    ``success`` = converged and no problems; ``status`` "converged", "not converged" or
    "implausible"; ``message`` says why in words. The result unpacks as
    ``lsfd, stabilization = fit_auto(...)`` for scripts written against the former pair.
    """

    lsfd: Any
    stabilization: Any
    band: tuple
    selected_poles: np.ndarray
    warnings: tuple = ()
    problems: tuple = field(default=())
    suspension_hz: tuple = ()

    @property
    def converged(self) -> bool:
        return bool(self.lsfd.success)

    @property
    def success(self) -> bool:
        return self.converged and not self.problems

    @property
    def status(self) -> str:
        if not self.converged:
            return "not converged"
        return "implausible" if self.problems else "converged"

    @property
    def message(self) -> str:
        return verdict_message(self.status, lsfd=self.lsfd.message, problems="; ".join(self.problems),
                               n_modes=self.lsfd.freq_hz.size, lo=self.band[0], hi=self.band[1])

    @property
    def model(self) -> Any:
        """The fitted :class:`analysis.modal.ModalModel` (window-corrected poles)."""
        return self.lsfd.model

    @property
    def freq_hz(self) -> np.ndarray:
        return self.lsfd.freq_hz

    @property
    def damping(self) -> np.ndarray:
        return self.lsfd.damping

    def table(self) -> list[dict[str, float]]:
        """One row per mode in order of frequency: f (Hz), zeta (ratio) and their standard deviations."""
        lf = self.lsfd
        order = np.argsort(np.asarray(lf.freq_hz, dtype=float))
        return [{"mode": i + 1, "freq_hz": float(lf.freq_hz[k]), "freq_hz_std": float(lf.freq_hz_std[k]),
                 "damping": float(lf.damping[k]), "damping_std": float(lf.damping_std[k])}
                for i, k in enumerate(order)]

    def __str__(self) -> str:
        lines = [f"{'mode':>4s} {'f [Hz]':>11s} {'+-':>9s} {'zeta [%]':>9s} {'+-':>8s}"]
        for row in self.table():
            lines.append(f"{row['mode']:4d} {row['freq_hz']:11.4f} {row['freq_hz_std']:9.2g} "
                         f"{100 * row['damping']:9.3f} {100 * row['damping_std']:8.2g}")
        lines.append(f"{self.status}: {self.message}")
        if self.warnings:
            lines.append(f"{len(self.warnings)} note(s): see .warnings")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return (f"FitResult({self.lsfd.freq_hz.size} modes in {self.band[0]:.5g}..{self.band[1]:.5g} Hz, "
                f"status={self.status!r}, {len(self.warnings)} warning(s))")

    def _repr_html_(self) -> str:
        rows = "".join(f"<tr><td>{r['mode']}</td><td>{r['freq_hz']:.4f}</td><td>{r['freq_hz_std']:.2g}</td>"
                       f"<td>{100 * r['damping']:.3f}</td><td>{100 * r['damping_std']:.2g}</td></tr>"
                       for r in self.table())
        import html

        return (f"<p><b>{html.escape(self.status)}</b>: {html.escape(self.message)}</p>"
                "<table><thead><tr><th>mode</th><th>f [Hz]</th><th>&sigma;<sub>f</sub> [Hz]</th>"
                f"<th>&zeta; [%]</th><th>&sigma;<sub>&zeta;</sub> [%]</th></tr></thead><tbody>{rows}</tbody></table>")

    def plot(self, frf: Any, **options: Any) -> Any:
        """Measured vs synthesised FRFs of ``frf`` over the fitted band (:func:`analysis.plots.fit_figure`);
        returns the matplotlib ``Figure``."""
        from .plots import fit_figure

        return fit_figure(frf, self.lsfd, band=self.band, **options)

    def __iter__(self) -> Iterator[Any]:
        yield self.lsfd
        yield self.stabilization

    def summary(self) -> dict:
        """The verdict as plain data (for JSON documents)."""
        return {"success": self.success, "status": self.status, "message": self.message,
                "converged": self.converged, "problems": list(self.problems), "warnings": list(self.warnings),
                "band_hz": [float(self.band[0]), float(self.band[1])]}
