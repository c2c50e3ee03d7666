"""An FRF-set generator that shares nothing with the diagnosis: a continuous Euler-Bernoulli beam.

The beam (pinned at both ends) is solved exactly per frequency line by the dynamic stiffness method:
each segment between points of interest has the closed-form dynamic stiffness of the beam equation
``EI w'''' = rho A omega^2 w`` (trigonometric and hyperbolic functions of ``beta x``,
``beta^4 = rho A omega^2 / EI``), so the FRFs hold every mode of the continuum (no modal truncation,
no pole-residue synthesis, no FE mesh). Damping is not modal: a hysteretic loss factor on the
modulus (``E (1 + j eta)``) plus a viscous dashpot to ground at one point. Sensors are point masses
on the beam; the hammer strikes one point (a driving point when a sensor sits there). A local
resonator (a spring-mass on the beam) is a mode the bare beam does not have.

The "simulation" file is the beam as designed (no change, no noise); the "measured" file is the
beam with the case's change and complex noise. Both are written as UFF 58 files with pyuff
directly (node numbers 1.., direction +Z).

The cases are drawn by a seeded generator, family by family (counts and ranges below, fixed before
the diagnosis was run on them); each case also draws its own beam (length, section, material), test
plan (3-5 sensors), damping, line count and noise level:

=================  =====  =========================================================================
family             cases  change made to the measured beam
=================  =====  =========================================================================
mass_one           12     one sensor (drawn among the outputs) heavier by 1-6 % of the beam's mass
mass_all           10     every sensor heavier by 0.5-3 % of the beam's mass each
stiffness          8      modulus x 0.85-0.95 or x 1.05-1.15
damping            8      loss factor and dashpot x 0.4-0.7 or x 1.5-3
extra_mode         6      a local resonator of 0.5-2 % of the beam's mass between two beam modes
null               15     none (other noise seeds, other beams)
mass_one_nodp      5      as mass_one, the hammer not at a sensor (no driving point)
mass_all_nodp      5      as mass_all, the hammer not at a sensor (no driving point)
=================  =====  =========================================================================

Right answer: ``mass_loading`` at that sensor (one sensor) or at every sensor, mass within 25 %;
``stiffness_shift`` with the stiffness factor within 2 %; ``damping_change`` with the factor within
15 %; ``missing_mode`` within 5 % of the resonator's own frequency; ``none`` for the nulls. Without a
driving point ``mass_loading`` cannot be named; right is a verdict other than ``mass_loading`` whose
message names the driving point to measure.

    .venv/bin/python benchmarks/accuracy/frf_beam_cases.py     # prints the case list
"""
from __future__ import annotations

import argparse
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

FAMILIES: tuple[tuple[str, int], ...] = (
    ("mass_one", 12), ("mass_all", 10), ("stiffness", 8), ("damping", 8), ("extra_mode", 6), ("null", 15),
    ("mass_one_nodp", 5), ("mass_all_nodp", 5),
)
SEED = 4242
MATERIALS = {"steel": (210e9, 7850.0), "aluminium": (70e9, 2700.0)}   # E (Pa), rho (kg/m^3)


@dataclass(frozen=True)
class Beam:
    """A pinned-pinned beam with point attachments (SI units). Positions are in m from the left pin."""

    length: float
    EI: float                     # N m^2
    rhoA: float                   # kg/m
    eta: float                    # hysteretic loss factor of the modulus
    dashpot_at: float             # m
    dashpot: float                # N s/m, to ground
    masses: tuple[tuple[float, float], ...] = ()            # (position m, kg): sensors, a bracket
    resonators: tuple[tuple[float, float, float, float], ...] = ()  # (position, kg, Hz, zeta)

    @property
    def mass(self) -> float:
        return self.rhoA * self.length


@dataclass
class Case:
    """One benchmark case: the beam as designed, the change, the test plan and the noise."""

    index: int
    family: str
    beam: Beam
    sensors: tuple[float, ...]      # positions (m) of the output sensors
    hammer: float                   # position (m) of the hammer
    sensor_kg: float                # each sensor's own mass (kg), in both files
    fmax_hz: float
    n_lines: int
    noise: float                    # relative complex noise per line
    seed: int
    change: dict = field(default_factory=dict)
    truth: dict = field(default_factory=dict)


def segment_stiffness(EI: complex, rhoA: float, omega: float | np.ndarray, length: float) -> np.ndarray:
    """Exact dynamic stiffness (4 x 4, complex; (n, 4, 4) for n angular frequencies ``omega``, rad/s) of a
    beam segment: end forces and moments ``[V0, M0, V1, M1]`` against end deflections and rotations
    ``[w0, t0, w1, t1]``, from the general solution ``w = a1 cos bx + a2 sin bx + a3 cosh bx + a4 sinh bx``."""
    om = np.atleast_1d(np.asarray(omega, float))
    bs = [(rhoA * w ** 2 / EI) ** 0.25 for w in om]     # b and its powers as scalars: the array power rounds otherwise
    b = np.array(bs, complex)
    b2, b3 = np.array([x ** 2 for x in bs], complex)[:, None], np.array([x ** 3 for x in bs], complex)[:, None]
    disp = np.zeros((om.size, 4, 4), complex)     # rows: w(0), w'(0), w(l), w'(l)
    force = np.zeros((om.size, 4, 4), complex)    # rows: shear and moment at both ends (nodal sign convention)
    for e, x in enumerate((0.0, length)):
        c, s, ch, sh = np.cos(b * x), np.sin(b * x), np.cosh(b * x), np.sinh(b * x)
        disp[:, 2 * e] = np.stack([c, s, ch, sh], axis=1)
        disp[:, 2 * e + 1] = b[:, None] * np.stack([-s, c, sh, ch], axis=1)
        w2 = b2 * np.stack([-c, -s, ch, sh], axis=1)
        w3 = b3 * np.stack([s, -c, sh, ch], axis=1)
        sign = 1.0 if e == 0 else -1.0
        force[:, 2 * e] = sign * EI * w3
        force[:, 2 * e + 1] = -sign * EI * w2
    K = force @ np.linalg.inv(disp)
    return K if np.ndim(omega) else K[0]


def beam_accelerance(beam: Beam, outputs: tuple[float, ...], hammer: float, freq_hz: np.ndarray) -> np.ndarray:
    """Accelerance (m/s^2)/N at ``outputs`` (positions) for a force at ``hammer``, (n_out, n_freq)."""
    pts = sorted({0.0, beam.length, beam.dashpot_at, hammer, *outputs, *(p for p, _ in beam.masses),
                  *(r[0] for r in beam.resonators)})
    idx = {p: i for i, p in enumerate(pts)}
    n = 2 * len(pts)
    keep = np.array([d for d in range(n) if d not in (0, 2 * (len(pts) - 1))])   # pinned: no deflection
    EI = beam.EI * (1 + 1j * beam.eta)
    omega = 2 * np.pi * np.asarray(freq_hz, float)
    segments = [segment_stiffness(EI, beam.rhoA, omega, b - a) for a, b in zip(pts[:-1], pts[1:])]
    H = np.zeros((len(outputs), freq_hz.size), complex)
    for k, f in enumerate(freq_hz):
        w = 2 * np.pi * f
        D = np.zeros((n, n), complex)
        for a, seg in zip(pts[:-1], segments):
            i = 2 * idx[a]
            D[i:i + 4, i:i + 4] += seg[k]
        for p, m in beam.masses:
            D[2 * idx[p], 2 * idx[p]] -= w ** 2 * m
        D[2 * idx[beam.dashpot_at], 2 * idx[beam.dashpot_at]] += 1j * w * beam.dashpot
        for p, m, fr, z in beam.resonators:
            ka = m * (2 * np.pi * fr) ** 2
            ca = 2 * z * np.sqrt(ka * m)
            kc = ka + 1j * w * ca
            D[2 * idx[p], 2 * idx[p]] += -w ** 2 * m * kc / (kc - w ** 2 * m)
        F = np.zeros(n, complex)
        F[2 * idx[hammer]] = 1.0
        x = np.linalg.solve(D[np.ix_(keep, keep)], F[keep])
        full = np.zeros(n, complex)
        full[keep] = x
        H[:, k] = -w ** 2 * full[[2 * idx[p] for p in outputs]]
    return H


def pinned_frequencies(beam: Beam, n: int) -> np.ndarray:
    """The bare beam's pinned-pinned natural frequencies (Hz), for choosing bands."""
    k = np.arange(1, n + 1)
    return k ** 2 * np.pi / (2 * beam.length ** 2) * np.sqrt(beam.EI / beam.rhoA)


def _positions(rng: np.random.Generator, L: float, n: int) -> list[float]:
    """``n`` distinct positions in (0.05 L, 0.95 L), at least 0.06 L apart, on a 1 mm grid."""
    while True:
        p = np.sort(np.round(rng.uniform(0.05 * L, 0.95 * L, n), 3))
        if n < 2 or np.min(np.diff(p)) >= 0.06 * L:
            return [float(x) for x in p]


def draw_case(index: int, family: str, rng: np.random.Generator) -> Case:
    """One case of ``family`` (module docstring) with everything drawn from ``rng``."""
    mat = str(rng.choice(list(MATERIALS)))
    E, rho = MATERIALS[mat]
    L = float(rng.uniform(0.9, 1.5))
    b, h = float(rng.uniform(0.03, 0.06)), float(rng.uniform(0.006, 0.012))
    n_out = int(rng.integers(3, 6))
    driving = not family.endswith("_nodp")
    pos = _positions(rng, L, n_out + (0 if driving else 1))
    if driving:
        sensors = tuple(pos)
        hammer = sensors[int(rng.integers(n_out))]
    else:
        j = int(rng.integers(len(pos)))
        hammer = pos.pop(j)
        sensors = tuple(pos)
    rhoA, EI = rho * b * h, E * b * h ** 3 / 12
    f1 = float(np.pi / (2 * L ** 2) * np.sqrt(EI / rhoA))
    M = rhoA * L
    z_c = float(rng.uniform(0.002, 0.015))
    beam = Beam(length=L, EI=EI, rhoA=rhoA, eta=float(rng.uniform(0.002, 0.01)),
                dashpot_at=float(np.round(rng.uniform(0.1 * L, 0.9 * L), 3)),
                dashpot=z_c * 2 * (2 * np.pi * f1) * M / 2,
                masses=((float(np.round(rng.uniform(0.1 * L, 0.9 * L), 3)), float(rng.uniform(0.02, 0.1)) * M),))
    sensor_kg = float(rng.uniform(0.002, 0.01)) * M
    case = Case(index=index, family=family, beam=beam, sensors=sensors, hammer=hammer, sensor_kg=sensor_kg,
                fmax_hz=float(f1 * rng.uniform(30.0, 60.0)), n_lines=int(rng.choice([800, 1600])),
                noise=float(rng.uniform(0.003, 0.015)), seed=int(rng.integers(1 << 30)))
    fam = family.removesuffix("_nodp")
    if fam == "mass_one":
        s = int(rng.integers(n_out))
        m = float(rng.uniform(0.01, 0.06)) * M
        case.change = {"sensor": s, "mass_kg": m}
        case.truth = {"effect": "mass_loading", "sensor": s, "mass_kg": m}
    elif fam == "mass_all":
        m = float(rng.uniform(0.005, 0.03)) * M
        case.change = {"mass_kg": m}
        case.truth = {"effect": "mass_loading", "mass_kg": m}
    elif fam == "stiffness":
        a = float(rng.uniform(0.85, 0.95) if rng.random() < 0.5 else rng.uniform(1.05, 1.15))
        case.change = {"modulus_factor": a}
        case.truth = {"effect": "stiffness_shift", "stiffness_factor": a}
    elif fam == "damping":
        c = float(rng.uniform(0.4, 0.7) if rng.random() < 0.5 else rng.uniform(1.5, 3.0))
        case.change = {"damping_factor": c}
        case.truth = {"effect": "damping_change", "factor": c}
    elif fam == "extra_mode":
        fb = pinned_frequencies(beam, 12)
        inband = fb[fb < 0.9 * case.fmax_hz]
        j = int(rng.integers(1, max(inband.size, 2)))
        fr = float(np.sqrt(fb[j - 1] * fb[j]) * rng.uniform(0.9, 1.1))
        case.change = {"resonator": (float(np.round(rng.uniform(0.1 * L, 0.9 * L), 3)),
                                     float(rng.uniform(0.005, 0.02)) * M, fr, float(rng.uniform(0.01, 0.03)))}
        case.truth = {"effect": "missing_mode", "freq_hz": fr}
    else:
        case.truth = {"effect": "none"}
    if not driving:
        case.truth = {"effect": "not mass_loading", "needs": "driving point"}
    return case


def draw_cases(seed: int = SEED, families: tuple[tuple[str, int], ...] = FAMILIES) -> list[Case]:
    """Every case, family by family; case i draws from ``default_rng([seed, i])``."""
    out: list[Case] = []
    for family, count in families:
        for _ in range(count):
            i = len(out)
            out.append(draw_case(i, family, np.random.default_rng([seed, i])))
    return out


def beams(case: Case) -> tuple[Beam, Beam]:
    """The beam as designed (the simulation) and as measured (with the change), sensors included."""
    from dataclasses import replace

    base = case.beam
    designed = replace(base, masses=base.masses + tuple((p, case.sensor_kg) for p in case.sensors))
    ch = case.change
    meas = designed
    if "sensor" in ch:
        meas = replace(meas, masses=meas.masses + ((case.sensors[ch["sensor"]], ch["mass_kg"]),))
    elif "mass_kg" in ch:
        meas = replace(meas, masses=meas.masses + tuple((p, ch["mass_kg"]) for p in case.sensors))
    if "modulus_factor" in ch:
        meas = replace(meas, EI=meas.EI * ch["modulus_factor"])
    if "damping_factor" in ch:
        meas = replace(meas, eta=meas.eta * ch["damping_factor"], dashpot=meas.dashpot * ch["damping_factor"])
    if "resonator" in ch:
        meas = replace(meas, resonators=(ch["resonator"],))
    return designed, meas


def node_numbers(case: Case) -> tuple[list[int], int]:
    """UFF node numbers: sensors 1..n along the beam, the hammer its sensor's node or n + 1."""
    outs = list(range(1, len(case.sensors) + 1))
    ham = outs[case.sensors.index(case.hammer)] if case.hammer in case.sensors else len(outs) + 1
    return outs, ham


def frfs(case: Case) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frequencies (Hz) and the simulated (noise-free) and measured (noisy) accelerances (n_out, n_freq)."""
    f = np.linspace(case.fmax_hz / case.n_lines, case.fmax_hz, case.n_lines)
    designed, meas = beams(case)
    Hs = beam_accelerance(designed, case.sensors, case.hammer, f)
    Hm = beam_accelerance(meas, case.sensors, case.hammer, f)
    rng = np.random.default_rng(case.seed)
    noise = (rng.standard_normal(Hm.shape) + 1j * rng.standard_normal(Hm.shape)) / np.sqrt(2)
    floor = 1e-3 * np.median(np.abs(Hm), axis=1, keepdims=True)
    Hm = Hm + noise * (case.noise * np.abs(Hm) + floor)
    return f, Hs, Hm


def write_uff(path: Path, case: Case, freq_hz: np.ndarray, H: np.ndarray, title: str) -> None:
    """Accelerances as UFF 58 (function type 4) with pyuff: response nodes 1.., reference node, +Z."""
    import pyuff

    outs, ham = node_numbers(case)
    sets = [pyuff.prepare_58(binary=1, func_type=4, rsp_node=n, rsp_dir=3, ref_node=ham, ref_dir=3,
                             data=np.asarray(H[i], complex), x=np.asarray(freq_hz, float), abscissa_spacing=1,
                             abscissa_spec_data_type=18, ordinate_spec_data_type=12, orddenom_spec_data_type=13,
                             abscissa_axis_units_lab="Hz", ordinate_axis_units_lab="m/s^2/N", id1=title,
                             id2="beam", id3="NONE", id4="NONE", id5="NONE")
            for i, n in enumerate(outs)]
    if path.exists():
        path.unlink()
    with warnings.catch_warnings():    # pyuff's writer leaves its last handle open: released when the call returns
        warnings.simplefilter("ignore", ResourceWarning)
        pyuff.UFF(str(path)).write_sets(sets, "add", force_double=True)


def write_case(case: Case, folder: Path) -> tuple[Path, Path]:
    """The case's simulation and measurement as UFF 58 files in ``folder``: (simulated, measured)."""
    f, Hs, Hm = frfs(case)
    folder.mkdir(parents=True, exist_ok=True)
    sim, meas = folder / f"case{case.index:03d}_sim.uff", folder / f"case{case.index:03d}_meas.uff"
    write_uff(sim, case, f, Hs, "simulation")
    write_uff(meas, case, f, Hm, "measurement")
    return sim, meas


def describe(case: Case) -> str:
    """One line: family, beam, plan and change."""
    ch = {k: (round(v, 4) if isinstance(v, float) else v) for k, v in case.change.items()}
    if "resonator" in ch:
        p, m, fr, z = case.change["resonator"]
        ch["resonator"] = f"at {p:.3f} m, {1000 * m:.1f} g, {fr:.1f} Hz, zeta {z:.3f}"
    return (f"{case.index:3d} {case.family:14s} L={case.beam.length:.2f} m M={case.beam.mass:.2f} kg "
            f"f1={pinned_frequencies(case.beam, 1)[0]:.1f} Hz fmax={case.fmax_hz:.0f} Hz lines={case.n_lines} "
            f"sensors={len(case.sensors)} noise={100 * case.noise:.2f} % change={ch}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=SEED)
    args = ap.parse_args()
    for c in draw_cases(args.seed):
        print(describe(c))


if __name__ == "__main__":
    main()
