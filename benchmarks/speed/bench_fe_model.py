"""Time of ``diagnose`` on a user's FE model of 10^4 DOF with one cause (an added mass).

    nice -n 10 .venv/bin/python benchmarks/speed/bench_fe_model.py [--nx 40 --ny 84] [--map-every K] [--write]

The model: a rectangular net of nx x ny nodes with three translations each (3 nx ny DOF, 10080 by
default), springs between neighbours (out-of-plane Z soft, in-plane X, Y a hundred times stiffer, so
the band holds the Z modes), diagonal springs coupling X and Y, each edge node held by springs to
ground; lumped masses. Written as Matrix Market K.mtx, M.mtx, a DOF map and a model.toml in a temporary
folder. The "measured" FRFs: the model with 3 kg (2 % of its mass) added at one node, solved in full (every mode below
twice the band's top) and synthesised with hysteretic damping (not the modal damping the model
declares) plus 1 % noise, at 5 outputs and one reference, written as a UFF file. Timed: the command as a user
runs it, ``python -m analysis diagnose --measured measured.uff --simulated model.toml --effects added_mass``
(a new process, no BLAS thread variables: the command chooses its threads), as wall time and as the CPU time
of that process with its threads and children (on a shared machine the wall time also holds the other
programs' share; the load average is printed). Prints the figures; run by hand, nothing here is a test.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from benchmarks.results import add_write_option, recorded  # noqa: E402

#: this benchmark's results file (``--write`` replaces it with the run's figures)
RESULTS = Path(__file__).with_name("bench_fe_model.md")


def build(nx: int, ny: int) -> tuple:
    """K (N/m) and M (kg) of the net, and the node label of each DOF (``n:{node}:{X|Y|Z}``)."""
    import numpy as np
    import scipy.sparse as sp

    n_nodes = nx * ny
    node = np.arange(n_nodes).reshape(ny, nx)
    k_axis = {0: 2.0e8, 1: 2.0e8, 2: 2.0e6}            # N/m per spring, X, Y, Z
    rows, cols, vals = [], [], []

    def spring(a: np.ndarray, b: np.ndarray, axis: int, k: float) -> None:
        ia, ib = 3 * a + axis, 3 * b + axis
        rows.extend([ia, ib, ia, ib])
        cols.extend([ia, ib, ib, ia])
        vals.extend([np.full(a.size, k), np.full(a.size, k), np.full(a.size, -k), np.full(a.size, -k)])

    for axis, k in k_axis.items():
        spring(node[:, :-1].ravel(), node[:, 1:].ravel(), axis, k)
        spring(node[:-1, :].ravel(), node[1:, :].ravel(), axis, k)
    # diagonal braces: a spring along (1, 1) couples X and Y
    a, b = node[:-1, :-1].ravel(), node[1:, 1:].ravel()
    kd = 0.25e8
    for i, j, s in ((0, 0, 1), (1, 1, 1), (0, 1, 1), (1, 0, 1)):
        rows.extend([3 * a + i, 3 * b + i, 3 * a + i, 3 * b + i])
        cols.extend([3 * a + j, 3 * b + j, 3 * b + j, 3 * a + j])
        vals.extend([np.full(a.size, s * kd), np.full(a.size, s * kd), np.full(a.size, -s * kd), np.full(a.size, -s * kd)])
    edge = np.unique(np.concatenate([node[0], node[-1], node[:, 0], node[:, -1]]))
    for axis in range(3):
        rows.append(3 * edge + axis)
        cols.append(3 * edge + axis)
        vals.append(np.full(edge.size, 5.0e6))
    n = 3 * n_nodes
    K = sp.coo_matrix((np.concatenate([np.asarray(v, float).ravel() for v in vals]),
                       (np.concatenate([np.asarray(r).ravel() for r in rows]),
                        np.concatenate([np.asarray(c).ravel() for c in cols]))), shape=(n, n)).tocsr()
    M = sp.identity(n, format="csr") * 0.05
    labels = [f"n:{i + 1}:{'XYZ'[d]}" for i in range(n_nodes) for d in range(3)]
    return K, M, labels


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nx", type=int, default=40)
    ap.add_argument("--ny", type=int, default=84)
    ap.add_argument("--mass-kg", type=float, default=3.0, help="the added mass (kg; the model's is 168 kg)")
    ap.add_argument("--map-every", type=int, nargs="+", default=[1],
                    help="the DOF map lists every k-th node (and the measured ones): the added mass's candidates; "
                         "several: one run each and a table")
    ap.add_argument("--profile", metavar="OUT.prof",
                    help="run the command under cProfile, its profile to OUT.prof.K for --map-every K (the times then "
                         "include its cost)")
    add_write_option(ap, RESULTS)
    args = ap.parse_args()
    with recorded(RESULTS, args.write):
        rows = [_run(args, every) for every in args.map_every]
        print("\n| DOF map (candidate nodes) | named | truth | wall (load average) | CPU |\n|---|---|---|---|---|")
        for r in rows:
            print(r)


def _run(args: argparse.Namespace, every: int) -> str:
    """One run with every ``every``-th node mapped (what :func:`main` records with ``--write``): prints its
    figures and returns its row of the table."""
    import numpy as np
    import scipy.io
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from analysis.fe_model import sparse_modes
    from analysis.frf import FRFSet
    from analysis.uff import write_uff58

    K, M, labels = build(args.nx, args.ny)
    n = K.shape[0]
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        scipy.io.mmwrite(str(d / "K.mtx"), K.tocoo(), symmetry="symmetric")
        scipy.io.mmwrite(str(d / "M.mtx"), M.tocoo(), symmetry="symmetric")
        first = (args.ny // 3) * args.nx + args.nx // 4           # an interior node, a mapped one
        mass_node = 1 + first + (-first % every)
        outs = [f"n:{(args.ny * j // 6) * args.nx + args.nx * (j + 1) // 7 + 1}:Z" for j in range(1, 6)]
        keep = {int(o.split(":")[1]) for o in outs}
        mapped = [(i, lbl) for i, lbl in enumerate(labels)
                  if (int(lbl.split(":")[1]) - 1) % every == 0 or int(lbl.split(":")[1]) in keep]
        (d / "dofs.csv").write_text("dof,point\n" + "".join(f"{i},{lbl}\n" for i, lbl in mapped))
        n_mapped = len({lbl.rsplit(":", 1)[0] for _, lbl in mapped})
        (d / "model.toml").write_text('[fe]\nstiffness = "K.mtx"\nmass = "M.mtx"\ndofs = "dofs.csv"\n\n'
                                      "[damping]\nzeta_default = 0.01\n")
        # the measurement: a mass at one node, every mode to 2x the band's top, hysteretic damping, noise
        dm = np.zeros(n)
        dm[3 * (mass_node - 1):3 * mass_node] = args.mass_kg
        t0 = time.perf_counter()
        w2 = np.sort(spla.eigsh(K, k=10, M=M, sigma=0.0, which="LM")[0])
        f0 = np.sqrt(w2) / (2 * np.pi)
        band_top = float(0.5 * (f0[7] + f0[8]))         # eight modes in the band
        f_all, phi = sparse_modes(K, M + sp.diags(dm), 2 * band_top)
        t_truth = time.perf_counter() - t0
        ref = outs[-1]
        idx = {lbl: i for i, lbl in enumerate(labels)}
        freq = np.linspace(band_top / 400, band_top, 800)
        w = 2 * np.pi * freq[None, :]
        wn = 2 * np.pi * f_all[:, None]
        eta = 0.02
        po = phi[[idx[o] for o in outs]]
        pr = phi[idx[ref]]
        H = -(w ** 2) * np.einsum("om,m,mk->ok", po, pr, 1.0 / (wn ** 2 * (1 + 1j * eta) - w ** 2))
        rng = np.random.default_rng(7)
        H = H * (1 + 0.01 * (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)) / np.sqrt(2))
        measured = FRFSet(freq_hz=freq, H=H[:, None, :], quantity="accelerance", outputs=tuple(outs),
                          references=(ref,))
        uff = d / "measured.uff"
        write_uff58(uff, measured)
        with open(d / "model.toml", "a") as fh:
            fh.write(f"\n[modes]\nmax_freq_hz = {float(2 * band_top)!r}\n")
        prof = ["-m", "cProfile", "-o", str(Path(f"{args.profile}.{every}").resolve())] if args.profile else []
        cmd = [sys.executable, *prof, "-m", "analysis", "diagnose", "-q", "--measured", str(uff), "--simulated",
               str(d / "model.toml"), "--effects", "added_mass", "--band", f"{float(freq[2])!r}:{float(freq[-1])!r}",
               "--json", str(d / "diag.json")]
        env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS") and k != "IMPACTLAB_THREADS"}
        env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
        load = os.getloadavg()[0]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        run = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=str(ROOT))
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        if run.returncode != 0:
            raise SystemExit(f"diagnose failed (exit {run.returncode}): {run.stderr.strip()[-2000:]}")
        diag = json.loads((d / "diag.json").read_text())
    named = (diag.get("named") or [{}])[0]
    print(f"model: {n} DOF ({args.nx} x {args.ny} nodes x 3), {K.nnz} stiffness entries; band to {band_top:.1f} Hz "
          f"({int(np.sum(f0 <= band_top))} modes)")
    print(f"DOF map: {n_mapped} nodes (the added mass's candidates)")
    print(f"truth: {args.mass_kg} kg at n:{mass_node}; measured at {len(outs)} outputs, reference {ref} "
          f"(set-up {t_truth:.1f} s, not timed)")
    print(f"command: python -m analysis diagnose --measured measured.uff --simulated model.toml --effects added_mass "
          f"--band {freq[2]:.3f}:{freq[-1]:.3f} --json diag.json (no BLAS thread variables)")
    print(f"verdict: {diag.get('verdict')} {named.get('effect', '')} {named.get('parameters', {})}")
    print(f"time: {wall:.2f} s wall, {cpu:.2f} s CPU (the process, its threads and children: start, read, diagnose); "
          f"load average {load:.1f} at the start on {os.cpu_count()} cores\n")
    par = named.get("parameters", {})
    shown = f"`{named.get('effect')}` {par.get('point')}, {par.get('mass_kg', float('nan')):.3f} kg" if named else "none"
    return (f"| every {every} ({n_mapped}) | {shown} | n:{mass_node}, {args.mass_kg:g} kg | {wall:.1f} s "
            f"({load:.1f}) | {cpu:.1f} s |")

if __name__ == "__main__":
    main()
