"""Mains interference the catalogue formula does not make: single lines and leaked (sinc) lines at
50/60 Hz and off it. How often does the diagnosis name ``mains_hum`` with the right base and
frequency, and how often does it name anything on the same FRFs without the lines?

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/accuracy/bench_mains_variants.py [--seeds 4]

The measured FRFs are the blind tests' (tests/test_diagnosis_blind.py: 4 outputs of the simulated
frame, 2-200 Hz, 0.25 Hz lines, noise added); the lines are added here, per harmonic and FRF, with
amplitude ``a * |H(fk)|`` (``a`` uniform in ``--amplitude``, random phase):

- single: synchronous interference, on the one line nearest each harmonic ``k (base + offset)``;
- sinc: a steady tone off the line grid leaked by a rectangular window, ``sinc((f - fk) / 0.5 Hz)``
  (main lobe and side lobes; the catalogue's own lines are Lorentzians).

Prints a table per variant: cases, named ``mains_hum``, base right, frequency within 0.1 Hz, the
median held-out gain; and the null rate (the same FRFs without lines).
"""
from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository, for benchmarks.results
from benchmarks.results import add_write_option, recorded  # noqa: E402

#: this benchmark's results file (``--write`` replaces it with the run's figures)
RESULTS = Path(__file__).with_name("bench_mains_variants.md")

OUTS = ["left:9:Y", "top:4:X", "right:6:-X", "left:6:X"]
REFS = ["right:6:-X"]
F = np.arange(2.0, 200.0, 0.25)


def add_lines(m, base_hz: float, offset_hz: float, shape: str, amp: tuple[float, float], rng):
    f, H = m.freq_hz, m.H.copy()
    for k in range(1, int(f[-1] // base_hz) + 1):
        fk = k * (base_hz + offset_hz)
        i = int(np.argmin(np.abs(f - fk)))
        a = rng.uniform(*amp) * np.abs(H[..., i]) * np.exp(2j * np.pi * rng.uniform())
        if shape == "single":
            H[..., i] += a
        else:
            H += a[..., None] * np.sinc((f - fk) / 0.5)[None, None, :]
    return replace(m, H=H)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--amplitude", default="0.05,0.2", help="range of the lines' amplitude relative to |H| (default 0.05,0.2)")
    add_write_option(ap, RESULTS)
    args = ap.parse_args()
    with recorded(RESULTS, args.write):
        _run(args)


def _run(args: argparse.Namespace) -> None:
    """The run itself (what :func:`main` records with ``--write``)."""
    amp = tuple(float(x) for x in args.amplitude.split(","))

    from analysis.diagnosis import diagnose
    from simulator.effects import add_frf_noise, base_model, simulate_with_effects

    base = base_model(None, OUTS, REFS)
    clean = simulate_with_effects(base, OUTS, REFS, F, "accelerance", [])
    rows: dict[tuple, list] = {}
    nulls = []
    missed: list[str] = []
    for seed in range(args.seeds):
        m = add_frf_noise(clean, np.random.default_rng(5000 + seed))
        nulls.append(diagnose(m, base).verdict)
        for shape in ("single", "sinc"):
            for base_hz in (50.0, 60.0):
                for off in (0.0, 0.1, -0.15, 0.2):
                    rng = np.random.default_rng([seed, int(base_hz), int(1000 * off) % 997, shape == "sinc"])
                    d = diagnose(add_lines(m, base_hz, off, shape, amp, rng), base)
                    top = d.causes[0] if d.causes else {"parameters": {}, "gain_db": 0.0}
                    p = top["parameters"]
                    named = d.verdict == "mains_hum"
                    right_base = named and p.get("base_hz") == base_hz
                    right_f = right_base and abs(p["base_hz"] + p["offset_hz"] - base_hz - off) <= 0.1
                    rows.setdefault((shape, off), []).append((named, right_base, right_f, float(top["gain_db"])))
                    if not right_f:
                        hum = next((c for c in d.causes if c["effect"] == "mains_hum"), None)
                        missed.append(f"{shape} {base_hz:g}{off:+.2f} Hz seed {seed}: {d.verdict}; mains_hum "
                                      + ("not tried" if hum is None else
                                         f"gain {hum['gain_db']:.2f} dB z {hum['z']:.1f} at "
                                         f"{hum['parameters']['base_hz'] + hum['parameters']['offset_hz']:.3f} Hz "
                                         f"({hum['parameters']['shape']})"))
    print(f"mains lines made outside the catalogue; amplitude {amp[0]:g}-{amp[1]:g} x |H|, {args.seeds} seeds x 50/60 Hz\n")
    print("| lines | offset Hz | cases | named mains_hum | base right | frequency within 0.1 Hz | median gain dB |")
    print("|---|---|---|---|---|---|---|")
    tot = [0, 0]
    for (shape, off), r in rows.items():
        n = len(r)
        k = sum(x[2] for x in r)
        tot[0] += n
        tot[1] += k
        print(f"| {shape} | {off:+.2f} | {n} | {sum(x[0] for x in r)} | {sum(x[1] for x in r)} | {k} | "
              f"{np.median([x[3] for x in r]):.2f} |")
    print("\nnot named right:\n" + "\n".join(f"  {x}" for x in missed))
    print(f"\nall variants: {tot[1]}/{tot[0]} named right ({100 * tot[1] / tot[0]:.0f} %); "
          f"the same FRFs without lines: {sum(v == 'none' for v in nulls)}/{len(nulls)} 'none' ({', '.join(nulls)})")


if __name__ == "__main__":
    main()
