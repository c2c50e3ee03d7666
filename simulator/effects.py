"""The simulator with physical effects as configuration.

``simulate_with_effects(config, outputs, references, freq_hz, quantity, effects)`` gives the frame's
FRFs extended by a list ``[{"effect": name, **params}, ...]`` of the catalogue
:mod:`analysis.diagnosis.effects` (the same functions the diagnosis fits, so a fitted effect
re-simulates exactly). ``draw_effect`` draws an effect with random physical parameters (tests and
benchmark) and ``add_frf_noise`` adds measurement noise to FRFs.

The base model is the frame's FE model (:class:`simulator.fem.FrameModel`) without sensor masses:
all its modes up to ``[modes] max_freq_hz`` as a receptance pole-residue model, with the
mass-normalised mode shapes at the outputs in ``meta["output_shapes"]`` (for ``mass_loading``).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from analysis.diagnosis.effects import EFFECTS, default_hum_width, hum_kernels, predict
from analysis.frf import FRFSet
from analysis.modal import ModalModel

from .config import FrameConfig
from .fem import FrameModel

__all__ = ["base_model", "simulate_with_effects", "add_frf_noise", "draw_effect", "DRAW_RANGES", "TOLERANCES",
           "primary_error"]


def _config(config: FrameConfig | str | Path | None) -> FrameConfig:
    return config if isinstance(config, FrameConfig) else FrameConfig.load(config)


def base_model(
    config: FrameConfig | str | Path | None, outputs: Sequence[str], references: Sequence[str],
    *, max_freq_hz: float | None = None,
) -> ModalModel:
    """Receptance pole-residue model of the frame at the points, with ``meta["output_shapes"]``
    (n_out, n_modes) mass-normalised shapes (1/sqrt(kg)) at the outputs. ``max_freq_hz`` keeps only
    the modes up to that frequency (a truncated simulation, no residual terms)."""
    cfg = _config(config)
    fm = FrameModel.from_config(cfg)
    model = fm.modal_model(list(outputs), list(references), "receptance")
    ms = fm.modes()
    flex = ms.freq_hz > 0
    po = fm.shape_at(list(outputs), ms)[:, flex]
    keep = np.ones(model.poles.size, bool) if max_freq_hz is None else model.freq_hz <= max_freq_hz
    meta = dict(model.meta)
    meta["output_shapes"] = po[:, keep]
    return ModalModel(poles=model.poles[keep], residues=model.residues[..., keep], quantity="receptance",
                      residual_form="none", outputs=model.outputs, references=model.references, meta=meta)


def simulate_with_effects(
    config: FrameConfig | str | Path | ModalModel | None,
    outputs: Sequence[str],
    references: Sequence[str],
    freq_hz: np.ndarray,
    quantity: str = "accelerance",
    effects: Sequence[Mapping] = (),
) -> FRFSet:
    """FRFs (``quantity``) of the frame at ``freq_hz`` (Hz) extended by ``effects`` (applied in order).
    ``config`` may also be a ready :class:`ModalModel` (e.g. from :func:`base_model`)."""
    model = config if isinstance(config, ModalModel) else base_model(config, outputs, references)
    frf = predict(model, freq_hz, quantity, effects, outputs=outputs, references=references)
    meta = dict(frf.meta)
    meta["effects"] = [dict(e) for e in effects]
    return FRFSet(freq_hz=frf.freq_hz, H=frf.H, quantity=frf.quantity, outputs=frf.outputs,
                  references=frf.references, unit=frf.unit, meta=meta)


def add_frf_noise(frf: FRFSet, rng: np.random.Generator, relative: float = 0.01,
                  floor_fraction: float = 1e-3) -> FRFSet:
    """FRFs plus complex Gaussian noise: relative (``relative`` x |H|) plus a floor
    (``floor_fraction`` x median |H| of each FRF), the shape of H1 noise with a good coherence."""
    H = frf.H
    floor = floor_fraction * np.median(np.abs(H), axis=2, keepdims=True)
    sd = np.sqrt((relative * np.abs(H)) ** 2 + floor ** 2) / np.sqrt(2)
    n = rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)
    return FRFSet(freq_hz=frf.freq_hz, H=H + sd * n, quantity=frf.quantity, outputs=frf.outputs,
                  references=frf.references, unit=frf.unit, meta=dict(frf.meta, noise_relative=relative))


# Parameter ranges drawn by draw_effect (physical, and large enough to stand above 1 % noise).
DRAW_RANGES = {
    "stiffness_shift": "factor in [0.93, 0.99] or [1.01, 1.07]",
    "damping_change": "factor in [0.4, 0.7] or [1.5, 3]",
    "exponential_window": "exp_window_tau_s: added damping 0.3..1.5 % at the first mode in band",
    "mass_loading": "mass_kg in [0.05, 0.3]",
    "missing_mode": "freq_hz between modes in the band, zeta 0.3..2 %, residue of a unit-ish mode shape",
    "residual_modes": "upper = 0.3..1 x the upper residual of the modes above 2 f_max",
    "sensor_highpass": "corner_hz in [0.5, 3] x lowest line, order 1 or 2",
    "time_delay": "delay_s in +-[0.02, 0.2] / f_max",
    "sensitivity_error": "one output's gain in [0.85, 0.97] or [1.03, 1.15]",
    "mains_hum": "base 50 or 60 Hz, 2..4 harmonics, amplitude 5..20 % of |H| there",
}


def _signed(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi) * (1 if rng.random() < 0.5 else -1))


def draw_effect(name: str, rng: np.random.Generator, model: ModalModel, freq_hz: np.ndarray,
                quantity: str = "accelerance") -> dict:
    """An effect ``{"effect": name, **params}`` with random physical parameters (see ``DRAW_RANGES``)
    for a base ``model`` analysed at ``freq_hz`` (Hz)."""
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r}; the catalogue has {', '.join(EFFECTS)}")
    f = np.asarray(freq_hz, float)
    lo, hi = f[0], f[-1]
    fn = model.freq_hz
    inband = np.sort(fn[(fn > lo) & (fn < hi)])
    no, nr = model.residues.shape[:2]
    if name == "stiffness_shift":
        return {"effect": name, "factor": 1 + _signed(rng, 0.01, 0.07)}
    if name == "damping_change":
        return {"effect": name, "factor": float(rng.uniform(0.4, 0.7) if rng.random() < 0.5 else rng.uniform(1.5, 3))}
    if name == "exponential_window":
        f1 = inband[0] if inband.size else lo
        s = rng.uniform(0.003, 0.015) * 2 * np.pi * f1
        return {"effect": name, "exp_window_tau_s": float(1 / s)}
    if name == "mass_loading":
        return {"effect": name, "mass_kg": float(rng.uniform(0.05, 0.3))}
    if name == "missing_mode":
        edges = np.concatenate([[lo], inband, [hi]])
        gaps = np.diff(edges)
        i = int(np.argmax(gaps * rng.uniform(0.5, 1.0, gaps.size)))
        fm = float(edges[i] + gaps[i] * rng.uniform(0.3, 0.7))
        zeta = float(rng.uniform(0.003, 0.02))
        wd = 2 * np.pi * fm * np.sqrt(1 - zeta ** 2)
        phi_o = rng.uniform(0.1, 0.4, no) * rng.choice([-1, 1], no)
        phi_r = rng.uniform(0.1, 0.4, nr) * rng.choice([-1, 1], nr)
        R = np.einsum("o,r->or", phi_o, phi_r) / (2j * wd)
        return {"effect": name, "freq_hz": fm, "zeta": zeta, "residue": np.stack([R.real, R.imag], -1).tolist()}
    if name == "local_resonator":
        # a spring-mass at one output, its own frequency in the widest gap between modes
        edges = np.concatenate([[lo], inband, [hi]])
        gaps = np.diff(edges)
        i = int(np.argmax(gaps * rng.uniform(0.5, 1.0, gaps.size)))
        labels = model.outputs or tuple(f"n:{i + 1}:Z" for i in range(no))
        return {"effect": name, "point": labels[int(rng.integers(no))], "mass_kg": float(rng.uniform(0.05, 0.3)),
                "frequency_hz": float(edges[i] + gaps[i] * rng.uniform(0.3, 0.7)), "zeta": float(rng.uniform(0.005, 0.03))}
    if name == "residual_modes":
        # the flexibility of the modes above 2 f_max (what a truncated model lacks), scaled
        above = fn > 2 * hi
        wn2 = (2 * np.pi * fn[above]) ** 2
        R = model.residues[..., above]
        wd = np.imag(model.poles[above])
        phi2 = np.real(R * 2j * wd)        # phi_o phi_r of each mode
        UR = np.sum(phi2 / wn2, axis=2) * rng.uniform(1.0, 3.0)
        return {"effect": name, "upper": UR.tolist(), "lower": np.zeros((no, nr)).tolist()}
    if name == "sensor_highpass":
        return {"effect": name, "corner_hz": float(lo * rng.uniform(0.5, 3.0)), "order": int(rng.integers(1, 3))}
    if name == "time_delay":
        return {"effect": name, "delay_s": _signed(rng, 0.02, 0.2) / hi}
    if name == "sensitivity_error":
        o = int(rng.integers(no))
        labels = model.outputs or tuple(f"n:{i + 1}:Z" for i in range(no))
        return {"effect": name, "gains": {labels[o]: 1 + _signed(rng, 0.03, 0.15)}}
    if name == "mains_hum":
        base = float(rng.choice([50.0, 60.0]))
        nominal = predict(model, f, quantity)
        width = default_hum_width(nominal.line_spacing_hz)
        fk, _ = hum_kernels(f, base, width)
        H = nominal.H
        n_on = int(rng.integers(2, 5))
        A = np.zeros((no, nr, fk.size, 2))
        for k, fh in enumerate(fk[:n_on]):
            kk = int(np.argmin(np.abs(f - fh)))
            amp = np.abs(H[..., kk]) * rng.uniform(0.05, 0.2, (no, nr))
            ph = rng.uniform(0, 2 * np.pi, (no, nr))
            A[..., k, 0], A[..., k, 1] = amp * np.cos(ph), amp * np.sin(ph)
        return {"effect": name, "base_hz": base, "width_hz": width, "amplitudes": A.tolist()}
    raise ValueError(f"no random draw for effect {name!r}")


# Tolerances of the primary parameter (relative error, see primary_error) that tests and the benchmark use.
TOLERANCES = {
    "residual_modes": 0.25, "sensor_highpass": 0.05, "time_delay": 0.02, "mass_loading": 0.05,
    "missing_mode": 0.002, "local_resonator": 0.02, "stiffness_shift": 0.001, "damping_change": 0.05, "exponential_window": 0.10,
    "sensitivity_error": 0.01, "mains_hum": 0.0,
}


def primary_error(injected: Mapping, fitted: Mapping) -> float:
    """Relative error of an effect's primary parameter (``inf`` for a wrong discrete choice).

    residual_modes: max |UR_fit - UR| / max |UR|; sensor_highpass: corner (order must match);
    missing_mode: frequency; sensitivity_error: gain of the injected channel; mains_hum: base frequency;
    the others: their one parameter.
    """
    name = injected["effect"]

    def rel(a: float, b: float) -> float:
        return abs(float(a) / float(b) - 1.0)

    if name == "residual_modes":
        u, v = np.asarray(injected["upper"], float), np.asarray(fitted["upper"], float)
        return float(np.max(np.abs(v - u)) / np.max(np.abs(u)))
    if name == "sensor_highpass":
        return rel(fitted["corner_hz"], injected["corner_hz"]) if int(fitted["order"]) == int(injected["order"]) else float("inf")
    if name == "time_delay":
        return rel(fitted["delay_s"], injected["delay_s"])
    if name == "mass_loading":
        return rel(fitted["mass_kg"], injected["mass_kg"])
    if name == "missing_mode":
        return rel(fitted["freq_hz"], injected["freq_hz"])
    if name == "local_resonator":
        return rel(fitted["frequency_hz"], injected["frequency_hz"])
    if name in ("stiffness_shift", "damping_change"):
        return rel(fitted["factor"], injected["factor"])
    if name == "exponential_window":
        return rel(fitted["exp_window_tau_s"], injected["exp_window_tau_s"])
    if name == "sensitivity_error":
        (label, g), = injected["gains"].items()
        return rel(fitted["gains"][label], g)
    if name == "mains_hum":
        return 0.0 if float(fitted["base_hz"]) == float(injected["base_hz"]) else float("inf")
    raise ValueError(f"unknown effect {name!r}")
