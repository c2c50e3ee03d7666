"""unesp_bert_boltedbeam_subset: bolted-joint cantilever beam, analyser H1 at two drive levels.

Source: GitHub shm-unesp/DATASET_BOLTEDBEAM ("BERT", SHM Lab, UNESP Ilha Solteira; R. Teloli, L. Miguel,
S. da Silva), commit 414c85b8, ``Data/T5Nm/...``. Non-commercial research; acknowledge the SHM Lab at
UNESP Ilha Solteira and cite the dataset (UNESP-BERT). Internal validation only.

LMS Test.Lab exports: H1 with 54 averages, uniform window, 0..512 Hz, df 0.0625 Hz, random excitation at
0.05 V and 0.30 V shaker drive. The 4 accelerometer FRFs (g/V: the input is the amplifier voltage, not a
force, so the form is "accelerance" only in shape; the shaker's own dynamics are part of the FRF).
A bolted joint softens and dissipates more at higher amplitude: the expected signature of the two levels
is lower frequencies and higher damping at 0.30 V for joint-sensitive modes.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from analysis.frf import FRFSet
from analysis.modal import synthesize

from .case import compare
from .common import CaseReport, consistency_table, data_model, fit_ours_from_poles, synthesis_error

NAME = "unesp_bert_boltedbeam_subset"
SOURCE = ("GitHub shm-unesp/DATASET_BOLTEDBEAM (UNESP-BERT, SHM Lab UNESP Ilha Solteira; R. Teloli, L. Miguel, "
          "S. da Silva), commit 414c85b8, Data/T5Nm; non-commercial research, internal validation only")
LEVELS = ("0p05", "0p30")
BAND = (10.0, 400.0)


def _lms(path: Path, key: str) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Frequencies (Hz), curves (one row each) and the curves' channel pairs ("Acc1:+X/Shaker:-X") of an
    LMS Test.Lab export."""
    import scipy.io

    s = scipy.io.loadmat(str(path))[key][0, 0]
    x = s["x_values"][0, 0]
    n = int(np.ravel(x["number_of_values"])[0])
    f = float(np.ravel(x["start_value"])[0]) + float(np.ravel(x["increment"])[0]) * np.arange(n)
    v = np.asarray(s["y_values"][0, 0]["values"])
    if v.shape[0] == n:
        v = v.T
    rec = s["function_record"][0, 0]
    resp = [str(np.ravel(a)[0]) for a in np.ravel(rec["primary_channel"][0, 0]["label"])]
    ref = [str(np.ravel(a)[0]) for a in np.ravel(rec["reference_channel"][0, 0]["label"])]
    return f, v, [f"{a}/{b}" for a, b in zip(resp, ref)]


def _matched_coherence(path: Path, f: np.ndarray, channels: list[str]) -> np.ndarray:
    """The coherence of each FRF's channel pair (``channels``), picked by name from the coherence export
    (which may hold more curves, e.g. a laser vibrometer's); a clear error when one is missing."""
    fc, C, names = _lms(path, "Coherence")
    if fc.shape != f.shape or not np.allclose(fc, f):
        raise ValueError(f"{path.name}: its frequency lines differ from the FRF file's; export both on one grid")
    missing = [c for c in channels if c not in names]
    if missing:
        raise ValueError(f"{path.name} holds no coherence for {', '.join(missing)} (it holds {', '.join(names)}); "
                         "export the coherence of every FRF's channel pair")
    return np.clip(np.real(C[[names.index(c) for c in channels]]), 0.0, 1.0)


def load(data_dir: Path, level: str = "0p05") -> FRFSet:
    """The 4 accelerometer H1 (g/V) at drive level ``level`` ("0p05" or "0p30"), with their coherence (matched to
    the FRFs by channel names: the coherence file also holds a laser vibrometer's curve)."""
    d = Path(data_dir) / NAME
    f, H, channels = _lms(d / f"Rand__Rand{level}__FRF.mat", "FRF")
    coh = _matched_coherence(d / f"Rand__Rand{level}__Coherence.mat", f, channels)
    return FRFSet(freq_hz=f[1:], H=H[:, None, 1:], quantity="accelerance",
                  outputs=tuple(f"beam:{k + 1}:Z" for k in range(H.shape[0])), references=("shaker:0:Z",),
                  unit="g/V", coherence=coh[:, None, 1:],
                  meta={"source": SOURCE, "level_V": level.replace("p", ".")})


def run(data_dir: Path, out_dir: Path) -> CaseReport:
    lo = load(data_dir, "0p05")
    ours, peer, block, summary, plots = compare(NAME, lo, out_dir, band=BAND, plot_name=f"{NAME}.png",
                                                title=NAME + " (0.05 V)")
    hi = load(data_dir, "0p30")
    res_hi = fit_ours_from_poles(hi, ours.result.poles_raw, ours.band)
    tab, arr = consistency_table(["0.05 V", "0.30 V"], [ours.result, res_hi.result], ours.result.freq_hz)
    df = arr["f"][1] - arr["f"][0]
    dz = arr["zeta"][1] - arr["zeta"][0]
    ok = np.isfinite(df)
    sub = lo.band(*ours.band)
    G = synthesize(data_model(ours.result), sub.freq_hz).H
    mains = np.abs(sub.freq_hz / 60.0 - np.round(sub.freq_hz / 60.0)) * 60.0 < 1.0
    err_clean = synthesis_error(sub.H[..., ~mains], G[..., ~mains])
    err_clean_peer = (synthesis_error(sub.H[..., ~mains].reshape(-1, int((~mains).sum())),
                                      peer.H_band[:, ~mains]) if peer.ok and peer.H_band is not None else float("nan"))
    fo = np.sort(ours.result.freq_hz)
    on_mains = np.abs(fo / 60.0 - np.round(fo / 60.0)) * 60.0 < 1.0
    ref = np.sort(ours.result.freq_hz)
    struct = ok & ~(np.abs(ref / 60.0 - np.round(ref / 60.0)) * 60.0 < 1.0)
    md = [
        "Analyser H1 (54 averages) of the 4 accelerometers over the shaker voltage, fitted at 0.05 V (automatic) and "
        "at 0.30 V (LSFD from the 0.05 V poles).",
        "",
        block,
        "",
        f"The FRFs carry narrow electrical lines at multiples of 60 Hz (180, 240, 300 Hz: mains harmonics, not "
        f"structural modes; each a few lines wide). They dominate the Frobenius error: leaving out the lines within "
        f"1 Hz of a multiple of 60 Hz ({int(mains.sum())} of {mains.size}), the synthesis error is {err_clean:.3g} % "
        f"for impactlab and {err_clean_peer:.3g} % for sdypy-EMA. "
        + (f"{int(on_mains.sum())} of impactlab's {fo.size} poles sit within 1 Hz of a multiple of 60 Hz "
           f"({', '.join(f'{x:.2f}' for x in fo[on_mains])} Hz): the pipeline's misfit step (which adds poles at "
           "unexplained peaks) fitted the mains line as modes; they are not structural."
           if on_mains.any() else "No impactlab pole sits on a mains line."),
        "",
        "Drive-level comparison:",
        "",
        tab,
        "",
        f"From 0.05 V to 0.30 V: {int(np.sum(df[ok] < 0))} of {int(ok.sum())} modes move down in frequency, "
        f"{int(np.sum(dz[ok] > 0))} of {int(ok.sum())} gain damping; of the {int(struct.sum())} structural ones "
        f"(not on a mains line) {int(np.sum(df[struct] < 0))} move down and {int(np.sum(dz[struct] > 0))} gain damping "
        "(the bolted joint's amplitude dependence).",
    ]
    summary["figures"] = {**summary.get("figures", {}), "n_mains": int(on_mains.sum()),
                          "mains_poles": ", ".join(f"{x:.2f}" for x in fo[on_mains]) or "none",
                          "n_struct": int(fo.size - on_mains.sum()), "err_clean": err_clean, "err_clean_peer": err_clean_peer,
                          "n_down": int(np.sum(df[struct] < 0)), "n_damp_up": int(np.sum(dz[struct] > 0)),
                          "n_struct_both": int(struct.sum())}
    summary["case"] = NAME + " (0.05 V)"
    return CaseReport(NAME, "UNESP BERT bolted beam, two drive levels", SOURCE, "\n".join(md), summary, plots)
