"""Simulated roving-hammer tests for the quality checks: the stand's hits as H1 per struck point."""
from __future__ import annotations

import numpy as np

from analysis.frf import FRFSet
from analysis.recording import merge_frfsets
from analysis.spectra import FRFAccumulator, WindowSettings, hit_spectra
from simulator.sensors import G_M_S2
from simulator.stand import TestStand

SENSORS = ("left:9:Y", "top:2:Z", "right:6:-X")


def roving_test(stand: TestStand, points=SENSORS, sensors=SENSORS, n_hits: int = 4, fs_hz: float = 1024.0,
                n_samples: int = 4096, gain: dict[str, float] | None = None, seed: int = 0) -> FRFSet:
    """H1 at every struck point (sensors fixed; ``gain``: a sensor whose data are that factor off)."""
    s = stand.config.sensors
    chans = [{"point": points[0], "quantity": "force", "sensitivity": s.force.sensitivity_mv_per_n,
              "sensitivity_unit": "mV/N", "iepe": False, "coupling": "DC"}]
    chans += [{"point": p, "quantity": "acceleration", "sensitivity": 100.0, "sensitivity_unit": "mV/g",
               "iepe": False, "coupling": "DC"} for p in sensors]
    stand.set_channels(chans)
    rng = np.random.default_rng(seed)
    g = np.array([(gain or {}).get(p, 1.0) for p in sensors])
    sets = []
    for p in points:
        stand.set_hammer_point(p)
        acc = FRFAccumulator(sensors, p, "accelerance", "(m/s^2)/N")
        for _ in range(n_hits):
            stand.next_strike(double_hit=False, neighbour=False)
            ev = stand.strike(fs_hz, n_samples, 64, noise=False)
            f = ev.force_n + s.force.noise_density_n_per_rthz * np.sqrt(fs_hz / 2) * rng.standard_normal(n_samples)
            x = ev.response[1:] + (s.accelerometer.noise_density_g_per_rthz * G_M_S2 * np.sqrt(fs_hz / 2)
                                   * rng.standard_normal((len(sensors), n_samples)))
            acc.add(hit_spectra(f, g[:, None] * x, fs_hz, 64, WindowSettings()))
        sets.append(acc.frfset("H1", sample_rate_hz=fs_hz))
    return merge_frfsets(sets)


FRICTION_JOINT = {"law": "iwan", "joint": "right:10", "axis": "ry", "slip_moment_nm": 1.5,
                  "stiffness_nm_per_rad": 2e4}


def level_hits(config, seed: int, n_hits: int = 8, levels=(0.2, 4.0), fs_hz: float = 1024.0,
               n_samples: int = 4096, points=("right:6:-X",)):
    """Hits at each of ``points`` alternating between ``levels`` x the nominal force (20 and 400 N by
    default), made by the stand of ``config`` (linear or with its nonlinear joint), as :class:`LevelHit`
    (sensor noise added; the default test plan's accelerometers)."""
    from analysis.linearity import LevelHit
    from simulator.nonlinear_joint import make_stand

    stand = make_stand(config, seed)
    s = stand.config.sensors
    rng = np.random.default_rng([seed, 25])
    outputs = tuple(c.point for c in stand.channels[1:])
    hits = []
    for p in points:
        stand.set_hammer_point(p)
        for i in range(n_hits):
            stand.next_strike(double_hit=False, neighbour=False, amplitude_scale=float(levels[i % len(levels)]))
            ev = stand.strike(fs_hz, n_samples, 64, noise=False)
            f = ev.force_n + s.force.noise_density_n_per_rthz * np.sqrt(fs_hz / 2) * rng.standard_normal(n_samples)
            x = ev.response[1:] + (s.accelerometer.noise_density_g_per_rthz * G_M_S2 * np.sqrt(fs_hz / 2)
                                   * rng.standard_normal((len(outputs), n_samples)))
            hits.append(LevelHit(f, x, fs_hz, 64, p, outputs))
    return hits
