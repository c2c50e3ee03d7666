"""The simulation side of the ``joint_nonlinearity`` cause: a measured test's hits re-simulated with a
friction joint at a candidate place.

:class:`JointHitSimulation` has the protocol :class:`analysis.diagnosis.joint_nonlinearity.JointSimulation`:
the frame's candidate rotational springs with their strain-energy shares (:class:`simulator.nonlinear_joint.JointModes`),
the linear frame's peak rotation of a candidate spring in the test's hardest hits, and the test's
FRFs per force level (one noise-free hit per struck point and level, H1) with an Iwan joint at a
candidate place. The test is described by its hits (points struck, outputs, sample rate, record
length, trigger) and its levels (peak force per level, N).
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from analysis.frf import FRFSet
from analysis.recording import merge_frfsets
from analysis.spectra import FRFAccumulator, WindowSettings, hit_spectra

from .config import FrameConfig
from .nonlinear_joint import JointModes, make_stand
from .response import simulate_response
from .stand import TestStand

__all__ = ["JointHitSimulation", "RESIDUAL_FRACTION"]

#: Share of the candidate spring's stiffness that never slips (the Iwan law of the simulated candidates).
RESIDUAL_FRACTION = 0.3


class JointHitSimulation:
    """A test re-simulated on the frame of ``config``: hits at ``points`` (labels), accelerometers at
    ``outputs``, ``levels`` (peak force N, ascending) sampled at ``fs_hz`` with ``n_samples`` samples and
    the trigger at ``trigger_index``; ``quantity`` and ``unit`` of the FRFs as measured."""

    def __init__(self, config: FrameConfig | str | Path | None, points: Sequence[str], outputs: Sequence[str],
                 levels: Sequence[float], fs_hz: float, n_samples: int, trigger_index: int = 64,
                 quantity: str = "accelerance", unit: str = "") -> None:
        cfg = config if isinstance(config, FrameConfig) else FrameConfig.load(config)
        self.config = cfg.with_overrides({"hammer": {"amplitude_scatter": 0.0, "width_scatter": 0.0,
                                                     "neighbour_probability": 0.0, "double_hit_probability": 0.0},
                                          "noise": {"enabled": False}, "nonlinear": {"law": "none"}})
        self.points = tuple(str(p) for p in points)
        self.outputs = tuple(str(o) for o in outputs)
        self.levels = tuple(sorted(float(v) for v in levels))
        self.fs_hz, self.n_samples, self.trigger_index = float(fs_hz), int(n_samples), int(trigger_index)
        self.quantity, self.unit = quantity, unit
        self._modes = JointModes(self.config, self.outputs)
        self._candidates = {c.name: c for c in self._modes.joint_candidates()[1]}
        lin = self._stand(self.config)
        lin.next_strike(amplitude_scale=1.0)
        self._peak_per_scale = float(np.max(np.abs(lin.strike(self.fs_hz, self.n_samples, self.trigger_index).force_n)))

    def _stand(self, cfg: FrameConfig) -> TestStand:
        stand = make_stand(cfg, 0)
        s = cfg.sensors
        chans = [{"point": self.points[0], "quantity": "force", "sensitivity": s.force.sensitivity_mv_per_n,
                  "sensitivity_unit": "mV/N", "iepe": False, "coupling": "DC"}]
        chans += [{"point": o, "quantity": "acceleration", "sensitivity": s.accelerometer.sensitivity_mv_per_g,
                   "sensitivity_unit": "mV/g", "iepe": False, "coupling": "DC"} for o in self.outputs]
        stand.set_channels(chans)
        return stand

    def joint_candidates(self) -> tuple[np.ndarray, list]:
        return self._modes.joint_candidates()

    def peak_rotation(self, candidate: str) -> float:
        """Peak rotation (rad) of the candidate spring in the linear frame over the hardest level's hits
        (a half-sine of the configured tip at that peak force)."""
        c = self._candidates[candidate]
        model = self._modes.model
        ms = model.modes()
        flex = ms.freq_hz > 0
        d = np.zeros(model.n_dof)
        ax = ("rx", "ry", "rz").index(c.axis)
        d[6 * model.node(c.nodes[0]) + 3 + ax] = 1.0
        if len(c.nodes) > 1:
            d[6 * model.node(c.nodes[1]) + 3 + ax] = -1.0
        delta = d @ ms.shapes[:, flex]
        fs = 16.0 * self.fs_hz
        w = self.config.hammer.width_s
        t = np.arange(int(np.ceil(w * fs)) + 1) / fs
        force = np.zeros(int(fs * min(self.n_samples / self.fs_hz, 1.0)))
        force[:t.size] = self.levels[-1] * np.sin(np.pi * np.clip(t / w, 0, 1))
        peak = 0.0
        for p in self.points:
            phi_in = model.shape_at([p], ms)[0, flex]
            th = simulate_response(force, fs, ms.poles[flex], delta[None, :], phi_in, "displacement")
            peak = max(peak, float(np.max(np.abs(th))))
        return peak

    def level_frfs(self, candidate: str, slip_moment_nm: float) -> list[FRFSet]:
        """H1 per level (ascending) with an Iwan joint (``slip_moment_nm`` N m in full slip,
        ``RESIDUAL_FRACTION`` never slips) at the candidate spring: one noise-free hit per point and level."""
        c = self._candidates[candidate]
        cfg = self.config.with_overrides({"nonlinear": {"law": "iwan", "joint": c.nodes[0], "axis": c.axis,
                                                        "slip_moment_nm": float(slip_moment_nm),
                                                        "residual_stiffness_fraction": RESIDUAL_FRACTION,
                                                        "stiffness_nm_per_rad": 0.0}})
        stand = self._stand(cfg)
        per_level: list[list[FRFSet]] = [[] for _ in self.levels]
        for p in self.points:
            stand.set_hammer_point(p)
            for k, lv in enumerate(self.levels):
                stand.next_strike(amplitude_scale=lv / self._peak_per_scale)
                ev = stand.strike(self.fs_hz, self.n_samples, self.trigger_index)
                acc = FRFAccumulator(self.outputs, p, self.quantity, self.unit)
                acc.add(hit_spectra(ev.force_n, ev.response[1:], self.fs_hz, self.trigger_index, WindowSettings()))
                per_level[k].append(acc.frfset("H1", sample_rate_hz=self.fs_hz))
        return [merge_frfsets(sets) for sets in per_level]
