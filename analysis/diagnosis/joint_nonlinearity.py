"""Physical cause ``joint_nonlinearity``: which joint or support has an amplitude-dependent spring.

Input: the level comparison of the measurement (:class:`analysis.linearity.LinearityResult`: per mode
the frequency change ``df_r`` % and damping change from the lowest to the highest excitation level,
with standard deviations) and a simulation with the protocol :class:`JointSimulation` (the frame's
FE model: for each candidate rotational spring of a joint or a support, the share of each mode's
strain energy stored in it, ``s_r = k0 delta_r^2 / omega_r^2``; :func:`simulator.nonlinear_joint.joint_candidates`).
This module never runs the simulator; it only reads those answers.

Physics. A spring whose stiffness changes by ``dk / k0`` between the levels moves mode r by
``df_r / f_r = s_r dk / (2 k0)``; a loss factor ``eta`` in it adds ``s_r eta / 2`` to the mode's damping
ratio. So each candidate predicts the pattern of the changes over the modes up to two numbers
(stiffness change ``a = dk / k0`` and loss-factor change ``b``), fitted by weighted least squares:

    df_r / 100 = s_r a / 2,     d zeta_r = s_r b / 2     (per measured mode r, paired by frequency)

with each residual's deviation ``sqrt(sd_r^2 + (MODEL_FRACTION change_r)^2 + floor^2)`` (the shares are
linear-model quantities, the joint's rotation differs per mode). A global candidate (the same
relative change for every mode: :mod:`analysis.diagnosis.timedata`'s ``amplitude_nonlinearity``)
competes.

With a simulation that re-runs the test (``level_frfs``), the ``N_SIMULATED`` best candidates of that
screening are then simulated: the test's hits at its levels with an Iwan joint at the candidate,
its slip moment sized from the screening's stiffness change and the candidate's peak rotation in the
linear frame (uniform micro-slip: secant loss ``(1 - rho) A / (2 theta_s)``); the simulated changes
per mode, scaled by one factor each for frequency and damping, are compared with the measured ones
(deviation ``SIM_MODEL_FRACTION`` of each change) and rank the candidates; the frequency factor
corrects the slip moment (the softening scales as its inverse).

The cause is named when the comparison says "nonlinear", the best candidate is a joint or support and
its chi2 is at most ``1 / MIN_LIKELIHOOD_RATIO`` of the global candidate's; candidates within
``MIN_MARGIN`` of it are listed (``ambiguous_with``: adjacent springs of one member load the same
modes). The law's parameters are the screening's stiffness change (softening when negative), the
loss-factor change (friction when positive: micro-slip; none: a nonlinear spring) and, when simulated,
the Iwan slip moment.

Measurements at several drive levels without a simulation of the test (FRF files, each with its level:
``diagnose --measured A B --levels LA,LB``): :func:`measured_levels` compares them and
:func:`amplitude_dependence` names the cause when a mode moves beyond its uncertainty, with the kind of
law the changes show and every mode's shift per level (:func:`level_shifts`); no joint is located.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from ..frf import FRFSet

__all__ = ["JointCandidate", "JointSimulation", "JointSimulationFactory", "joint_nonlinearity", "level_dependence",
           "named_joint", "MODEL_FRACTION", "MIN_MARGIN", "measured_levels", "amplitude_dependence", "named_levels",
           "level_shifts"]

#: Model error of the share pattern as a fraction of each change.
MODEL_FRACTION = 0.3
#: Floors of the deviations: frequency change (%), damping-ratio change (absolute).
DF_FLOOR_PERCENT = 0.01
DZETA_FLOOR = 2e-5
#: Candidates whose chi2 is within this factor of the best are listed as fitting nearly as well.
MIN_MARGIN = 1.5
#: ...and the global (every mode alike) candidate's by this factor.
MIN_LIKELIHOOD_RATIO = 2.0
#: Measured and model modes pair within this relative frequency difference.
PAIR_TOLERANCE = 0.08
#: Candidates (best by the share screening) whose level dependence is simulated.
N_SIMULATED = 4
#: Model error of a simulated pattern as a fraction of each change.
SIM_MODEL_FRACTION = 0.15
#: The simulated Iwan law's share of the stiffness that never slips (as the simulation side uses).
RESIDUAL_FRACTION = 0.3


@dataclass(frozen=True)
class JointCandidate:
    """A rotational spring that may be nonlinear: ``name`` (e.g. ``"joint right:10-top:8 ry"``), ``kind``
    ("joint" or "support"), ``nodes`` (its node keys), ``axis`` ("rx", "ry", "rz"), its linear stiffness
    ``stiffness_nm_per_rad`` and ``shares`` (n_modes,): the share of each model mode's strain energy in it."""

    name: str
    kind: str
    nodes: tuple
    axis: str
    stiffness_nm_per_rad: float
    shares: np.ndarray


class JointSimulation(Protocol):
    """What the cause needs of the simulation (:class:`simulator.nonlinear_simulation.JointHitSimulation`)."""

    def joint_candidates(self) -> tuple[np.ndarray, Sequence[JointCandidate]]:
        """The model's natural frequencies (Hz) and its candidate springs."""
        ...

    def peak_rotation(self, candidate: str) -> float:
        """Peak rotation (rad) of the candidate spring in the linear frame at the highest level's hits."""
        ...

    def level_frfs(self, candidate: str, slip_moment_nm: float) -> list[FRFSet]:
        """The test's FRFs per level (ascending, the measurement's levels, points and lines) with an Iwan
        joint of that slip moment (N m) at the candidate spring (``RESIDUAL_FRACTION`` never slips)."""
        ...


def _pair(measured_hz: np.ndarray, model_hz: np.ndarray) -> np.ndarray:
    """Index of the nearest model mode for each measured mode (-1 when none is within PAIR_TOLERANCE)."""
    out = np.full(measured_hz.size, -1)
    for i, f in enumerate(measured_hz):
        j = int(np.argmin(np.abs(np.log(model_hz / f))))
        if abs(model_hz[j] / f - 1.0) <= PAIR_TOLERANCE:
            out[i] = j
    return out


def _fit(x: np.ndarray, y: np.ndarray, sd: np.ndarray) -> tuple[float, float]:
    """(coefficient, chi2) of y = c x by weighted least squares."""
    w = 1.0 / sd ** 2
    den = float(np.sum(w * x * x))
    c = float(np.sum(w * x * y)) / den if den > 0 else 0.0
    return c, float(np.sum(w * (y - c * x) ** 2))


#: Builds the simulation of a recorded test from its hits (:class:`analysis.linearity.LevelHit`), their force
#: levels (N) and the FRF set per level (e.g. :class:`simulator.nonlinear_simulation.JointHitSimulation`).
JointSimulationFactory = Callable[[Sequence[Any], Sequence[float], Sequence[FRFSet]], JointSimulation]


def level_dependence(recording: str | Path, band: tuple[float, float] | None = None,
                     simulation: JointSimulationFactory | None = None) -> dict | None:
    """The level comparison of a recording whose hits span force levels (``{"linearity": ...}``,
    :func:`analysis.linearity.compare_levels` in ``band`` Hz) and, when it says "nonlinear" and a
    ``simulation`` factory is given, ``"cause"``: :func:`joint_nonlinearity` with the simulation it builds
    of the recorded test. None when the recording holds no hits or their forces do not spread."""
    from ..linearity import compare_levels, recording_hits

    got = recording_hits(recording)
    if got is None:
        return None
    hits, levels, sets = got
    if len(sets) < 2:
        return None
    lin = compare_levels(sets, levels, band=band)
    out: dict = {"linearity": lin.to_dict()}
    if lin.verdict == "nonlinear" and simulation is not None:
        out["cause"] = joint_nonlinearity(lin, simulation(hits, levels, sets))
    return out


def named_joint(cause: dict) -> dict:
    """A present cause of :func:`joint_nonlinearity` as a named cause of the diagnosis: ``effect`` and
    ``parameters`` (the joint's name and the law's plain values)."""
    params: dict = {"joint": cause["joint"]["name"]}
    params.update({k: v for k, v in (cause.get("law") or {}).items() if not isinstance(v, (list, dict))})
    return {"effect": "joint_nonlinearity", "parameters": params, "evidence": cause["evidence"]}


def joint_nonlinearity(linearity: Any, simulation: JointSimulation) -> dict:
    """The cause as a JSON-ready dict (module docstring).

    Keys: ``effect`` ("joint_nonlinearity"), ``present`` (bool), ``evidence`` (one sentence), and when
    the modes allow a fit: ``joint`` (the best candidate: name, kind, nodes, axis, stiffness_nm_per_rad),
    ``law`` (``stiffness_change_percent``, ``loss_factor_change``, ``kind``: "micro-slip friction",
    "softening spring" or "hardening spring", ``slip_moment_nm`` and ``residual_stiffness_fraction`` when
    simulated (else None), ``stiffness_change_percent_per_decade``, ``levels``), ``method`` ("strain-energy
    shares" or "simulated hits"), ``ambiguous_with`` (candidates within ``MIN_MARGIN``), ``chi2`` per
    candidate (best first), ``global_chi2``, ``global_change_percent``, ``modes_used``. ``linearity`` is a
    :class:`analysis.linearity.LinearityResult`.
    """
    base = {"effect": "joint_nonlinearity", "present": False}
    if linearity.verdict != "nonlinear":
        return {**base, "evidence": "the modes do not change between the excitation levels beyond the noise"}
    model_hz, candidates = simulation.joint_candidates()
    model_hz = np.asarray(model_hz, float)
    modes = [m for m in linearity.modes if m.determined]
    if len(modes) < 3 or not candidates:
        return {**base, "evidence": f"{len(modes)} determined mode(s): too few to tell a joint from the whole frame"}
    f = np.array([m.freq_hz for m in modes])
    idx = _pair(f, model_hz)
    keep = idx >= 0
    if keep.sum() < 3:
        return {**base, "evidence": "fewer than three measured modes pair with the simulation's"}
    df = np.array([m.df_percent for m in modes])[keep] / 100.0
    df_sd = np.hypot(np.array([m.df_std_percent for m in modes])[keep] / 100.0,
                     np.hypot(MODEL_FRACTION * df, DF_FLOOR_PERCENT / 100.0))
    z0 = np.array([m.zeta for m in modes])[keep]
    dz = z0 * np.array([m.dzeta_percent for m in modes])[keep] / 100.0
    dz_sd = np.hypot(z0 * np.array([m.dzeta_std_percent for m in modes])[keep] / 100.0,
                     np.hypot(MODEL_FRACTION * dz, DZETA_FLOOR))
    rows: list = []
    for c in candidates:
        s = np.asarray(c.shares, float)[idx[keep]]
        if not np.any(s > 0):
            continue
        a, chi_f = _fit(s / 2.0, df, df_sd)
        b, chi_z = _fit(s / 2.0, dz, dz_sd)
        rows.append((chi_f + chi_z, c, a, b))
    g_a, g_chi = _fit(np.ones(df.size), df, df_sd)
    g_b, g_chiz = _fit(z0, dz, dz_sd)  # every mode's damping scaled alike
    global_chi2 = g_chi + g_chiz
    if not rows:
        return {**base, "evidence": "no candidate joint or support stores strain energy in the measured modes"}
    rows.sort(key=lambda r: r[0])
    method = "strain-energy shares"
    slip = None
    if hasattr(simulation, "level_frfs") and getattr(linearity, "poles", np.zeros(0)).size:
        df_sd2 = np.hypot(df_sd, SIM_MODEL_FRACTION * df)
        dz_sd2 = np.hypot(dz_sd, SIM_MODEL_FRACTION * dz)
        sim_rows = _simulated(linearity, simulation, rows[:N_SIMULATED], f[keep], df, df_sd2, dz, dz_sd2)
        if sim_rows:
            rows, method = sim_rows, "simulated hits"
            slip = rows[0][4]
            # the global candidate judged with the same deviations
            global_chi2 = _fit(np.ones(df.size), df, df_sd2)[1] + _fit(z0, dz, dz_sd2)[1]
    chi2, best, a, b = rows[0][:4]
    runner = rows[1][0] if len(rows) > 1 else float("inf")
    present = bool(chi2 * MIN_LIKELIHOOD_RATIO <= global_chi2 and a != 0)
    close = [r[1].name for r in rows[1:] if r[0] < MIN_MARGIN * chi2]
    if a < 0:
        kind = "micro-slip friction" if b > 0 else "softening spring"
    else:
        kind = "hardening spring"
    lv = linearity.levels
    law = {"kind": kind, "stiffness_change_percent": 100.0 * a, "loss_factor_change": b, "slip_moment_nm": slip,
           "residual_stiffness_fraction": RESIDUAL_FRACTION if slip is not None else None,
           "stiffness_change_percent_per_decade": 100.0 * a / float(np.log10(lv[-1] / lv[0])),
           "levels": [float(lv[0]), float(lv[-1])]}
    joint = {"name": best.name, "kind": best.kind, "nodes": list(best.nodes), "axis": best.axis,
             "stiffness_nm_per_rad": float(best.stiffness_nm_per_rad)}
    if present:
        evidence = (f"{best.kind} {'-'.join(best.nodes)} ({best.axis}): its spring's stiffness changes by "
                    f"{100 * a:+.1f} % and its loss factor by {b:+.3g} from level {lv[0]:.3g} to {lv[-1]:.3g} "
                    f"({kind}); the modes' changes follow its strain-energy shares (chi2 {chi2:.3g}, next "
                    f"{rows[1][1].name if len(rows) > 1 else '-'} {runner:.3g}, every mode alike {global_chi2:.3g})"
                    + (f"; {', '.join(close)} fit(s) nearly as well" if close else ""))
    else:
        evidence = (f"the level dependence is not tied to one joint: best {best.name} chi2 {chi2:.3g}, next "
                    f"{runner:.3g}, every mode alike {global_chi2:.3g}")
    return {**base, "present": present, "evidence": evidence, "joint": joint, "law": law, "method": method,
            "ambiguous_with": close,
            "chi2": [{"candidate": r[1].name, "chi2": float(r[0])} for r in rows[:6]],
            "global_chi2": global_chi2, "global_change_percent": 100.0 * g_a, "modes_used": int(keep.sum())}


def _simulated(linearity: Any, simulation: Any, screened: list, f: np.ndarray, df: np.ndarray, df_sd2: np.ndarray,
               dz: np.ndarray, dz_sd2: np.ndarray) -> list:
    """Rows (chi2, candidate, a, b, slip moment) from the simulated level dependence of each screened
    candidate with an Iwan joint sized from its share fit, best first (deviations ``df_sd2``, ``dz_sd2``);
    [] when no simulation succeeds."""
    from ..linearity import compare_levels

    out = []
    for _, cand, a, b in screened:
        if not a < 0:
            continue
        # uniform micro-slip: secant loss (1 - rho) A / (2 theta_s) at rotation amplitude A; slip moment
        # (1 - rho) k0 theta_s / 2
        amp = simulation.peak_rotation(cand.name)
        theta_s = (1.0 - RESIDUAL_FRACTION) * amp / (2.0 * abs(a))
        slip = 0.5 * (1.0 - RESIDUAL_FRACTION) * cand.stiffness_nm_per_rad * theta_s
        try:
            sets = simulation.level_frfs(cand.name, slip)
            sim = compare_levels(sets, linearity.levels, band=linearity.band, poles=linearity.poles)
        except ValueError:
            continue
        sf = np.array([m.freq_hz for m in sim.modes])
        p_df = np.zeros(f.size)
        p_dz = np.zeros(f.size)
        for i, fr in enumerate(f):
            j = int(np.argmin(np.abs(sf - fr)))
            if abs(sf[j] / fr - 1.0) <= 0.02:
                p_df[i] = sim.modes[j].df_percent / 100.0
                p_dz[i] = sim.modes[j].zeta * sim.modes[j].dzeta_percent / 100.0
        if not np.any(p_df):
            continue
        c_f, chi_f = _fit(p_df, df, df_sd2)
        c_z, chi_z = _fit(p_dz, dz, dz_sd2) if np.any(p_dz) else (0.0, float(np.sum((dz / dz_sd2) ** 2)))
        # the predicted softening scales as 1 / slip moment (micro-slip): the slip moment that matches
        out.append((chi_f + chi_z, cand, a, b, slip / c_f if c_f > 0 else slip))
    out.sort(key=lambda r: r[0])
    return out


def level_shifts(linearity: Any) -> list[dict]:
    """Per level above the lowest, per mode: the frequency and damping change from the lowest level (%) with
    its standard deviation (the two levels' fits, as :func:`analysis.linearity.compare_levels` widens them),
    and ``determined`` (False: a mode the fits leave too uncertain to judge, its numbers meaningless).
    ``linearity`` is a :class:`analysis.linearity.LinearityResult`; modes in its order."""
    f, z = np.asarray(linearity.freq_hz, float), np.asarray(linearity.zeta, float)
    fs, zs = np.asarray(linearity.freq_hz_std, float), np.asarray(linearity.zeta_std, float)
    out = []
    for lv in range(1, f.shape[0]):
        modes = []
        for k in range(f.shape[1]):
            modes.append({"freq_hz": float(f[0, k]),
                          "df_percent": float(100.0 * (f[lv, k] - f[0, k]) / f[0, k]),
                          "df_std_percent": float(100.0 * np.hypot(fs[0, k], fs[lv, k]) / f[0, k]),
                          "dzeta_percent": float(100.0 * (z[lv, k] - z[0, k]) / z[0, k]) if z[0, k] else None,
                          "dzeta_std_percent": float(100.0 * np.hypot(zs[0, k], zs[lv, k]) / z[0, k])
                          if z[0, k] else None,
                          "determined": bool(linearity.modes[k].determined)})
        out.append({"level": float(linearity.levels[lv]), "modes": modes})
    return out


def amplitude_dependence(linearity: Any) -> dict:
    """The ``joint_nonlinearity`` cause from measurements at several drive levels without a simulation of
    the test (FRF files, each with its level): present when the level comparison says "nonlinear" (a mode's
    frequency or damping moves beyond its uncertainty, :func:`analysis.linearity.compare_levels`). Keys:
    ``effect``, ``present``, ``evidence`` (one sentence), ``law`` (``kind``: "micro-slip friction" when the
    moving modes soften and damp more, "softening spring", "hardening spring" or "amplitude-dependent
    damping"; ``levels``; the mean frequency change of the moving modes ``stiffness_change_percent`` (twice
    it: the modal stiffness), their damping change ``damping_change_percent``), ``modes`` (the moving modes:
    frequency, change and its sd, lowest to highest level) and ``per_level`` (:func:`level_shifts`). No
    joint is located (that needs a model of the joints: a simulator configuration and the test's hits)."""
    base = {"effect": "joint_nonlinearity", "present": False, "per_level": level_shifts(linearity)}
    lv = linearity.levels
    if linearity.verdict != "nonlinear":
        return {**base, "evidence": f"the modes do not change between the drive levels {lv[0]:.3g} and {lv[-1]:.3g} "
                                    "beyond their uncertainty: linear within the noise"}
    moving = [m for m in linearity.modes if m.significant]
    df = np.array([m.df_percent for m in moving])
    dz = np.array([m.dzeta_percent for m in moving], float)
    soft, damps = bool(np.mean(df) < 0), bool(np.nanmean(dz) > 0)
    moved_f = any(abs(m.df_percent) > Z_LEVELS * m.df_std_percent for m in moving)
    kind = ("micro-slip friction" if soft and damps else "softening spring" if soft else "hardening spring") \
        if moved_f else "amplitude-dependent damping"
    parts = [f"{m.freq_hz:.4g} Hz {m.df_percent:+.2f} % (+-{m.df_std_percent:.2f}), damping {m.dzeta_percent:+.0f} % "
             f"(+-{m.dzeta_std_percent:.0f})" for m in moving]
    evidence = (f"the modes move with the drive level ({lv[0]:.3g} -> {lv[-1]:.3g}) beyond their uncertainty: "
                + "; ".join(parts) + f": an amplitude-dependent stiffness and damping ({kind}, e.g. a bolted or "
                "clamped joint); the model is linear and compared at the lowest level")
    law = {"kind": kind, "levels": [float(v) for v in lv], "stiffness_change_percent": float(2.0 * np.mean(df)),
           "frequency_change_percent": float(np.mean(df)), "damping_change_percent": float(np.nanmean(dz))}
    return {**base, "present": True, "evidence": evidence, "law": law, "method": "drive levels",
            "modes": [m.to_dict() for m in moving]}


#: A moving mode's frequency change counts (for the law's kind) beyond this many standard deviations.
Z_LEVELS = 3.0


def named_levels(cause: dict) -> dict:
    """A present :func:`amplitude_dependence` cause as a named cause of the diagnosis: ``effect`` and
    ``parameters`` (the law's kind, the levels, and per moving mode its frequency and changes)."""
    law = cause["law"]
    params = {"kind": law["kind"], "levels": law["levels"],
              "freq_hz": [m["freq_hz"] for m in cause["modes"]],
              "df_percent": [m["df_percent"] for m in cause["modes"]],
              "dzeta_percent": [m["dzeta_percent"] for m in cause["modes"]]}
    return {"effect": "joint_nonlinearity", "parameters": params, "evidence": cause["evidence"]}


def measured_levels(sets: Sequence[FRFSet], levels: Sequence[float], band: tuple[float, float]) -> dict:
    """The level dependence of one structure measured at several drive ``levels`` (one FRF set each, any
    order; the data's unit: N, V...) in ``band`` (Hz): ``{"linearity": ..., "cause": amplitude_dependence}``
    (:func:`analysis.linearity.compare_levels`; raises its errors: LevelsDoNotPair when the sets are not one
    structure, FitError when no mode can be fitted)."""
    from ..linearity import compare_levels

    lin = compare_levels(list(sets), list(levels), band=band)
    return {"linearity": lin.to_dict(), "cause": amplitude_dependence(lin)}
