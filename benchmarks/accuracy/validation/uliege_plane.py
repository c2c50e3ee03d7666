"""uliege_meca0062_plane_hammer: aircraft-like lab structure, 74 hammer points x 3 accelerometers.

Source: GitHub VictorRenkin/MECA0062-1_vibration_testing (commit a22f8821), University of Liege course
MECA0062 laboratory measurements. No licence in the source: internal validation only.

Data used: ``sec_lab_all_H1_coh_time.npz`` (all 79 second-lab DataPhysics exports packed; files 1-28,
31-58, 61-78 are the 74 impact points of ``node_shock.csv``), fs 512 Hz, 4096-sample blocks (8 s),
analyser H1 in g/N (converted here to (m/s^2)/N with g = 9.80665 m/s^2), and the last hit's raw and
analyser-windowed time blocks.

Exponential window
------------------
The analyser multiplied the responses (and the force) by ``w(t) = exp(-(t - t_0)/tau)`` from the block
start ``t_0``, decaying to 0.329 at the block end: ``tau = T / ln(1/0.329)`` with ``T = 8 s``, i.e.
7.2 s. :func:`window_tau` measures it from the stored raw/windowed blocks (``ln(w/x)`` is a straight
line of slope ``-1/tau``). The FRF set carries ``exp_window_tau_s = tau`` so the LSFD removes the
window's decay ``1/tau`` (rad/s) from every pole: the apparent extra damping is ``1/(tau omega_n)``,
0.15 % at 15 Hz.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from analysis.frf import FRFSet
from analysis.mac import mac
from analysis.modal import natural_freq_hz, synthesize
from analysis.spectra import FRFAccumulator, WindowSettings, hit_spectra

from .case import compare, peer_repeats, scatter_table
from .common import (
    CaseReport,
    consistency_table,
    data_model,
    fit_ours,
    fit_ours_from_poles,
    fmt,
    match_poles,
    md_table,
    synthesis_error,
)

NAME = "uliege_meca0062_plane_hammer"
SOURCE = ("GitHub VictorRenkin/MECA0062-1_vibration_testing (commit a22f8821), University of Liege MECA0062 "
          "laboratory measurements; no licence: internal validation only")
G = 9.80665
BAND = (15.0, 170.0)
DECAY_AT_END = 0.329
IMPACT_FILES = tuple(list(range(1, 29)) + list(range(31, 59)) + list(range(61, 79)))


def _npz(data_dir: Path):
    return np.load(Path(data_dir) / NAME / "sec_lab_all_H1_coh_time.npz")


def window_tau(data_dir: Path) -> dict:
    """Exponential-window time constant (s) measured from raw vs windowed blocks, and the force-window end (s)."""
    d = _npz(data_dir)
    t = d["t_s"]
    x = d["x_last_block"]
    w = d["w_last_block"].astype(float)
    taus = []
    for i in range(0, x.shape[0], 7):
        for c in (1, 2, 3):
            k = np.abs(x[i, c]) > 1e-3 * np.abs(x[i, c]).max()
            r = w[i, c][k] / x[i, c][k]
            ok = r > 0
            slope = np.polyfit(t[k][ok], np.log(r[ok]), 1)[0]
            taus.append(-1.0 / slope)
    r0 = w[:, 0] / np.where(np.abs(x[:, 0]) > 1e-12, x[:, 0], np.nan)
    k0 = int(np.argmin(np.abs(t)))
    ends = []
    for i in range(r0.shape[0]):
        z = np.flatnonzero(np.abs(r0[i, k0:]) < 1e-3)
        if z.size:
            ends.append(t[k0 + z[0]])
    T = t[-1] - t[0] + (t[1] - t[0])
    return {"exp_window_tau_s": float(np.median(taus)), "tau_spread_s": float(np.ptp(taus)), "block_s": float(T),
            "tau_nominal_s": float(T / math.log(1 / DECAY_AT_END)), "force_window_end_s": float(np.median(ends)),
            "t0_s": float(t[0]), "fs_hz": float(1.0 / (t[1] - t[0]))}


def load(data_dir: Path, band: tuple[float, float] | None = BAND, exp_window_tau_s: float = 7.2) -> FRFSet:
    """Analyser H1 of the 74 impact points: H[3 accelerometers, 74 hammer points, n], (m/s^2)/N."""
    d = _npz(data_dir)
    ids = list(d["file_id"])
    idx = [ids.index(k) for k in IMPACT_FILES]
    H = np.transpose(d["H1_g_per_N"][idx], (1, 0, 2)) * G
    C = np.transpose(d["coherence"][idx].astype(float), (1, 0, 2))
    f = d["freq_hz"]
    refs = tuple(f"plane:{k + 1}:{'Z' if k < 68 else 'X'}" for k in range(74))
    frf = FRFSet(freq_hz=f, H=H, quantity="accelerance", outputs=("acc:1:Z", "acc:2:Z", "acc:3:Z"),
                 references=refs, unit="(m/s^2)/N", coherence=np.clip(C, 0, 1), exp_window_tau_s=exp_window_tau_s,
                 meta={"source": SOURCE, "estimator": "analyser H1"})
    return frf.band(*band) if band else frf


def _mat_tau(m: dict) -> float:
    """Exponential-window tau (s) from a DataPhysics export's raw (X) and windowed (W) response blocks."""
    taus = []
    for c in (2, 3, 4):
        t, x = m[f"X{c}"][:, 0], m[f"X{c}"][:, 1]
        w = m[f"W{c}"][:, 1]
        k = (np.abs(x) > 1e-3 * np.abs(x).max()) & (w / np.where(x == 0, 1, x) > 0)
        taus.append(-1.0 / np.polyfit(t[k], np.log(w[k] / x[k]), 1)[0])
    return float(np.median(taus))


def first_lab(data_dir: Path) -> tuple[FRFSet, float]:
    """The first lab's analyser H1 (3 files x 3 accelerometers, 16 s blocks, df 0.0625 Hz), (m/s^2)/N,
    and the exponential-window tau (s) measured from its raw/windowed blocks."""
    import scipy.io

    Hs, Cs, taus = [], [], []
    for k in (1, 2, 3):
        m = scipy.io.loadmat(str(Path(data_dir) / NAME / "first_lab" / f"DPsv0000{k}.mat"))
        f = np.real(m["H1_2"][:, 0])
        Hs.append(np.stack([m[f"H1_{c}"][:, 1] for c in (2, 3, 4)]) * G)
        Cs.append(np.stack([np.real(m[f"C1_{c}"][:, 1]) for c in (2, 3, 4)]))
        taus.append(_mat_tau(m))
    tau = float(np.median(taus))
    frf = FRFSet(freq_hz=f, H=np.stack(Hs, axis=1), quantity="accelerance", outputs=("acc:1:Z", "acc:2:Z", "acc:3:Z"),
                 references=("lab1:1:Z", "lab1:2:Z", "lab1:3:Z"), unit="(m/s^2)/N",
                 coherence=np.clip(np.stack(Cs, axis=1), 0, 1), exp_window_tau_s=tau,
                 meta={"source": SOURCE + ", first_lab/DPsv0000{1,2,3}.mat"})
    return frf, tau


def importer_check(data_dir: Path) -> float:
    """Max |difference| between ``read_dataphysics_mat`` on ``sec_lab_original/DPsv00001.mat`` and the packed
    ``x_last_block`` of file 1, relative to the block's peak (0 when the packing and the importer agree)."""
    from acquisition.importers import read_dataphysics_mat

    t = read_dataphysics_mat(Path(data_dir) / NAME / "sec_lab_original" / "DPsv00001.mat")
    d = _npz(data_dir)
    x = d["x_last_block"][list(d["file_id"]).index(1)]
    return float(np.max(np.abs(t.hits[0] - x)) / np.max(np.abs(x)))


def raw_h1(data_dir: Path, exp_window_tau_s: float, force_end_s: float, band: tuple[float, float] | None = BAND) -> FRFSet:
    """H1 of the stored last hit of every impact point, by :mod:`analysis.spectra` with the analyser's windows.

    The windows start at the block start (the analyser's convention): force window up to
    ``force_end_s`` after the trigger, exponential ``exp_window_tau_s`` on force and responses.
    """
    d = _npz(data_dir)
    ids = list(d["file_id"])
    t = d["t_s"]
    fs = 1.0 / (t[1] - t[0])
    win = WindowSettings(force_width_s=force_end_s - t[0], force_taper_s=0.0, exp_window_tau_s=exp_window_tau_s, exp_on_force=True)
    blocks = d["x_last_block"]  # read once: every NpzFile item access re-reads the array
    Hs = []
    for k in IMPACT_FILES:
        x = blocks[ids.index(k)]
        acc = FRFAccumulator(("acc:1:Z", "acc:2:Z", "acc:3:Z"), "plane:0:Z", "accelerance", "(m/s^2)/N")
        acc.add(hit_spectra(x[0], x[1:] * G, fs, trigger_index=0, windows=win))
        fr = acc.frfset("H1")
        Hs.append(fr.H[:, 0])
    H = np.stack(Hs, axis=1)
    refs = tuple(f"plane:{k + 1}:{'Z' if k < 68 else 'X'}" for k in range(74))
    frf = FRFSet(freq_hz=fr.freq_hz, H=H, quantity="accelerance", outputs=("acc:1:Z", "acc:2:Z", "acc:3:Z"),
                 references=refs, unit="(m/s^2)/N", exp_window_tau_s=exp_window_tau_s, meta={"estimator": "impactlab H1, 1 hit"})
    return frf.band(*band) if band else frf


def per_reference_poles(frf: FRFSet, f_hz: float, zeta: float, half_width_hz: float = 3.0) -> np.ndarray:
    """One mode fitted alone on each hammer point's 3 FRFs (band f +- half_width): rows (f Hz, zeta, std f Hz).

    If the poles were truly global, the per-reference frequencies would scatter by about their own
    standard deviation; a larger scatter means the structure changed between the 74 measurements.
    """
    import warnings as _w

    from analysis.lsfd import LSFDConvergenceWarning, fit_lsfd
    from analysis.modal import pole_from_fz

    tau = frf.exp_window_tau_s or np.inf
    p0 = pole_from_fz([f_hz], [zeta]) - 1.0 / tau
    out = []
    for r in range(frf.n_references):
        one = frf.select(references=[frf.references[r]])
        with _w.catch_warnings():
            _w.simplefilter("ignore", LSFDConvergenceWarning)
            res = fit_lsfd(one, p0, band=(f_hz - half_width_hz, f_hz + half_width_hz))
        if res.success:
            out.append((res.freq_hz[0], res.damping[0], res.freq_hz_std[0]))
    return np.asarray(out)


def per_frf_errors(frf: FRFSet, result) -> tuple[float, float]:
    """Each FRF's own relative misfit ``e_o = ||H_o - G_o|| / ||H_o||`` over the fitted band (``G`` from
    ``poles_raw``, as the data were measured): returns (RMS over the FRFs of e_o, median of e_o), as
    fractions. Unlike the Frobenius synthesis error, a weak FRF counts as much as a strong one."""
    sub = frf.band(*result.band)
    H = sub.H.reshape(-1, sub.freq_hz.size)
    G = synthesize(data_model(result), sub.freq_hz).H.reshape(H.shape)
    e = np.sqrt(np.sum(np.abs(H - G) ** 2, axis=1) / np.sum(np.abs(H) ** 2, axis=1))
    return float(np.sqrt(np.mean(e ** 2))), float(np.median(e))


def subsets(frf: FRFSet) -> dict:
    """Independent subsets of the 222 FRFs: each accelerometer alone, three blocks of hammer points
    (measured one after the other) and the odd/even hammer points."""
    out = {f"acc {o + 1}": frf.select(outputs=[frf.outputs[o]]) for o in range(frf.n_outputs)}
    n = frf.n_references
    for name, idx in ((f"points 1-{n // 3}", range(0, n // 3)), (f"points {n // 3 + 1}-{2 * n // 3}", range(n // 3, 2 * n // 3)),
                      (f"points {2 * n // 3 + 1}-{n}", range(2 * n // 3, n)), ("odd points", range(0, n, 2)),
                      ("even points", range(1, n, 2))):
        out[name] = frf.select(references=[frf.references[k] for k in idx])
    return out


def close_pair_check(sets: dict, poles_raw: np.ndarray, pair_hz: tuple[float, float], margin_hz: float = 2.5,
                     auto: dict | None = None) -> tuple[list, dict]:
    """Is a close pair of global poles (one of them possibly added by the pipeline's misfit step) a pair of
    modes in every subset? For each subset: LSFD on ``pair - margin .. pair + margin`` Hz from the global
    poles there (and within 3 Hz of that band), with and without the lower pole of the pair; the pair's
    frequencies, damping, residue-norm ratio |R_low| / |R_high| and residue MAC, the local synthesis error
    without -> with the lower pole, and (``auto``: subset name -> its independent hint-free ``fit_auto``
    result) the automatic fit's poles within the band. Returns markdown rows and arrays (f_low, f_high,
    found_by_auto)."""
    from analysis.lsfd import fit_lsfd

    f_all = natural_freq_hz(poles_raw)
    i_lo = int(np.argmin(np.abs(f_all - pair_hz[0])))
    i_hi = int(np.argmin(np.abs(f_all - pair_hz[1])))
    band = (min(pair_hz) - margin_hz, max(pair_hz) + margin_hz)
    near = np.flatnonzero((f_all > band[0] - 3.0) & (f_all < band[1] + 3.0))
    without = near[near != i_lo]
    rows, f_lo, f_hi, n_auto = [], [], [], []
    for name, fr in sets.items():
        r2 = fit_lsfd(fr, poles_raw[near], band=band)
        r1 = fit_lsfd(fr, poles_raw[without], band=band)
        sub = fr.band(*band)
        e2 = synthesis_error(sub.H, synthesize(data_model(r2), sub.freq_hz).H)
        e1 = synthesis_error(sub.H, synthesize(data_model(r1), sub.freq_hz).H)
        a = int(np.flatnonzero(near == i_lo)[0])
        b = int(np.flatnonzero(near == i_hi)[0])
        R = r2.model.residues.reshape(-1, near.size)
        ra, rb = R[:, a], R[:, b]
        mac_ab = mac(ra, rb)
        f_lo.append(r2.freq_hz[a])
        f_hi.append(r2.freq_hz[b])
        found = "-"
        if auto is not None and name in auto:
            fa = np.sort(auto[name].freq_hz)
            fa = fa[(fa > band[0]) & (fa < band[1])]
            n_auto.append(fa.size)
            found = ", ".join(f"{x:.2f}" for x in fa) or "none"
        rows.append([name, f"{r2.freq_hz[a]:.3f} / {100 * r2.damping[a]:.3g}", f"{r2.freq_hz[b]:.3f} / {100 * r2.damping[b]:.3g}",
                     fmt(np.linalg.norm(ra) / np.linalg.norm(rb), 2), fmt(mac_ab, 2), f"{e1:.3g} -> {e2:.3g}", found])
    return rows, {"f_lo": np.array(f_lo), "f_hi": np.array(f_hi), "n_auto": np.array(n_auto), "band": band}


def _paired(ref_f: np.ndarray, f: np.ndarray, x: np.ndarray, target_hz: float) -> float:
    """Value ``x`` of the pole of ``f`` paired with the reference pole nearest ``target_hz`` (NaN if none)."""
    i0 = int(np.argmin(np.abs(ref_f - target_hz)))
    for i, j in match_poles(ref_f, f, 0.03):
        if i == i0 and j is not None:
            return float(x[j])
    return float("nan")


def run(data_dir: Path, out_dir: Path) -> CaseReport:
    wt = window_tau(data_dir)
    tau = wt["exp_window_tau_s"]
    frf = load(data_dir, band=None, exp_window_tau_s=tau)
    ours, peer, block, summary, plots = compare(NAME, frf, out_dir, band=BAND, plot_name=f"{NAME}.png", title=NAME)
    res = ours.result
    md = [
        "222 analyser H1 FRFs (3 accelerometers x 74 hammer points; 68 in z, 6 in x), 0..200 Hz, df 0.125 Hz, fitted "
        "together with global poles (multi-reference LSFD: one pole set for all 222 FRFs).",
        "",
        f"Exponential window measured from the stored raw and analyser-windowed blocks: tau = {tau:.4g} s "
        f"(spread {wt['tau_spread_s']:.2g} s over the blocks checked), the nominal T / ln(1/0.329) = "
        f"{wt['block_s']:.4g} / {math.log(1 / DECAY_AT_END):.4f} = {wt['tau_nominal_s']:.4g} s; the window starts at the "
        f"block start (t = {wt['t0_s']:.4g} s) and is applied to the force as well (force window ends at "
        f"t = {wt['force_window_end_s']:.4g} s). The FRF set carries `exp_window_tau_s = {tau:.4g}`, so the LSFD "
        f"removes 1/tau = {1 / tau:.4g} rad/s from every pole's decay rate (apparent damping 1/(tau omega_n): "
        f"{100 / (tau * 2 * np.pi * 15):.3g} % at 15 Hz, {100 / (tau * 2 * np.pi * 170):.3g} % at 170 Hz). The sdypy "
        "damping in the table was corrected the same way by us (sdypy has no window correction).",
        "",
        block,
    ]
    # the same automatic fit without the per-FRF weighting
    uw = fit_ours(frf, band=BAND, frf_weighting="none")
    w_rows, frf_err = [], {}
    for label, fit in (("1 / noise level (`frf_weighting=\"rms\"`, default)", ours),
                       ("none (`frf_weighting=\"none\"`)", uw)):
        rms_e, med_e = per_frf_errors(frf, fit.result)
        frf_err[id(fit)] = (rms_e, med_e)
        fs = np.sort(fit.result.freq_hz)
        w_rows.append([label, str(fs.size), f"{fit.synth_err_pct:.3g} %", fmt(rms_e, 2), fmt(med_e, 2),
                       f"{fit.time_s:.3g} s", ", ".join(f"{x:.2f}" for x in fs)])
    lost = [f for f in np.sort(res.freq_hz)
            if not any(i is not None and j is not None and res.freq_hz[i] == f
                       for i, j in match_poles(res.freq_hz, uw.result.freq_hz, 0.01))]
    md += [
        "",
        "FRF weighting: the default fit weights every FRF by 1 / its noise level (estimated from the analyser's "
        "coherence, `analysis.pipeline.rms_weights`), the unweighted fit minimises the plain "
        "Frobenius error. \"per-FRF error\" is each FRF's own relative misfit ||H_o - G_o|| / ||H_o||, summarised "
        "over the 222 FRFs (RMS and median): it counts a weak FRF as much as a strong one, where the Frobenius "
        "synthesis error is dominated by the few strongest FRFs.",
        "",
        md_table(["FRF weighting", "modes", "synthesis error (Frobenius)", "per-FRF error, RMS", "per-FRF error, median",
                  "time", "natural frequencies [Hz]"], w_rows),
        "",
        f"Modes of the weighted fit the unweighted one does not have (within 1 %): "
        f"{', '.join(f'{x:.2f}' for x in lost) or 'none'} Hz."
        + (f" Unweighted fit notes: {'; '.join(uw.warnings)}" if uw.warnings else ""),
    ]
    # consistency across the three accelerometers (each fitted alone from the global poles)
    labels, per = [], []
    for o in range(3):
        one = frf.select(outputs=[frf.outputs[o]])
        fo = fit_ours_from_poles(one, res.poles_raw, ours.band)
        labels.append(f"acc {o + 1}")
        per.append(fo.result)
    raw = raw_h1(data_dir, tau, wt["force_window_end_s"], band=None)
    fr = fit_ours_from_poles(raw, res.poles_raw, ours.band)
    labels.append("raw last hit, impactlab H1")
    per.append(fr.result)
    tab, arr = consistency_table(labels, per, res.freq_hz)
    sets = [frf.select(outputs=[frf.outputs[o]]) for o in range(3)] + [raw]
    pf, pz = (peer_repeats(sets, ours.band, max(ours.stab.orders), res.freq_hz) if peer.ok else (None, None))
    stab_tab = scatter_table(res.freq_hz, arr, pf, pz)
    # analyser H1 vs our H1 of the last hit, where the analyser's coherence is high
    A = frf.band(*ours.band)
    Bq = raw.band(*ours.band)
    good = A.coherence > 0.98
    rel = np.abs(Bq.H - A.H) / np.abs(A.H)
    md += [
        "",
        "Consistency between references: each accelerometer's 74 FRFs fitted alone (LSFD from the global poles), and "
        "the FRFs impactlab estimates from the stored raw time blocks (one hit per point, same windows as the "
        "analyser, `analysis.spectra`) fitted the same way:",
        "",
        tab,
        "",
        "Scatter over the four sets (3 accelerometers, raw-hit FRFs), impactlab vs sdypy-EMA (same hints):",
        "",
        stab_tab,
        "",
        f"Analyser H1 (average of several hits) vs impactlab H1 of the last stored hit: median |difference| / |H| = "
        f"{100 * np.median(rel[good]):.3g} % over the {int(good.sum())} lines with analyser coherence > 0.98 "
        f"({100 * np.median(rel):.3g} % over all lines). Synthesis error of the global model against the raw-hit FRFs: "
        f"{synthesis_error(Bq.H, synthesize(data_model(res), Bq.freq_hz).H):.3g} %.",
    ]
    # is the pole global? one mode at a time, per hammer point
    rows, per_point = [], {}
    for i in np.argsort(res.freq_hz):
        f0, z0 = float(res.freq_hz[i]), float(res.damping[i])
        others = np.delete(np.arange(res.freq_hz.size), i)
        near = np.abs(res.freq_hz[others] - f0) < 3.0
        if z0 > 0.01 or np.any(near & (res.damping[others] < 0.01)):
            continue  # too damped, or another light mode within the +-3 Hz band: one pole cannot fit it
        pr = per_reference_poles(frf, f0, z0)
        if pr.shape[0] < 10:
            continue
        q75, q25 = np.percentile(pr[:, 0], [75, 25])
        per_point[round(f0)] = {"scatter": (q75 - q25) / 1.349, "claimed": float(np.median(pr[:, 2])),
                                "global": float(res.freq_hz_std[i]), "zeta_median": float(np.median(pr[:, 1]))}
        rows.append([fmt(f0, 6), fmt(100 * z0, 3), str(pr.shape[0]), fmt(np.median(pr[:, 0]), 6),
                     fmt(100 * np.median(pr[:, 1]), 3), fmt((q75 - q25) / 1.349, 2), fmt(np.median(pr[:, 2]), 2),
                     fmt(res.freq_hz_std[i], 2)])
    sub = frf.band(*ours.band)
    err_struct = synthesis_error(sub.H, synthesize(res.model, sub.freq_hz).H)
    md += [
        "",
        "Are the poles global? Each lightly damped mode fitted alone (one pole, band f +- 3 Hz) on every hammer "
        "point's 3 FRFs: the robust scatter (IQR / 1.349) of those 74 frequencies against the standard deviation "
        "each single fit claims, and the standard deviation the global fit claims (modes with another lightly damped "
        "mode within 3 Hz are left out):",
        "",
        md_table(["f global [Hz]", "zeta [%]", "points fitted", "median f [Hz]", "median zeta [%]", "scatter f [Hz]",
                  "median per-point std f [Hz]", "global-fit std f [Hz]"], rows),
        "",
        f"Synthesis error of the reported (window-corrected) model against the windowed data: {err_struct:.3g} % "
        f"(against {ours.synth_err_pct:.3g} % for the model with the window's decay kept, `poles_raw`): a plot or "
        "export that overlays `result.model` on exponentially windowed FRFs compares two different things.",
    ]
    # the first lab (another day, 16 s blocks, its own window), fitted from the second lab's poles
    lab1, tau1 = first_lab(data_dir)
    r1 = fit_ours_from_poles(lab1, res.poles - 1.0 / tau1, ours.band)
    tab1, _ = consistency_table(["second lab (74 points)", "first lab (3 files)"], [res, r1.result], res.freq_hz)
    md += [
        "",
        f"Across labs: the first lab's analyser H1 (`first_lab/DPsv0000{{1,2,3}}.mat`, 16 s blocks, df 0.0625 Hz, "
        f"exponential window measured tau = {tau1:.4g} s = 16 s / ln(1/0.329) = {16 / math.log(1 / DECAY_AT_END):.4g} s) "
        f"fitted by LSFD from the second lab's poles (synthesis error {r1.synth_err_pct:.3g} %):",
        "",
        tab1,
        "",
        f"Importer check: `acquisition.importers.read_dataphysics_mat` on `sec_lab_original/DPsv00001.mat` reproduces "
        f"the packed raw block of file 1 to {importer_check(data_dir):.2g} of its peak.",
    ]
    # the close pairs the misfit step completed: are they in every subset of the data?
    sets = subsets(frf.band(BAND[0] - 5.0, BAND[1] + 5.0))
    auto = {name: fit_ours(fr, band=BAND).result for name, fr in sets.items()}
    added = [w for w in ours.warnings if w.startswith("added a pole")]
    pair_figs = {}
    fsorted = np.sort(res.freq_hz)
    close = [(a, b) for a, b in zip(fsorted[:-1], fsorted[1:]) if b - a < 1.0]
    md += ["", "Close pairs: the global fit has " + (", ".join(f"{a:.2f} / {b:.2f} Hz" for a, b in close) or "none")
           + ". The misfit step: " + ("; ".join(added) if added else "added no pole") + ". Is each pair two modes in "
           "every independent part of the data? Each subset fitted by LSFD in the pair's band from the global poles "
           "(with and without the lower pole of the pair), and fitted again independently, hint-free, by `fit_auto` "
           "(its poles in the band in the last column):"]
    for k, (a, b) in enumerate(close):
        prow, parr = close_pair_check(sets, res.poles_raw, (a, b), auto=auto)
        md += ["", md_table(["subset", "lower pole f [Hz] / zeta [%]", "upper pole f [Hz] / zeta [%]",
                             "abs(R low) / abs(R high)", "residue MAC", "local synthesis error, 1 -> 2 poles [%]",
                             f"independent automatic fit, poles in {parr['band'][0]:.4g}..{parr['band'][1]:.4g} Hz"], prow)]
        pair_figs[k] = {"lo": a, "hi": b, "lo_min": float(parr["f_lo"].min()), "lo_max": float(parr["f_lo"].max()),
                        "hi_min": float(parr["f_hi"].min()), "hi_max": float(parr["f_hi"].max()),
                        "n_sets": len(sets), "n_two": int(np.sum(parr["n_auto"] >= 2)),
                        "n_lo_auto": int(sum(np.any(np.abs(auto[nm].freq_hz - a) < 0.15) for nm in sets))}
    # figures quoted by the discussion
    peer_f = peer.freq_hz if peer.ok else np.array([])
    peer_z = peer.damping if peer.ok else np.array([])

    def z_of(target, result):
        return 100 * _paired(res.freq_hz, np.asarray(result.freq_hz), np.asarray(result.damping), target)

    figs = {
        "f105": float(res.freq_hz[np.argmin(np.abs(res.freq_hz - 105.2))]),
        "z105": z_of(105.2, res), "z105_peer": 100 * _paired(res.freq_hz, peer_f, peer_z, 105.2),
        "z105_accs": ", ".join(f"{z_of(105.2, r):.2g}" for r in per[:3]), "z105_raw": z_of(105.2, per[3]),
        "z105_points": 100 * per_point.get(105, {}).get("zeta_median", np.nan), "z105_lab1": z_of(105.2, r1.result),
        "z97": z_of(97.1, res), "z97_peer": 100 * _paired(res.freq_hz, peer_f, peer_z, 97.1),
        "z97_accs": ", ".join(f"{z_of(97.1, r):.2g}" for r in per[:3]),
        "pp97_scatter": per_point.get(97, {}).get("scatter", np.nan), "pp105_scatter": per_point.get(105, {}).get("scatter", np.nan),
        "pp105_claimed": per_point.get(105, {}).get("claimed", np.nan), "pp105_global": per_point.get(105, {}).get("global", np.nan),
        "tau": tau, "inv_tau": 1 / tau, "zwin19": 100 / (tau * 2 * np.pi * 18.85), "zwin105": 100 / (tau * 2 * np.pi * 105.2),
        "lab1_err": r1.synth_err_pct, "err_model_vs_raw": err_struct,
        "w_rms": frf_err[id(ours)][0], "w_med": frf_err[id(ours)][1], "uw_rms": frf_err[id(uw)][0],
        "uw_med": frf_err[id(uw)][1],
        "uw_err": uw.synth_err_pct, "uw_modes": int(uw.result.poles.size), "uw_lost": ", ".join(f"{x:.1f}" for x in lost),
    }
    for k, d in pair_figs.items():
        figs.update({f"pair{k + 1}_{n}": v for n, v in d.items()})
    summary["figures"] = {**summary.get("figures", {}), **figs}
    summary["extra"] = {"exp_window_tau_s": tau, "consistency": arr}
    s_uw = {"case": NAME + " (unweighted)", "n_frf": summary["n_frf"], "lines": summary["lines"], "band": uw.band,
            "modes_ours": int(uw.result.poles.size), "modes_peer": None, "err_ours": uw.synth_err_pct, "err_peer": None,
            "t_ours": uw.time_s, "t_peer": None}
    return CaseReport(NAME, "ULiege MECA0062 plane, 74 points x 3 accelerometers", SOURCE, "\n".join(md),
                      [summary, s_uw], plots)
