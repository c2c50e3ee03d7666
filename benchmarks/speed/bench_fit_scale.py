"""The whole automatic fit (``fit_auto``: band, stabilization, selection, LSFD, missing modes) at
scanning-vibrometer scale: time per step, peak memory, and the modes found against the truth.

The test: ``--outputs`` x ``--refs`` FRFs (default 1000 x 3 = 3000) x ``--lines`` lines (8000,
10..800 Hz) of an accelerance with ``--modes`` modes (40) at random frequencies at least 1 % apart
and damping 0.3..2 %, random real mode shapes with a little complexity, small residual terms,
and ``--noise`` (1 % of the RMS FRF level, circular complex Gaussian). Nothing is tuned to the
fitter: the frequencies, shapes and noise come from the seed.

The BLAS thread count is what a user gets (``analysis.threads``: chosen from the problem size and
the free cores) unless ``--threads N`` or ``IMPACTLAB_THREADS`` is given. Peak memory is the
process's maximum resident set (``resource.getrusage``) less the memory before the fit, and
includes the data set.

Run: ``.venv/bin/python benchmarks/speed/bench_fit_scale.py [--outputs 1000 --refs 3 --lines 8000 --modes 40]
[--threads N] [--profile]``
"""
from __future__ import annotations

import argparse
import logging
import resource
import sys
import time

import numpy as np

from analysis.frf import FRFSet
from analysis.modal import ModalModel, damping_ratio, natural_freq_hz, pole_from_fz, synthesize
from analysis.pipeline import fit_auto
from analysis.progress import PROGRESS_LOGGER
from analysis.threads import use_threads

TARGET_S = 10.0
TARGET_GB = 4.0


def scanning_model(n_out: int, n_ref: int, n_modes: int, seed: int) -> ModalModel:
    """The test's modal model (see the module docstring): poles, residues and residual terms from
    the seed."""
    rng = np.random.default_rng(seed)
    fn = np.sort(rng.uniform(30.0, 760.0, n_modes))
    for k in range(1, n_modes):  # modes at least 1 % apart
        fn[k] = max(fn[k], fn[k - 1] * 1.01)
    zeta = rng.uniform(0.003, 0.02, n_modes)
    lam = pole_from_fz(fn, zeta)
    psi = rng.normal(size=(n_out, n_modes)) * (1 + 0.05j * rng.normal(size=(n_out, n_modes)))
    L = rng.normal(size=(n_modes, n_ref))
    R = np.einsum("oj,jr->orj", psi, L) * (np.abs(lam) / 2j)[None, None, :]
    return ModalModel(lam, R, quantity="accelerance", residual_form="physical",
                      upper_residual=1e-7 * rng.normal(size=(n_out, n_ref)) * (1 + 0j),
                      lower_residual=2.0 * rng.normal(size=(n_out, n_ref)) * (1 + 0j))


def scanning_freq(n_lines: int) -> np.ndarray:
    """The test's lines (Hz): 10..800 Hz."""
    return np.linspace(10.0, 800.0, n_lines)


def add_noise(H: np.ndarray, sd: float | np.ndarray, rng: np.random.Generator) -> None:
    """Add circular complex Gaussian noise of standard deviation ``sd`` (a number, or one per
    output and reference) to ``H`` in place, 100 outputs at a time (no second copy of the data)."""
    sd_all = np.broadcast_to(np.asarray(sd, dtype=float), H.shape[:2])
    for i in range(0, H.shape[0], 100):
        part = H[i:i + 100]
        part += (sd_all[i:i + 100, :, None] / np.sqrt(2)) * (rng.standard_normal(part.shape)
                                                               + 1j * rng.standard_normal(part.shape))


def scanning_test(n_out: int, n_ref: int, n_lines: int, n_modes: int, noise: float, seed: int
                  ) -> tuple[FRFSet, np.ndarray, float]:
    """The FRFs, the true poles (rad/s) and the noise standard deviation."""
    model = scanning_model(n_out, n_ref, n_modes, seed)
    clean = synthesize(model, scanning_freq(n_lines))
    sd = noise * float(np.sqrt(np.mean(clean.H.real ** 2 + clean.H.imag ** 2)))
    H = np.array(clean.H)
    del clean
    add_noise(H, sd, np.random.default_rng(seed))
    return FRFSet(scanning_freq(n_lines), H, quantity="accelerance"), np.asarray(model.poles), sd


def _rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class _Steps(logging.Handler):
    """Wall time of each step of the fit, from its progress messages."""

    def __init__(self) -> None:
        super().__init__()
        self.marks: list[tuple[float, float, str]] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.marks.append((time.perf_counter(), time.process_time(), record.getMessage()))


def size_arguments(ap: argparse.ArgumentParser) -> None:
    """The test's size and seed on the command line (``--outputs --refs --lines --modes --seed``)."""
    ap.add_argument("--outputs", type=int, default=1000)
    ap.add_argument("--refs", type=int, default=3)
    ap.add_argument("--lines", type=int, default=8000)
    ap.add_argument("--modes", type=int, default=40)
    ap.add_argument("--seed", type=int, default=7, help="seed of the model")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    size_arguments(ap)
    ap.add_argument("--noise", type=float, default=0.01)
    ap.add_argument("--threads", type=int, default=None, help="BLAS threads (default: analysis.threads chooses)")
    ap.add_argument("--profile", action="store_true", help="print the 25 most expensive functions (cProfile)")
    a = ap.parse_args(argv)
    frf, lam, sd = scanning_test(a.outputs, a.refs, a.lines, a.modes, a.noise, a.seed)
    base = _rss_mib()
    print(f"problem: {a.outputs} x {a.refs} = {a.outputs * a.refs} FRFs x {a.lines} lines x {a.modes} modes, "
          f"noise {a.noise:.0%} of RMS; data {frf.H.nbytes / 2**30:.2f} GiB")
    steps = _Steps()
    plog = logging.getLogger(PROGRESS_LOGGER)
    plog.addHandler(steps)
    plog.setLevel(logging.INFO)
    plog.propagate = False
    prof = None
    if a.profile:
        import cProfile

        prof = cProfile.Profile()
        prof.enable()
    ru0 = resource.getrusage(resource.RUSAGE_SELF)
    t0, c0 = time.perf_counter(), time.process_time()
    with use_threads(a.threads):
        fit = fit_auto(frf)
    wall = time.perf_counter() - t0
    ru1 = resource.getrusage(resource.RUSAGE_SELF)
    cpu = ru1.ru_utime + ru1.ru_stime - ru0.ru_utime - ru0.ru_stime
    if prof is not None:
        import pstats

        prof.disable()
        pstats.Stats(prof).sort_stats("cumulative").print_stats(25)
    peak = _rss_mib()
    marks = [(t0, c0, "start")] + steps.marks + [(t0 + wall, c0 + cpu, "end")]
    print("     wall      CPU  step")
    for (ta, ca, what), (tb, cb, _) in zip(marks[1:-1], marks[2:]):
        print(f"  {tb - ta:7.2f} s {cb - ca:6.2f} s  {what}")
    f_true, z_true = np.sort(natural_freq_hz(lam)), damping_ratio(lam)[np.argsort(natural_freq_hz(lam))]
    f_fit = natural_freq_hz(fit.lsfd.poles)
    near = np.array([np.min(np.abs(f_fit - f)) / f for f in f_true]) if f_fit.size else np.ones(f_true.size)
    found = near < 0.002
    print(f"modes: {int(found.sum())} of {a.modes} found (within 0.2 %), {f_fit.size} fitted; status {fit.status}")
    if found.any():
        k = [int(np.argmin(np.abs(f_fit - f))) for f in f_true[found]]
        zerr = np.abs(damping_ratio(fit.lsfd.poles)[k] - z_true[found]) / z_true[found]
        print(f"  max |f error| {np.max(near[found]) * 100:.4f} %, max |zeta error| {np.max(zerr) * 100:.2f} %")
    gb = (peak - base) / 1024 + frf.H.nbytes / 2**30
    print(f"wall {wall:.1f} s (target < {TARGET_S:g} s; CPU {cpu:.1f} s), peak memory {peak / 1024:.2f} GiB resident "
          f"({gb:.2f} GiB for data and fit; target < {TARGET_GB:g} GB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
