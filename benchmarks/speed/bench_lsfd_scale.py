"""Timing and peak memory of the nonlinear LSFD fit on a big problem.

300 FRFs (100 outputs x 3 references) x 8000 lines x 20 modes, accelerance, physical
residual terms, 1 % noise (of the RMS FRF level, circular complex Gaussian), Levenberg-Marquardt
from poles perturbed by 0.2 % in frequency and 10 % in damping. Only ``fit_lsfd`` is timed;
peak memory is traced by ``tracemalloc`` over the fit (numpy allocations are traced).

OpenBLAS runs single-threaded unless ``OPENBLAS_NUM_THREADS`` is set: on the shared 2-core
machine threaded BLAS under contention was 20x slower (8 s instead of 0.4 s).

Run: ``.venv/bin/python benchmarks/speed/bench_lsfd_scale.py [--outputs 100 --refs 3 --lines 8000 --modes 20]
[--method lm|gn] [--precise-only]``
"""
from __future__ import annotations

import argparse
import os
import resource
import sys
import time
import tracemalloc

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import analysis._lsfd_kernels as kernels  # noqa: E402
from analysis.frf import FRFSet  # noqa: E402
from analysis.lsfd import fit_lsfd  # noqa: E402
from analysis.modal import ModalModel, pole_from_fz, synthesize  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository, for benchmarks.results
from benchmarks.results import add_write_option, recorded  # noqa: E402

#: this benchmark's results file (``--write`` replaces it with the run's figures)
RESULTS = Path(__file__).with_name("bench_lsfd_scale.md")


def build(n_out: int, n_ref: int, n_lines: int, n_modes: int, noise: float, seed: int):
    rng = np.random.default_rng(seed)
    fn = np.sort(rng.uniform(20.0, 780.0, n_modes))
    for k in range(1, n_modes):  # keep modes at least 1 % apart
        fn[k] = max(fn[k], fn[k - 1] * 1.01)
    zeta = rng.uniform(0.003, 0.02, n_modes)
    lam = pole_from_fz(fn, zeta)
    psi = rng.normal(size=(n_out, n_modes))
    L = rng.normal(size=(n_modes, n_ref))
    R = np.einsum("or,rj->ojr", psi, L) * (1j * np.abs(lam))[None, None, :] * (1 + 0.1j * rng.normal(size=(1, 1, n_modes)))
    ur = 1e-7 * rng.normal(size=(n_out, n_ref)) * (1 + 0j)
    lr = 5e2 * rng.normal(size=(n_out, n_ref)) * (1 + 0j)
    model = ModalModel(lam, R, quantity="accelerance", residual_form="physical", upper_residual=ur, lower_residual=lr)
    f = np.linspace(10.0, 800.0, n_lines)
    clean = synthesize(model, f)
    rms = np.sqrt(np.mean(np.abs(clean.H) ** 2))
    sd = noise * rms
    H = clean.H + sd / np.sqrt(2) * (rng.normal(size=clean.H.shape) + 1j * rng.normal(size=clean.H.shape))
    frf = FRFSet(f, H, quantity="accelerance")
    p0 = pole_from_fz(fn * (1 + 0.002 * rng.choice([-1, 1], n_modes)), zeta * (1 + 0.1 * rng.choice([-1, 1], n_modes)))
    return frf, lam, p0, sd ** 2


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--outputs", type=int, default=100)
    ap.add_argument("--refs", type=int, default=3)
    ap.add_argument("--lines", type=int, default=8000)
    ap.add_argument("--modes", type=int, default=20)
    ap.add_argument("--noise", type=float, default=0.01)
    ap.add_argument("--method", default="lm")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--precise-only", action="store_true", help="disable the fast (Gram-based) evaluations")
    add_write_option(ap, RESULTS)
    a = ap.parse_args(argv)
    with recorded(RESULTS, a.write):
        return _run(a)


def _run(a: argparse.Namespace) -> int:
    """The run itself (what :func:`main` records with ``--write``)."""
    if a.precise_only:
        kernels.gram_form_pays = lambda *sizes, **kw: False   # the cost model never picks the Gram form
    frf, lam, p0, nv = build(a.outputs, a.refs, a.lines, a.modes, a.noise, seed=7)
    print(f"problem: {a.outputs * a.refs} FRFs x {a.lines} lines x {a.modes} modes, noise {a.noise:.0%} of RMS; "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}, "
          f"{'precise evaluations only' if a.precise_only else 'fast evaluations first'}")
    times = []
    for _k in range(a.repeat):
        t0 = time.perf_counter()
        res = fit_lsfd(frf, p0, method=a.method)
        times.append(time.perf_counter() - t0)
    tracemalloc.start()
    res = fit_lsfd(frf, p0, method=a.method)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    maxrss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    ferr = np.max(np.abs(res.freq_hz - np.abs(lam) / 2 / np.pi) / res.freq_hz_std)
    print(f"method {a.method}: status {res.status} ({res.message}), {res.iterations} iterations, {res.nfev} evaluations")
    print(f"wall time: best {min(times):.3f} s, median {np.median(times):.3f} s over {a.repeat} runs")
    print(f"peak traced memory during the fit: {peak / 2**20:.1f} MiB; process max RSS: {maxrss:.0f} MiB "
          f"(data set itself: {frf.H.nbytes / 2**20:.1f} MiB)")
    print(f"max |f - f_true| / f_std = {ferr:.2f}; noise_var estimate / true = {res.noise_var / nv:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
