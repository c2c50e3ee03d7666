"""The simulator with physical effects as configuration.

``simulate_with_effects(config, outputs, references, freq_hz, quantity, effects)`` gives the frame's
FRFs extended by a list ``[{"effect": name, **params}, ...]`` of the catalogue
:mod:`analysis.diagnosis.effects` (the same functions the diagnosis fits, so a fitted effect
re-simulates exactly) and ``add_frf_noise`` adds measurement noise to FRFs. The test oracle (an effect
drawn with random physical parameters, the tolerance of its recovery) is :mod:`simulator.effect_oracle`.

The base model is the frame's FE model (:class:`simulator.fem.FrameModel`) without sensor masses:
all its modes up to ``[modes] max_freq_hz`` as a receptance pole-residue model, with the
mass-normalised mode shapes at the outputs in ``meta["output_shapes"]`` (for ``mass_loading``).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from analysis.diagnosis.effects import predict
from analysis.frf import FRFSet
from analysis.modal import ModalModel

from .config import FrameConfig
from .fem import FrameModel

__all__ = ["base_model", "simulate_with_effects", "add_frf_noise"]


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
