"""The standard comparison of one FRF set: impactlab fit, Cramer-Rao bound, sdypy-EMA, figure, markdown."""
from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from analysis.frf import FRFSet

from .common import OurFit, fit_ours, fmt, md_table, plot_case, pole_table
from .peer import PeerFit, fit_peer

log = logging.getLogger(__name__)

__all__ = ["compare", "crlb_of", "agreement", "summary_row_header", "summary_row", "peer_repeats", "scatter_table"]

#: above this many real observations the Cramer-Rao bound is not evaluated (dense Jacobian)
_CRLB_MAX_OBS = 4_000_000


def crlb_of(fit: OurFit, frf: FRFSet):
    """Cramer-Rao bound of our poles at our estimated noise level, or None when too big or failing."""
    from analysis.uncertainty import crlb_poles

    from .common import data_model

    res = fit.result
    sub = frf.band(*res.band)
    n_obs = 2 * sub.H.size * (2 * res.poles.size + 4)
    if n_obs > _CRLB_MAX_OBS or not np.isfinite(res.noise_var) or res.noise_var <= 0:
        return None
    try:
        # the data hold the window-shifted poles: the bound is evaluated there (a constant shift
        # of every pole leaves its covariance unchanged)
        return crlb_poles(data_model(res), sub.freq_hz, res.noise_var)
    except (ValueError, np.linalg.LinAlgError, MemoryError) as exc:
        log.info("CRLB not evaluated: %s", exc)
        return None


def correct_peer_window(peer: PeerFit, exp_window_tau_s: float) -> PeerFit:
    """The peer's poles with an exponential window's decay ``1/exp_window_tau_s`` (rad/s) removed, as our LSFD does."""
    from dataclasses import replace

    from analysis.modal import damping_ratio, natural_freq_hz, pole_from_fz

    out = {}
    for fk, zk in (("freq_hz", "damping"), ("used_freq_hz", "used_damping")):
        lam = pole_from_fz(getattr(peer, fk), getattr(peer, zk)) + 1.0 / exp_window_tau_s
        out[fk], out[zk] = natural_freq_hz(lam), damping_ratio(lam)
    return replace(peer, **out)


def compare(name: str, frf: FRFSet, out_dir: Path, *, band: Sequence[float] | None = None,
            max_modes: int | None = None, n_modes: int | None = None, pair: tuple | None = None,
            title: str = "", with_peer: bool = True, with_crlb: bool = True,
            selection_options: dict | None = None, plot_name: str | None = None, initial="lscf",
            frf_weighting: str = "rms") -> tuple[OurFit, PeerFit, str, dict, list]:
    """Fit ``frf`` with impactlab (automatic) and with sdypy-EMA (hinted by our frequencies).

    Returns (our fit, peer fit, markdown block, summary dict, plot paths relative to ``out_dir.parent``).
    """
    ours = fit_ours(frf, band=band, max_modes=max_modes, n_modes=n_modes, selection_options=selection_options,
                    initial=initial, frf_weighting=frf_weighting)
    res = ours.result
    mm = max(ours.stab.orders) if ours.stab is not None else (max_modes or 2 * res.poles.size + 8)
    peer = fit_peer(frf, ours.band, mm, res.freq_hz) if with_peer else PeerFit(False, "not run for this case")
    if peer.ok and frf.exp_window_tau_s:
        peer = correct_peer_window(peer, float(frf.exp_window_tau_s))
    fixed = fit_peer(frf, ours.band, mm, res.freq_hz, repair=True) if with_peer and peer.ok else None
    crlb = crlb_of(ours, frf) if with_crlb else None
    sub = frf.band(*ours.band)
    lines = []
    lines.append(
        f"Fitted band {ours.band[0]:.6g}..{ours.band[1]:.6g} Hz, {sub.n_outputs} x {sub.n_references} FRFs x "
        f"{sub.freq_hz.size} lines, {sub.quantity}; stabilization up to {mm} modes; "
        + (f"{res.poles.size} modes selected automatically; " if isinstance(initial, str) else
           f"{res.poles.size} modes from the given frequencies {', '.join(f'{x:.5g}' for x in initial)} Hz; ")
        + f"LSFD ({res.method}) {res.iterations} iterations, "
        f"status {res.status} ({res.message})."
    )
    lines.append("")
    lines.append(md_table(
        ["", "impactlab (LSCF + selection + nonlinear LSFD)", "sdypy-EMA (LSCF + hinted selection + linear LSFD)"],
        [["modes", str(res.poles.size), str(peer.freq_hz.size) if peer.ok else "-"],
         ["synthesis error (rel. Frobenius)", f"{fmt(ours.synth_err_pct, 3)} %",
          f"{fmt(peer.synth_err_pct, 3)} %" if peer.ok else f"unavailable: {peer.reason}"],
         ["synthesis error, sdypy with `pole_ind` repaired by us", "",
          f"{fmt(fixed.synth_err_pct, 3)} %" if fixed is not None and fixed.ok else "-"],
         ["wall time", f"{ours.time_s:.3g} s", f"{peer.time_s:.3g} s" if peer.ok else "-"]]))
    lines.append("")
    lines.append(pole_table(res, peer, crlb))
    lines.append("")
    lines.append("`std` = standard deviation from the fit (Jacobian and residual variance); `CRLB` = Cramer-Rao "
                 "bound at the estimated noise level" + (" (not evaluated: problem too large)" if crlb is None else "")
                 + "; `df` = (f sdypy - f ours) / f ours.")
    if peer.ok:
        dz = np.abs(peer.used_freq_hz - peer.freq_hz) / np.maximum(peer.freq_hz, 1e-300)
        if np.any(dz > 1e-6) or np.any(np.abs(peer.used_damping - peer.damping) > 1e-6 * np.maximum(peer.damping, 1e-12)):
            k = int(np.argmax(dz))
            lines.append("")
            lines.append(
                f"sdypy pole bookkeeping: the poles its LSFD used differ from the ones it reports "
                f"(largest: reported {peer.freq_hz[k]:.6g} Hz / {100 * peer.damping[k]:.3g} %, used "
                f"{peer.used_freq_hz[k]:.6g} Hz / {100 * peer.used_damping[k]:.3g} %); see the defects section.")
    if ours.warnings:
        lines.append("")
        lines.append("impactlab notes: " + "; ".join(ours.warnings))
    plots = []
    if plot_name:
        p = plot_case(out_dir / plot_name, frf, ours, peer, title=title or name, pair=pair)
        plots.append(f"{out_dir.name}/{p.name}")
        lines.append("")
        lines.append(f"![{name}]({out_dir.name}/{p.name})")
    summary = {"case": name, "n_frf": sub.n_outputs * sub.n_references, "lines": sub.freq_hz.size,
               "band": ours.band, "modes_ours": res.poles.size, "modes_peer": peer.freq_hz.size if peer.ok else None,
               "err_ours": ours.synth_err_pct, "err_peer": peer.synth_err_pct if peer.ok else None,
               "err_peer_fixed": fixed.synth_err_pct if fixed is not None and fixed.ok else None,
               "t_ours": ours.time_s, "t_peer": peer.time_s if peer.ok else None,
               "figures": agreement(res, peer) if peer.ok else {}}
    return ours, peer, "\n".join(lines), summary, plots


def agreement(res, peer: PeerFit, tol: float = 0.03) -> dict:
    """How far the peer's poles are from ours over the modes both have (paired by frequency within
    ``tol``, relative): ``max_df_pct`` = max |f_peer - f_ours| / f_ours (percent), ``max_dzeta_pct`` and
    ``median_dzeta_pct`` = max and median |zeta_peer - zeta_ours| / zeta_ours (percent), ``n_paired``."""
    from .common import match_poles

    pairs = [(i, j) for i, j in match_poles(res.freq_hz, peer.freq_hz, tol) if i is not None and j is not None]
    if not pairs:
        return {"n_paired": 0}
    i, j = np.array(pairs).T
    df = np.abs(peer.freq_hz[j] - res.freq_hz[i]) / res.freq_hz[i]
    dz = np.abs(peer.damping[j] - res.damping[i]) / res.damping[i]
    return {"n_paired": len(pairs), "max_df_pct": float(100 * df.max()), "max_dzeta_pct": float(100 * dz.max()),
            "median_dzeta_pct": float(100 * np.median(dz))}


def summary_row_header() -> list[str]:
    return ["case", "FRFs x lines", "band [Hz]", "modes ours / sdypy", "synthesis error ours / sdypy "
            "(sdypy, pole_ind repaired) [%]", "time ours / sdypy [s]"]


def summary_row(s: dict) -> list[str]:
    return [s["case"], f"{s['n_frf']} x {s['lines']}", f"{s['band'][0]:.4g}-{s['band'][1]:.4g}",
            f"{s['modes_ours']} / {s['modes_peer'] if s['modes_peer'] is not None else '-'}",
            f"{fmt(s['err_ours'], 3)} / {fmt(s['err_peer'], 3) if s['err_peer'] is not None else '-'}"
            + (f" ({fmt(s['err_peer_fixed'], 3)})" if s.get('err_peer_fixed') is not None else ""),
            f"{s['t_ours']:.3g} / {fmt(s['t_peer'], 3) if s['t_peer'] is not None else '-'}"]


def peer_repeats(frfs: Sequence[FRFSet], band: Sequence[float], max_modes: int, ref_freqs: np.ndarray,
                 tol: float = 0.03) -> tuple[np.ndarray, np.ndarray]:
    """sdypy-EMA on each repetition (same band, order and hints ``ref_freqs``): (f, zeta) arrays
    (n_rep, n_modes) paired to ``ref_freqs`` (NaN where missing or the peer failed). Exponential
    windows carried by the FRF sets are removed as for our fit."""
    from .common import match_poles

    ref = np.sort(np.asarray(ref_freqs, float))
    F = np.full((len(frfs), ref.size), np.nan)
    Z = np.full_like(F, np.nan)
    for a, fr in enumerate(frfs):
        p = fit_peer(fr, band, max_modes, ref)
        if not p.ok:
            continue
        if fr.exp_window_tau_s:
            p = correct_peer_window(p, float(fr.exp_window_tau_s))
        for i, j in match_poles(ref, p.freq_hz, tol):
            if i is not None and j is not None and p.freq_hz[j] > 0:
                F[a, i], Z[a, i] = p.freq_hz[j], p.damping[j]
    return F, Z


def scatter_table(ref_freqs: np.ndarray, ours: dict, peer_f: np.ndarray | None, peer_z: np.ndarray | None) -> str:
    """Per mode: standard deviation over repetitions of f and zeta, ours vs the peer's, and the
    median standard deviation our fit claims (so the claim can be checked against the scatter)."""
    import warnings

    ref = np.sort(np.asarray(ref_freqs, float))
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)

        def sd(a):
            return np.nanstd(a, ddof=1) if np.sum(np.isfinite(a)) > 1 else np.nan

        for i, f in enumerate(ref):
            r = [fmt(f, 6), fmt(sd(ours["f"][:, i]), 2), fmt(np.nanmedian(ours["f_std"][:, i]), 2)]
            r.append(fmt(sd(peer_f[:, i]), 2) if peer_f is not None else "-")
            r += [fmt(100 * sd(ours["zeta"][:, i]), 2), fmt(100 * np.nanmedian(ours["zeta_std"][:, i]), 2)]
            r.append(fmt(100 * sd(peer_z[:, i]), 2) if peer_z is not None else "-")
            r.append(f"{int(np.sum(np.isfinite(ours['f'][:, i])))} / "
                     + (f"{int(np.sum(np.isfinite(peer_f[:, i])))}" if peer_f is not None else "-"))
            rows.append(r)
    return md_table(["f [Hz]", "scatter f ours", "fit std f ours", "scatter f sdypy", "scatter zeta ours [%]",
                     "fit std zeta ours [%]", "scatter zeta sdypy [%]", "repetitions found ours / sdypy"], rows)
