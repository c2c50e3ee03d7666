"""Benchmark: impactlab's whole automatic fit against sdypy-EMA's LSCF + LSFD.

What is compared
----------------
Same synthetic data for both: 30 accelerance FRFs x 2000 lines (0.25..500 Hz), 8 modes in the
band 20..480 Hz (two of them 4 % apart) plus one mode below (10 Hz) and one above (700 Hz)
the band, additive complex noise at 1 % of the RMS level (the issue's Monte Carlo definition,
the default): 0.01 RMS(H_o) (n1 + j n2) / sqrt 2 on every line of FRF o;
``--noise proportional`` gives each line 0.01 |H| (n1 + j n2) / sqrt 2 instead.

* impactlab: ``analysis.pipeline.fit_auto`` = LSCF stabilization + automatic hint-free pole
  selection + nonlinear LSFD (Levenberg-Marquardt and Gauss-Newton), all in the timing.
* sdypy-EMA: ``Model.get_poles("lscf")`` + ``select_closest_poles(true frequencies)`` (it is
  *given* the true natural frequencies as hints, which favours it) + ``get_constants("lsfd")``
  (its LSFD is linear: the poles, hence damping, stay those of LSCF). Same band, same largest
  model order.

Then 300 FRFs (100 outputs x 3 references) x 8000 lines, 20 modes: wall time and peak memory of
the impactlab pipeline alone.

Errors are relative: |f - f_true| / f_true and |zeta - zeta_true| / zeta_true over the 8 modes.
Times are the best of ``--repeat`` runs, the libraries interleaved in every repeat so they share
the (shared, busy) machine's load; the time ratio is also given as the median of per-repeat ratios. BLAS runs single-threaded
(``OPENBLAS_NUM_THREADS=1`` etc. are set below before numpy loads, for both libraries):
on a loaded 2-core machine threaded BLAS is many times slower for these small matrices.

The sdypy venv (never a dependency of impactlab)
------------------------------------------------
    python3 -m venv ../peer-venv
    ../peer-venv/bin/pip install sdypy-EMA numpy scipy matplotlib
    ../peer-venv/bin/pip install -e .
    ../peer-venv/bin/python benchmarks/speed/bench_vs_sdypy.py

Without sdypy importable, the sdypy rows are skipped with a message and the rest still runs
(``.venv/bin/python benchmarks/speed/bench_vs_sdypy.py``).
"""
from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import io  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from analysis.frf import FRFSet  # noqa: E402
from analysis.modal import ModalModel, pole_from_fz, synthesize  # noqa: E402
from analysis.pipeline import fit_auto  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository, for benchmarks.results
from benchmarks.results import add_write_option, recorded  # noqa: E402

#: this benchmark's results file (``--write`` replaces it with the run's figures)
RESULTS = Path(__file__).with_name("bench_vs_sdypy.md")

F_IN = np.array([40.0, 75.0, 78.0, 130.0, 180.0, 240.0, 310.0, 390.0])
Z_IN = np.array([0.005, 0.007, 0.009, 0.011, 0.013, 0.015, 0.018, 0.02])
BAND = (20.0, 480.0)


NOISE_KIND = "additive"


def make_data(freqs, zetas, out_freqs, n_out, n_ref, n_lines, fmax, noise, seed):
    """Accelerance FRFs of a modal model (+ out-of-band modes) with complex noise: proportional
    (``noise * |H|`` per line) or additive (``noise * RMS of that FRF`` on every line), see NOISE_KIND."""
    rng = np.random.default_rng(seed)
    f_all = np.concatenate([freqs, out_freqs])
    z_all = np.concatenate([zetas, np.full(len(out_freqs), 0.02)])
    poles = pole_from_fz(f_all, z_all)
    phi = rng.standard_normal((n_out, f_all.size))
    part = 1.0 + 0.3 * rng.standard_normal((n_ref, f_all.size))
    R = phi[:, None, :] * part[None] * np.exp(0.05j * rng.standard_normal(f_all.size)) * poles.imag / 2j
    model = ModalModel(poles, R, quantity="accelerance", residual_form="none")
    f = np.arange(1, n_lines + 1) * (fmax / n_lines)
    H = synthesize(model, f).H
    n = (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)) / np.sqrt(2)
    if NOISE_KIND == "proportional":
        H = H + noise * np.abs(H) * n
    else:
        H = H + noise * np.sqrt(np.mean(np.abs(H) ** 2, axis=-1, keepdims=True)) * n
    return FRFSet(f, H, quantity="accelerance"), pole_from_fz(freqs, zetas)


def errors(f_est, z_est, f_true, z_true):
    """Relative errors of the estimate nearest each true mode (nan when fewer modes found)."""
    f_est, z_est = np.asarray(f_est, float), np.asarray(z_est, float)
    ef, ez = [], []
    for ft, zt in zip(f_true, z_true):
        if f_est.size == 0:
            ef.append(np.nan)
            ez.append(np.nan)
            continue
        k = int(np.argmin(np.abs(f_est - ft)))
        ef.append(abs(f_est[k] / ft - 1))
        ez.append(abs(z_est[k] / zt - 1))
    return np.array(ef), np.array(ez)


def best_time(fn, repeat):
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def run_impactlab(frf, method, max_modes):
    fit_st = fit_auto(frf, band=BAND, method=method, max_modes=max_modes)
    res, st = fit_st
    return res.freq_hz, res.damping, res


def run_sdypy(frf, max_modes, hints):
    import sdypy.EMA as EMA

    with warnings.catch_warnings(), contextlib.redirect_stderr(io.StringIO()):  # its progress bars
        warnings.simplefilter("ignore")
        m = EMA.Model(frf=frf.H.reshape(-1, frf.freq_hz.size), freq=frf.freq_hz, lower=BAND[0], upper=BAND[1],
                      pol_order_high=max_modes, frf_form="accelerance")
        m.get_poles("lscf", show_progress=False)
        m.select_closest_poles(list(hints), f_window=10)
        m.get_constants(method="lsfd", f_lower=BAND[0], f_upper=BAND[1])
    return np.asarray(m.nat_freq), np.asarray(m.nat_xi), m


def rms(x):
    return float(np.sqrt(np.nanmean(np.asarray(x) ** 2)))


def table(rows):
    head = (f"{'method':42s} {'time [s]':>9s} {'modes':>5s} {'f err med':>10s} {'f err max':>10s} "
            f"{'zeta err med':>12s} {'zeta err max':>12s} {'zeta err rms':>12s}")
    print(head)
    print("-" * len(head))
    for name, t, n, ef, ez in rows:
        print(f"{name:42s} {t:9.3f} {n:5d} {np.nanmedian(ef):10.2e} {np.nanmax(ef):10.2e} "
              f"{np.nanmedian(ez):12.2e} {np.nanmax(ez):12.2e} {rms(ez):12.2e}")


def part_zero(repeat):
    """Speed of the initial-pole kernels: 30 FRFs x 2000 lines, every order up to 60 (30 modes)."""
    from analysis.lsce import lsce_poles_all_orders
    from analysis.lscf import lscf_poles_all_orders
    from analysis.stabilization import stabilization

    frf, _ = make_data(F_IN, Z_IN, [10.0, 700.0], 30, 1, 2000, 500.0, 0.01, 0)
    print("\ninitial-pole kernels, 30 FRFs x 2000 lines, all model orders 1..30 modes (polynomial order 60)")
    for name, fn in (("lscf_poles_all_orders", lambda: lscf_poles_all_orders(frf, 30)),
                     ("lsce_poles_all_orders", lambda: lsce_poles_all_orders(frf, 30)),
                     ("stabilization lscf (with MAC)", lambda: stabilization(frf, 30, method="lscf")),
                     ("stabilization lsce (with MAC)", lambda: stabilization(frf, 30, method="lsce"))):
        t, _ = best_time(fn, repeat)
        print(f"  {name:32s} {t:7.3f} s")


def part_one(repeat, seed, max_modes):
    """One data set; the three runs are interleaved in every repeat so they share the machine's
    load, and each keeps its best time; ``ratio`` is also given as the median of per-repeat ratios."""
    frf, truth = make_data(F_IN, Z_IN, [10.0, 700.0], 30, 1, 2000, 500.0, 0.01, seed)
    print(f"\n30 FRFs x 2000 lines, 8 modes in {BAND[0]:g}..{BAND[1]:g} Hz + 2 outside, 1 % noise, seed {seed}, "
          f"largest model order {max_modes} modes")
    try:
        import sdypy.EMA  # noqa: F401
        have_sdypy = True
    except ImportError:
        have_sdypy = False
        print("sdypy-EMA is not importable here: its rows are skipped (see the module docstring to create "
              "../peer-venv)")
    runs = {
        "lm": lambda: run_impactlab(frf, "lm", max_modes),
        "gn": lambda: run_impactlab(frf, "gn", max_modes),
    }
    if have_sdypy:
        runs["sdypy"] = lambda: run_sdypy(frf, max_modes, F_IN)
    times = {k: [] for k in runs}
    outs = {}
    for _ in range(repeat):
        for k, fn in runs.items():
            t = time.perf_counter()
            outs[k] = fn()
            times[k].append(time.perf_counter() - t)
    rows = []
    names = {"lm": "impactlab fit_auto (LSCF+select+LSFD lm)", "gn": "impactlab fit_auto (LSCF+select+LSFD gn)",
             "sdypy": "sdypy-EMA LSCF+closest(hints)+LSFD"}
    errs = {}
    for k in runs:
        f, z, _ = outs[k]
        ef, ez = errors(f, z, F_IN, Z_IN)
        errs[k] = ez
        rows.append((names[k], min(times[k]), len(f), ef, ez))
    table(rows)
    if have_sdypy:
        for k in ("lm", "gn"):
            per = np.median(np.array(times[k]) / np.array(times["sdypy"]))
            print(f"  {k}: time ratio ours/sdypy = {min(times[k]) / min(times['sdypy']):.2f} best-to-best, "
                  f"{per:.2f} median of repeats (target <= 1.5); damping error ratio sdypy/ours: median "
                  f"{np.nanmedian(errs['sdypy']) / np.nanmedian(errs[k]):.1f}, max "
                  f"{np.nanmax(errs['sdypy']) / np.nanmax(errs[k]):.1f}, rms {rms(errs['sdypy']) / rms(errs[k]):.1f} "
                  "(target >= 10)")
    return rows


def part_two(repeat, seed):
    rng = np.random.default_rng(seed + 100)
    f20 = np.sort(np.concatenate([np.linspace(60.0, 1800.0, 18), [410.0, 1210.0]]))  # two close pairs
    f20 = f20 * (1 + 0.002 * rng.standard_normal(f20.size))
    z20 = np.linspace(0.004, 0.015, f20.size)
    frf, truth = make_data(f20, z20, [], 100, 3, 8000, 2000.0, 0.01, seed)
    band = (20.0, 2000.0)
    print("\n300 FRFs (100 outputs x 3 references) x 8000 lines, 20 modes, 1 % noise: impactlab pipeline")

    def run():
        fit_st = fit_auto(frf, band=band, method="lm")
        res, st = fit_st
        return res

    run()  # warm-up (imports, caches)
    t, res = best_time(run, repeat)
    tracemalloc.start()
    res = run()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    ef, ez = errors(res.freq_hz, res.damping, f20, z20)
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    data_mb = frf.H.nbytes / 2**20
    print(f"{'wall time [s]':28s} {t:8.3f}   (target < 1.5)")
    print(f"{'modes found':28s} {res.poles.size:8d}   (true 20)")
    print(f"{'f err median / max':28s} {np.nanmedian(ef):8.1e} / {np.nanmax(ef):.1e}")
    print(f"{'zeta err median / max':28s} {np.nanmedian(ez):8.1e} / {np.nanmax(ez):.1e}")
    print(f"{'peak traced memory [MB]':28s} {peak / 2**20:8.1f}   (numpy allocations during one fit; target < 1024)")
    print(f"{'process max RSS [MB]':28s} {rss_mb:8.1f}   (incl. interpreter, libraries, the {data_mb:.0f} MB of FRFs)")
    print(f"{'LSFD iterations / success':28s} {res.iterations:8d} / {res.success}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="timing repeats (best kept)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4], help="seeds of the 30-FRF data")
    ap.add_argument("--max-modes", type=int, default=24, help="largest model order (modes) for both libraries")
    ap.add_argument("--skip-large", action="store_true", help="skip the 300 x 8000 run")
    ap.add_argument("--noise", choices=("proportional", "additive"), default="additive",
                    help="noise model: 1 %% of each FRF's RMS on every line (default) or 1 %% of |H| per line")
    add_write_option(ap, RESULTS)
    args = ap.parse_args(argv)
    with recorded(RESULTS, args.write):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    """The run itself (what :func:`main` records with ``--write``)."""
    global NOISE_KIND
    NOISE_KIND = args.noise
    print(f"noise model: {NOISE_KIND}")
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, BLAS threads {os.environ['OPENBLAS_NUM_THREADS']}")
    part_zero(args.repeat)
    all_rows = []
    for s in args.seeds:
        all_rows.append(part_one(args.repeat, s, args.max_modes))
    if len(args.seeds) > 1:
        print(f"\nall {len(args.seeds)} seeds pooled ({8 * len(args.seeds)} modes):")
        pooled = {}
        for rows in all_rows:
            for name, t, n, ef, ez in rows:
                p = pooled.setdefault(name, [[], [], [], []])
                p[0].append(t)
                p[1].append(n)
                p[2].append(ef)
                p[3].append(ez)
        table([(name, float(np.median(v[0])), int(np.sum(v[1])), np.concatenate(v[2]), np.concatenate(v[3]))
               for name, v in pooled.items()])
    if not args.skip_large:
        part_two(args.repeat, 0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
