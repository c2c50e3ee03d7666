"""The batch's outputs: ``modes.parquet``, ``fleet.json`` and ``fleet.png``, each written atomically.

``modes.parquet``: one row per input and fitted mode (an input with no result: one row with
``status = "error"`` and the reason). Columns: ``input`` (the input's file name), ``unit`` (its
result name), ``status``, ``error``, ``mode`` (1-based, by frequency, within the input),
``f_hz``, ``zeta``, ``f_std_hz``, ``zeta_std``, ``ref_mode`` (1-based reference mode it pairs
with; 0: none), ``ref_f_hz``, ``mac`` (to the reference mode), ``shift_pct`` (beyond the unit's
common shift and the fleet's median), ``z`` (in robust standard deviations), ``flagged`` (the unit).

``fleet.json``: ``{"schema", "reference", "rules", "common_shift", "units": [{"name", "file",
"status", "flagged", "reasons", "notes", "error", "common_shift_pct"}], "modes": [{"mode", "ref_freq_hz",
"found", "found_fraction", "assessed", "freq_median_hz", "shift_median_pct", "shift_spread_pct",
"damping_median", "damping_spread"}]}``; a flagged unit diagnosed (``analysis batch --diagnose``)
also has ``"diagnosis": {"verdict", "named": [{"effect", "parameters"}], "trace"}``.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import atomic_path
from .fleet import FleetResult
from .unit_modes import UnitModes

__all__ = ["MODES_COLUMNS", "modes_rows", "write_modes_parquet", "fleet_document",
           "plot_fleet"]

MODES_COLUMNS = ("input", "unit", "status", "error", "mode", "f_hz", "zeta", "f_std_hz", "zeta_std", "ref_mode",
                 "ref_f_hz", "mac", "shift_pct", "z", "flagged")


def _f(x: Any) -> float:
    return float(x) if x is not None and np.isfinite(x) else float("nan")


def modes_rows(fleet: FleetResult, units: Sequence[UnitModes | None], inputs: Sequence[str],
               ref_freq_hz: np.ndarray) -> list[dict[str, Any]]:
    """The rows of modes.parquet (see the module docstring); ``inputs`` are the inputs' file names."""
    rows = []
    for flags, u, inp in zip(fleet.units, units, inputs):
        base = {"input": inp, "unit": flags.name, "status": flags.status, "error": flags.error, "flagged": flags.flagged}
        if u is None or flags.pairing is None:
            rows.append({**base, "mode": 0, "f_hz": math.nan, "zeta": math.nan, "f_std_hz": math.nan,
                         "zeta_std": math.nan, "ref_mode": 0, "ref_f_hz": math.nan, "mac": math.nan,
                         "shift_pct": math.nan, "z": math.nan})
            continue
        paired_to = {int(j): k for k, j in enumerate(flags.pairing.index) if j >= 0}
        for j in range(u.n_modes):
            k = paired_to.get(j)
            rows.append({**base, "mode": j + 1, "f_hz": _f(u.freq_hz[j]), "zeta": _f(u.damping[j]),
                         "f_std_hz": _f(u.freq_std_hz[j]), "zeta_std": _f(u.damping_std[j]),
                         "ref_mode": 0 if k is None else k + 1,
                         "ref_f_hz": math.nan if k is None else float(ref_freq_hz[k]),
                         "mac": math.nan if k is None else _f(flags.pairing.mac[k]),
                         "shift_pct": math.nan if k is None else _f(flags.shift_pct[k]),
                         "z": math.nan if k is None else _f(flags.z[k])})
    return rows


def write_modes_parquet(path: str | Path, rows: Sequence[dict[str, Any]]) -> None:
    """Write the rows as a Parquet table (pyarrow), atomically, with the columns in MODES_COLUMNS order."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise ImportError("modes.parquet needs pyarrow: pip install 'impactlab[batch]'") from None
    types = {"input": pa.string(), "unit": pa.string(), "status": pa.string(), "error": pa.string(),
             "mode": pa.int32(), "ref_mode": pa.int32(), "flagged": pa.bool_()}
    schema = pa.schema([(c, types.get(c, pa.float64())) for c in MODES_COLUMNS])
    table = pa.Table.from_pylist([{c: r.get(c) for c in MODES_COLUMNS} for r in rows], schema=schema)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)


def _num(x: float, nd: int = 6) -> float | None:
    return round(float(x), nd) if x is not None and np.isfinite(x) else None


def fleet_document(fleet: FleetResult, run_info: dict[str, Any],
                   diagnoses: Mapping[str, dict[str, Any]] | None = None) -> dict[str, Any]:
    """The fleet.json document; ``diagnoses`` (unit name -> ``{"verdict", "named", "trace"}``, the
    flagged units diagnosed) become those units' ``diagnosis``."""
    doc = {
        "schema": "impactlab.fleet/1",
        "reference": fleet.reference,
        "rules": fleet.rules,
        "common_shift": {"median_pct": _num(fleet.common_shift_median_pct), "spread_pct": _num(fleet.common_shift_spread_pct)},
        "run": run_info,
        "units": [{"name": u.name, "file": u.file, "status": u.status, "flagged": u.flagged, "reasons": list(u.reasons),
                   "notes": list(u.notes),
                   "error": u.error, "common_shift_pct": _num(u.common_shift_pct)} for u in fleet.units],
        "modes": [{"mode": m.index + 1, "ref_freq_hz": _num(m.ref_freq_hz), "found": m.found,
                   "found_fraction": _num(m.found_fraction, 4), "assessed": m.assessed,
                   "freq_median_hz": _num(m.freq_median_hz), "shift_median_pct": _num(m.shift_median_pct),
                   "shift_spread_pct": _num(m.shift_spread_pct), "damping_median": _num(m.damping_median),
                   "damping_spread": _num(m.damping_spread)} for m in fleet.modes],
    }
    for u in doc["units"]:
        if diagnoses and u["name"] in diagnoses:
            u["diagnosis"] = diagnoses[u["name"]]
    return doc


def plot_fleet(path: str | Path, fleet: FleetResult, captions: Sequence[str] = ()) -> None:
    """fleet.png: per reference mode, every unit's shift beyond its common shift (%), flagged units
    in red with their names (at their largest departure), the fleet's +-z_limit robust band in grey;
    the units' common shifts in a second panel (flagged units named); ``captions`` (one line each,
    e.g. what the diagnosis of each flagged unit named) under the panels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    modes = fleet.modes
    shown = list(captions[:12]) + ([f"... and {len(captions) - 12} more"] if len(captions) > 12 else [])
    extra = 0.17 * len(shown) + (0.1 if shown else 0.0)            # inches of caption lines
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.8 + extra), gridspec_kw={"width_ratios": [4, 1]})
    x = np.arange(1, len(modes) + 1)
    zl = float(fleet.rules["z_limit"])
    lim = np.array([max(zl * m.shift_spread_pct, fleet.rules["min_shift_pct"]) for m in modes])
    ax.fill_between(x, [m.shift_median_pct for m in modes] - lim, [m.shift_median_pct for m in modes] + lim,
                    step="mid", color="0.88", label=f"fleet: +-max({zl:g} robust sigma, {fleet.rules['min_shift_pct']:g} %)")
    rng = np.random.default_rng(0)
    for flagged, colour, label in ((False, "tab:blue", "unit"), (True, "tab:red", "flagged unit")):
        xs, ys = [], []
        for u in fleet.units:
            if u.status != "ok" or u.flagged != flagged:
                continue
            ok = np.isfinite(u.shift_pct)
            ux = x[ok] + rng.uniform(-0.18, 0.18, ok.sum())
            xs.extend(ux)
            ys.extend(u.shift_pct[ok])
            if flagged and ok.any():  # the unit's name at its largest departure: the plot names the units
                k = int(np.argmax(np.abs(u.shift_pct[ok] - np.array([m.shift_median_pct for m in modes])[ok])))
                ax.annotate(u.name, (ux[k], u.shift_pct[ok][k]), xytext=(4, 3), textcoords="offset points",
                            fontsize=7, color=colour)
        if xs:
            ax.plot(xs, ys, ".", color=colour, ms=4 if not flagged else 6, alpha=0.6 if not flagged else 0.9,
                    label=label)
    ax.set_xticks(x)
    ax.set_xticklabels([f"{m.ref_freq_hz:.0f}" + ("" if m.assessed else "*") for m in modes], rotation=60, fontsize=8)
    ax.set_xlabel("reference mode (Hz; * = found in too few units to judge)")
    ax.set_ylabel("shift beyond the unit's common shift (%)")
    ax.set_title(f"resonance inspection: {sum(u.flagged for u in fleet.units)} of {len(fleet.units)} units flagged "
                 f"(reference {fleet.reference})")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    cs = [u.common_shift_pct for u in fleet.units if u.status == "ok"]
    colours = ["tab:red" if u.flagged else "tab:blue" for u in fleet.units if u.status == "ok"]
    cx = rng.uniform(-0.2, 0.2, len(cs))
    ax2.scatter(cx, cs, c=colours, s=10)
    for xi, yi, u in zip(cx, cs, [u for u in fleet.units if u.status == "ok"]):
        if u.flagged:
            ax2.annotate(u.name, (xi, yi), xytext=(4, 0), textcoords="offset points", fontsize=7, color="tab:red")
    ax2.set_xticks([])
    ax2.set_ylabel("common shift of all modes (%)")
    ax2.set_title("material scatter")
    ax2.grid(True, alpha=0.3)
    fig.tight_layout(rect=(0.0, extra / (4.8 + extra), 1.0, 1.0))
    if shown:
        fig.text(0.01, 0.01, "\n".join(shown), fontsize=8, va="bottom", ha="left", color="tab:red", family="monospace")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
