"""The test oracle of the diagnosis: for every row of its registries, how the simulator draws that effect
with random physical parameters and how closely the diagnosis must recover it.

Two tables keyed by the diagnosis' own registries, one row per effect:

* :data:`FRF_ORACLE`, keyed by the catalogue :data:`analysis.diagnosis.effects.EFFECTS`: the drawn range
  in words, the draw (``draw(rng, model, freq_hz, quantity) -> parameters`` for a base ``model`` analysed
  at ``freq_hz``), the tolerance of the primary parameter and its error (``error(injected, fitted)``,
  relative; ``inf`` for a wrong discrete choice). :func:`draw_effect` and :func:`primary_error` read it;
  ``DRAW_RANGES`` and ``TOLERANCES`` are its columns.
* :data:`TIME_ORACLE`, keyed by the time-data rows :data:`analysis.diagnosis.timedata.TIME_EFFECTS` (in the
  order the tests and the benchmark draw them): the same for hits (:func:`draw_time_effect`,
  :func:`time_primary_error`, ``TIME_DRAW_RANGES``, ``TIME_TOLERANCES``).

A row of a registry without its oracle row (or the reverse) fails ``tests/test_effect_oracle.py``.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from analysis.diagnosis.effects import EFFECTS, default_hum_width, hum_kernels, predict
from analysis.diagnosis.timedata import TIME_EFFECTS
from analysis.frf import line_spacing_hz
from analysis.modal import ModalModel

from .time_effects import _count

__all__ = ["OracleRow", "FRF_ORACLE", "TIME_ORACLE", "draw_effect", "primary_error", "DRAW_RANGES", "TOLERANCES",
           "draw_time_effect", "time_primary_error", "TIME_DRAW_RANGES", "TIME_TOLERANCES"]


@dataclass(frozen=True)
class OracleRow:
    """One effect's oracle: ``draws`` (the drawn range in words), ``draw`` (random physical parameters, without
    the ``"effect"`` key), ``tolerance`` (of the primary parameter's error) and ``error(injected, fitted)``."""

    draws: str
    draw: Callable[..., dict]
    tolerance: float
    error: Callable[..., float]


def _signed(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi) * (1 if rng.random() < 0.5 else -1))


def _rel(a: float, b: float) -> float:
    return abs(float(a) / float(b) - 1.0)


def _of(key: str) -> Callable[[Mapping, Mapping], float]:
    """The relative error of the parameter ``key``."""
    return lambda injected, fitted: _rel(fitted[key], injected[key])


@dataclass(frozen=True)
class _Band:
    """What a draw needs of the base model and the analysed band."""

    lo: float
    hi: float
    f: np.ndarray
    fn: np.ndarray
    inband: np.ndarray
    no: int
    nr: int
    labels: tuple

    @classmethod
    def of(cls, model: ModalModel, freq_hz: np.ndarray) -> _Band:
        f = np.asarray(freq_hz, float)
        fn = model.freq_hz
        no, nr = model.residues.shape[:2]
        return cls(lo=float(f[0]), hi=float(f[-1]), f=f, fn=fn, inband=np.sort(fn[(fn > f[0]) & (fn < f[-1])]),
                   no=no, nr=nr, labels=tuple(model.outputs) or tuple(f"n:{i + 1}:Z" for i in range(no)))

    def widest_gap(self, rng: np.random.Generator) -> tuple[float, float]:
        """A random frequency (Hz) in a wide gap between the in-band modes (the widest, randomly weighted)."""
        edges = np.concatenate([[self.lo], self.inband, [self.hi]])
        gaps = np.diff(edges)
        i = int(np.argmax(gaps * rng.uniform(0.5, 1.0, gaps.size)))
        return float(edges[i]), float(gaps[i])


def _stiffness(rng: np.random.Generator, b: _Band, model: ModalModel, quantity: str) -> dict:
    return {"factor": 1 + _signed(rng, 0.01, 0.07)}


def _damping(rng: np.random.Generator, b: _Band, model: ModalModel, quantity: str) -> dict:
    return {"factor": float(rng.uniform(0.4, 0.7) if rng.random() < 0.5 else rng.uniform(1.5, 3))}


def _window(rng: np.random.Generator, b: _Band, model: ModalModel, quantity: str) -> dict:
    f1 = b.inband[0] if b.inband.size else b.lo
    s = rng.uniform(0.003, 0.015) * 2 * np.pi * f1
    return {"exp_window_tau_s": float(1 / s)}


def _mass(rng: np.random.Generator, b: _Band, model: ModalModel, quantity: str) -> dict:
    return {"mass_kg": float(rng.uniform(0.05, 0.3))}


def _missing(rng: np.random.Generator, b: _Band, model: ModalModel, quantity: str) -> dict:
    start, gap = b.widest_gap(rng)
    fm = float(start + gap * rng.uniform(0.3, 0.7))
    zeta = float(rng.uniform(0.003, 0.02))
    wd = 2 * np.pi * fm * np.sqrt(1 - zeta ** 2)
    phi_o = rng.uniform(0.1, 0.4, b.no) * rng.choice([-1, 1], b.no)
    phi_r = rng.uniform(0.1, 0.4, b.nr) * rng.choice([-1, 1], b.nr)
    R = np.einsum("o,r->or", phi_o, phi_r) / (2j * wd)
    return {"freq_hz": fm, "zeta": zeta, "residue": np.stack([R.real, R.imag], -1).tolist()}


def _resonator(rng: np.random.Generator, b: _Band, model: ModalModel, quantity: str) -> dict:
    # a spring-mass at one output, its own frequency in the widest gap between modes
    start, gap = b.widest_gap(rng)
    return {"point": b.labels[int(rng.integers(b.no))], "mass_kg": float(rng.uniform(0.05, 0.3)),
            "frequency_hz": float(start + gap * rng.uniform(0.3, 0.7)), "zeta": float(rng.uniform(0.005, 0.03))}


def _residual(rng: np.random.Generator, b: _Band, model: ModalModel, quantity: str) -> dict:
    # the flexibility of the modes above 2 f_max (what a truncated model lacks), scaled
    above = b.fn > 2 * b.hi
    wn2 = (2 * np.pi * b.fn[above]) ** 2
    R = model.residues[..., above]
    wd = np.imag(model.poles[above])
    phi2 = np.real(R * 2j * wd)        # phi_o phi_r of each mode
    UR = np.sum(phi2 / wn2, axis=2) * rng.uniform(1.0, 3.0)
    return {"upper": UR.tolist(), "lower": np.zeros((b.no, b.nr)).tolist()}


def _highpass(rng: np.random.Generator, b: _Band, model: ModalModel, quantity: str) -> dict:
    return {"corner_hz": float(b.lo * rng.uniform(0.5, 3.0)), "order": int(rng.integers(1, 3))}


def _delay(rng: np.random.Generator, b: _Band, model: ModalModel, quantity: str) -> dict:
    return {"delay_s": _signed(rng, 0.02, 0.2) / b.hi}


def _sensitivity(rng: np.random.Generator, b: _Band, model: ModalModel, quantity: str) -> dict:
    o = int(rng.integers(b.no))
    return {"gains": {b.labels[o]: 1 + _signed(rng, 0.03, 0.15)}}


def _hum(rng: np.random.Generator, b: _Band, model: ModalModel, quantity: str) -> dict:
    base = float(rng.choice([50.0, 60.0]))
    width = default_hum_width(line_spacing_hz(b.f))
    fk, _ = hum_kernels(b.f, base, width)
    H = predict(model, b.f, quantity).H
    n_on = int(rng.integers(2, 5))
    A = np.zeros((b.no, b.nr, fk.size, 2))
    for k, fh in enumerate(fk[:n_on]):
        kk = int(np.argmin(np.abs(b.f - fh)))
        amp = np.abs(H[..., kk]) * rng.uniform(0.05, 0.2, (b.no, b.nr))
        ph = rng.uniform(0, 2 * np.pi, (b.no, b.nr))
        A[..., k, 0], A[..., k, 1] = amp * np.cos(ph), amp * np.sin(ph)
    return {"base_hz": base, "width_hz": width, "amplitudes": A.tolist()}


def _residual_error(injected: Mapping, fitted: Mapping) -> float:
    u, v = np.asarray(injected["upper"], float), np.asarray(fitted["upper"], float)
    return float(np.max(np.abs(v - u)) / np.max(np.abs(u)))


def _highpass_error(injected: Mapping, fitted: Mapping) -> float:
    if int(fitted["order"]) != int(injected["order"]):
        return float("inf")
    return _rel(fitted["corner_hz"], injected["corner_hz"])


def _sensitivity_error(injected: Mapping, fitted: Mapping) -> float:
    (label, g), = injected["gains"].items()
    return _rel(fitted["gains"][label], g)


def _hum_error(injected: Mapping, fitted: Mapping) -> float:
    return 0.0 if float(fitted["base_hz"]) == float(injected["base_hz"]) else float("inf")


_FRF_ROWS: dict[str, OracleRow] = {
    "stiffness_shift": OracleRow("factor in [0.93, 0.99] or [1.01, 1.07]", _stiffness, 0.001, _of("factor")),
    "damping_change": OracleRow("factor in [0.4, 0.7] or [1.5, 3]", _damping, 0.05, _of("factor")),
    "exponential_window": OracleRow("exp_window_tau_s: added damping 0.3..1.5 % at the first mode in band", _window,
                                    0.10, _of("exp_window_tau_s")),
    "mass_loading": OracleRow("mass_kg in [0.05, 0.3]", _mass, 0.05, _of("mass_kg")),
    "missing_mode": OracleRow("freq_hz between modes in the band, zeta 0.3..2 %, residue of a unit-ish mode shape",
                              _missing, 0.002, _of("freq_hz")),
    "local_resonator": OracleRow("frequency_hz between modes in the band, mass_kg in [0.05, 0.3] at one output, "
                                 "zeta 0.5..3 %", _resonator, 0.02, _of("frequency_hz")),
    "residual_modes": OracleRow("upper = 1..3 x the upper residual of the modes above 2 f_max", _residual, 0.25,
                                _residual_error),
    "sensor_highpass": OracleRow("corner_hz in [0.5, 3] x lowest line, order 1 or 2", _highpass, 0.05,
                                 _highpass_error),
    "time_delay": OracleRow("delay_s in +-[0.02, 0.2] / f_max", _delay, 0.02, _of("delay_s")),
    "sensitivity_error": OracleRow("one output's gain in [0.85, 0.97] or [1.03, 1.15]", _sensitivity, 0.01,
                                   _sensitivity_error),
    "mains_hum": OracleRow("base 50 or 60 Hz, 2..4 harmonics, amplitude 5..20 % of |H| there", _hum, 0.0,
                           _hum_error),
}

#: The FRF-level oracle, in the catalogue's order (a catalogue row without an oracle row has none here:
#: ``tests/test_effect_oracle.py`` fails).
FRF_ORACLE: dict[str, OracleRow] = {name: _FRF_ROWS[name] for name in EFFECTS if name in _FRF_ROWS}

#: The drawn ranges in words and the tolerances of the primary parameters (relative error), per effect.
DRAW_RANGES = {name: row.draws for name, row in FRF_ORACLE.items()}
TOLERANCES = {name: row.tolerance for name, row in FRF_ORACLE.items()}


def draw_effect(name: str, rng: np.random.Generator, model: ModalModel, freq_hz: np.ndarray,
                quantity: str = "accelerance") -> dict:
    """An effect ``{"effect": name, **params}`` with random physical parameters (``DRAW_RANGES``) for a base
    ``model`` analysed at ``freq_hz`` (Hz)."""
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r}; the catalogue has {', '.join(EFFECTS)}")
    if name not in FRF_ORACLE:
        raise ValueError(f"no random draw for effect {name!r}")
    return {"effect": name, **FRF_ORACLE[name].draw(rng, _Band.of(model, freq_hz), model, quantity)}


def primary_error(injected: Mapping, fitted: Mapping) -> float:
    """Relative error of an effect's primary parameter (``inf`` for a wrong discrete choice).

    residual_modes: max |UR_fit - UR| / max |UR|; sensor_highpass: corner (order must match);
    missing_mode: frequency; sensitivity_error: gain of the injected channel; mains_hum: base frequency;
    the others: their one parameter."""
    name = injected["effect"]
    if name not in FRF_ORACLE:
        raise ValueError(f"unknown effect {name!r}")
    return FRF_ORACLE[name].error(injected, fitted)


# --------------------------------------------------------------------------- time-data effects
def _fraction_error(injected: Mapping, fitted: Mapping, n_hits: int) -> float:
    return abs(round(float(fitted["fraction"]) * n_hits) - _count(injected["fraction"], n_hits)) / n_hits


def _fraction(rng: np.random.Generator, nominal_n: float) -> dict:
    return {"fraction": float(rng.uniform(0.25, 0.5))}


_TIME_ROWS: dict[str, OracleRow] = {
    "amplitude_nonlinearity": OracleRow("k_per_n in [6e-5, 2.5e-4] 1/N (0.5-2 % softening at 80 N)",
                                        lambda rng, nominal_n: {"k_per_n": float(rng.uniform(6e-5, 2.5e-4))}, 0.15,
                                        lambda i, f, n_hits: _rel(f["k_per_n"], i["k_per_n"])),
    "input_noise": OracleRow("noise_rms_n in [1, 4] % of the nominal peak force",
                             lambda rng, nominal_n: {"noise_rms_n": float(rng.uniform(0.01, 0.04) * nominal_n)}, 0.15,
                             lambda i, f, n_hits: _rel(f["noise_rms_n"], i["noise_rms_n"])),
    "double_hit": OracleRow("fraction in [0.25, 0.5] of the hits", _fraction, 0.0, _fraction_error),
    "overload": OracleRow("fraction in [0.25, 0.5] of the hits, struck 2-3 x harder, force clipped at 1.3 x the "
                          "normal peak", _fraction, 0.0, _fraction_error),
}

#: The time-data oracle, keyed by the diagnosis' time-data rows, in the order the tests and the benchmark
#: draw them (the rows' own order in the diagnosis is its detectors').
TIME_ORACLE: dict[str, OracleRow] = {name: row for name, row in _TIME_ROWS.items() if name in TIME_EFFECTS}

TIME_DRAW_RANGES = {name: row.draws for name, row in TIME_ORACLE.items()}
TIME_TOLERANCES = {name: row.tolerance for name, row in TIME_ORACLE.items()}


def draw_time_effect(name: str, rng: np.random.Generator, nominal_n: float = 100.0) -> dict:
    """A time-data effect with random physical parameters (``TIME_DRAW_RANGES``); ``nominal_n`` is the
    hammer's nominal peak force (N)."""
    if name not in TIME_ORACLE:
        raise ValueError(f"unknown time-data effect {name!r}; known: {', '.join(TIME_ORACLE)}")
    return {"effect": name, **TIME_ORACLE[name].draw(rng, nominal_n)}


def time_primary_error(injected: Mapping, fitted: Mapping, n_hits: int) -> float:
    """Error of the primary parameter: relative for ``k_per_n`` and ``noise_rms_n``; for double hits and
    overloads, the number of hits counted wrong (0 = exact) as a fraction of the hits."""
    name = injected["effect"]
    if name not in TIME_ORACLE:
        raise ValueError(f"unknown time-data effect {name!r}")
    return TIME_ORACLE[name].error(injected, fitted, n_hits)
