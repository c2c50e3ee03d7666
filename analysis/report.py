"""Fit results for people and programs: the terminal table (paper Table 1) and the JSON document.

Complex numbers are written as ``[re, im]`` pairs. Frequencies in Hz, damping as a ratio in
the JSON (percent in the table), residues in the FRF unit times rad/s.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from .frf import FRFSet
from .modal import damping_ratio, natural_freq_hz

if TYPE_CHECKING:
    from .fit_result import FitResult
    from .lsfd import LSFDResult
    from .scatter import SubsetScatter
    from .stabilization import StabilizationResult

__all__ = ["roman", "format_table", "result_to_dict", "write_json", "complex_pair", "synthesis_error"]

JSON_SCHEMA = "impactlab.fit/1"


def roman(n: int) -> str:
    """Roman numeral of a positive integer (pole I, pole II, ...)."""
    if n < 1:
        raise ValueError(f"roman numerals start at 1; got {n}")
    out = []
    for v, s in ((1000, "M"), (900, "CM"), (500, "D"), (400, "CD"), (100, "C"), (90, "XC"), (50, "L"),
                 (40, "XL"), (10, "X"), (9, "IX"), (5, "V"), (4, "IV"), (1, "I")):
        while n >= v:
            out.append(s)
            n -= v
    return "".join(out)


def complex_pair(z: complex) -> list | None:
    """``[re, im]`` of a complex number, None when it is not finite."""
    z = complex(z)
    if not (math.isfinite(z.real) and math.isfinite(z.imag)):
        return None
    return [float(z.real), float(z.imag)]


def _fnum(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _cstr(z: complex, digits: int = 4) -> str:
    z = complex(z)
    if not (math.isfinite(z.real) and math.isfinite(z.imag)):
        return "n/a"
    sign = "-" if z.imag < 0 else "+"
    return f"{z.real:.{digits}g} {sign} {abs(z.imag):.{digits}g}i"


def format_table(result: LSFDResult, frf: FRFSet | None = None, *, output: int = 0, reference: int = 0,
                 title: str | None = None, initial: np.ndarray | None = None,
                 initial_label: str = "initial", status: str | None = None) -> str:
    """The paper's Table 1 for one FRF (``output``, ``reference`` indices) of an LSFD result.

    Columns: pole | [initial f, zeta] | f [Hz] | zeta [%] | f std [Hz] | zeta std [%] | parameter |
    value (residue R_r of that FRF), then S, UR and LR of that FRF. With ``initial`` poles (rad/s,
    e.g. those selected from the stabilization diagram) their f and zeta are shown first, as
    the paper's LSCE columns: each initial pole is matched to at most one fitted pole (nearest
    pairs first, within 3 half-power bandwidths of the fitted pole or 1 % in frequency); a fitted
    pole without a match (added by the pipeline for a missed resonance) shows "-". The exponential
    window's decay that the fit removed from its poles (``meta["exp_window_shift_rad_s"]``, 1/s) is
    removed from the initial poles too, so both columns speak of the structure. ``status``: the whole
    fit's :attr:`analysis.fit_result.FitResult.status`; other than "converged" it replaces the word
    "success" (the LSFD converging is not the fit succeeding).
    """
    model = result.model
    outs, refs = model.outputs, model.references
    label = f"{outs[output]} / {refs[reference]}" if outs and refs else "FRF"
    est = frf.meta.get("estimator") if frf is not None else None
    of = f" of {est}" if isinstance(est, str) and est else ""
    head = title or f"LSFD ({result.method}) fit{of}, residues of {label}"
    init = None if initial is None or np.size(initial) == 0 else np.asarray(initial, dtype=complex)
    if init is not None:
        init = init + float(model.meta.get("exp_window_shift_rad_s", 0.0) or 0.0)
    pre = (f"{initial_label} f [Hz]", f"{initial_label} zeta [%]") if init is not None else ()
    rows = [("",) + pre + ("f [Hz]", "zeta [%]", "f std [Hz]", "zeta std [%]", "parameter", "value")]
    order = np.argsort(result.freq_hz)
    match: dict = {}
    if init is not None:
        fi, ff = natural_freq_hz(init), np.asarray(result.freq_hz)
        tol = np.maximum(3 * 2 * np.abs(np.asarray(result.damping)) * ff, 0.01 * ff)
        dist = np.abs(fi[:, None] - ff[None, :])
        for flat in np.argsort(dist, axis=None):
            a, b = np.unravel_index(flat, dist.shape)
            if dist[a, b] <= tol[b] and a not in match.values() and b not in match:
                match[b] = a
    for k, r in enumerate(order, start=1):
        extra: tuple = ()
        if init is not None:
            if r in match:
                q = init[match[r]]
                extra = (f"{natural_freq_hz(q):.4f}", f"{100 * damping_ratio(q):.3f}")
            else:
                extra = ("-", "-")
        rows.append((
            f"pole {roman(k)}",) + extra + (
            f"{result.freq_hz[r]:.4f}",
            f"{100 * result.damping[r]:.3f}",
            "n/a" if not np.isfinite(result.freq_hz_std[r]) else f"{result.freq_hz_std[r]:.2g}",
            "n/a" if not np.isfinite(result.damping_std[r]) else f"{100 * result.damping_std[r]:.2g}",
            f"R{k}",
            _cstr(model.residues[output, reference, r]),
        ))
    widths = [max(len(row[c]) for row in rows) for c in range(len(rows[0]))]
    lines = [head]
    sep = "-+-".join("-" * w for w in widths)
    left = {0, len(widths) - 2, len(widths) - 1}
    for i, row in enumerate(rows):
        lines.append(" | ".join(cell.ljust(w) if c in left else cell.rjust(w)
                                for c, (cell, w) in enumerate(zip(row, widths))))
        if i == 0:
            lines.append(sep)
    lines.append(sep)
    state = f"{'success' if result.success else 'NOT converged'}: {result.message}"
    if status is not None and status != "converged":
        state = f"fit {status.upper()} (see the warnings); LSFD {result.message}"
    lines.append(f"sum of square errors: S = {result.sse:.6g} (all FRFs, {result.iterations} iterations, {state})")
    if model.upper_residual is not None:
        lines.append(f"upper residual term UR: {_cstr(model.upper_residual[output, reference])}")
    if model.lower_residual is not None:
        lines.append(f"lower residual term LR: {_cstr(model.lower_residual[output, reference])}")
    lines.append(f"band {result.band[0]:.6g}..{result.band[1]:.6g} Hz, quantity {model.quantity}, "
                 f"residual form {model.residual_form}")
    n_frf = len(outs) * len(refs)
    if n_frf > 1:
        lines.append(f"({n_frf} FRFs fitted with common poles; the residues of every FRF are in the JSON)")
    return "\n".join(lines)


def _labelled(values: np.ndarray, outs: Sequence[str], refs: Sequence[str], key: str) -> list[dict[str, Any]]:
    out = []
    for i, o in enumerate(outs):
        for j, r in enumerate(refs):
            v = values[i, j]
            item: dict[str, Any] = {"output": o, "reference": r}
            if np.ndim(v) == 0:
                item[key] = complex_pair(v)
            else:
                item[key] = [complex_pair(x) for x in v]
            out.append(item)
    return out


STD_NOTE = ("freq_hz_std/damping_std assume white noise of equal variance on every line and a perfect model "
            "(Jacobian and residual variance); on real data model error dominates and they are lower bounds. "
            "freq_hz_scatter_std/damping_scatter_std, when present, are the spread of refits on independent FRF "
            "groups divided by sqrt(number of groups) (see docs/fitting.md, section 9).")


def result_to_dict(result: LSFDResult | FitResult, frf: FRFSet | None = None,
                   stab: StabilizationResult | None = None, *, extra: dict | None = None,
                   scatter: SubsetScatter | None = None) -> dict:
    """JSON-ready dictionary of an LSFD result (schema ``impactlab.fit/1``).

    Keys: poles (freq_hz, damping, freq_hz_std, damping_std, damped_freq_hz, pole [re, im] rad/s),
    residues / upper_residual / lower_residual (per output/reference label), sse, iterations,
    history, status, message, success, method, band, quantity, unit, residual_form, outputs,
    references, noise_var, nfev, mode_shapes/participation when present, per_frf summaries,
    and the stabilization summary when given; ``std_note`` says what the standard deviations
    assume; with ``scatter`` (:class:`analysis.scatter.SubsetScatter` of this result) every pole
    also gets ``freq_hz_scatter_std`` and ``damping_scatter_std`` and ``scatter_groups`` lists the
    groups.

    ``result`` may be the :class:`analysis.fit_result.FitResult` of :func:`analysis.pipeline.fit_auto`
    (then ``stab`` comes from it): ``success`` is then the fit's verdict, *converged and physically
    sensible*, with ``converged``, ``fit_status`` and ``problems`` beside it.
    """
    fit: FitResult | None = None
    if hasattr(result, "lsfd"):  # a FitResult
        fit = cast("FitResult", result)
        stab = fit.stabilization if stab is None else stab
    lsfd: LSFDResult = fit.lsfd if fit is not None else cast("LSFDResult", result)
    model = lsfd.model
    outs, refs = list(model.outputs), list(model.references)
    order = np.argsort(lsfd.freq_hz)
    poles = []
    for k, r in enumerate(order, start=1):
        poles.append({
            "label": f"pole {roman(k)}",
            "freq_hz": _fnum(lsfd.freq_hz[r]),
            "damping": _fnum(lsfd.damping[r]),
            "freq_hz_std": _fnum(lsfd.freq_hz_std[r]),
            "damping_std": _fnum(lsfd.damping_std[r]),
            "damped_freq_hz": _fnum(lsfd.damped_freq_hz[r]),
            "pole": complex_pair(lsfd.poles[r]),
        })
        if scatter is not None:
            poles[-1]["freq_hz_scatter_std"] = _fnum(scatter.freq_hz_std[r])
            poles[-1]["damping_scatter_std"] = _fnum(scatter.damping_std[r])
    R = np.asarray(model.residues)[..., order]
    doc: dict[str, Any] = {
        "schema": JSON_SCHEMA,
        "method": lsfd.method,
        "status": int(lsfd.status),
        "message": str(lsfd.message),
        "success": bool(lsfd.success),
        "band": [float(lsfd.band[0]), float(lsfd.band[1])],
        "quantity": model.quantity,
        "unit": frf.unit if frf is not None else "",
        "residual_form": model.residual_form,
        "outputs": outs,
        "references": refs,
        "poles": poles,
        "residues": _labelled(R, outs, refs, "values"),
        "upper_residual": None if model.upper_residual is None else _labelled(model.upper_residual, outs, refs, "value"),
        "lower_residual": None if model.lower_residual is None else _labelled(model.lower_residual, outs, refs, "value"),
        "sse": _fnum(lsfd.sse),
        "iterations": int(lsfd.iterations),
        "nfev": int(lsfd.nfev),
        "history": [_fnum(s) for s in lsfd.history],
        "noise_var": _fnum(lsfd.noise_var),
        "std_note": STD_NOTE,
    }
    if fit is not None:
        doc["converged"] = bool(lsfd.success)
        doc["success"] = bool(fit.success)
        doc["fit_status"] = fit.status
        doc["problems"] = list(fit.problems)
        doc["suspension_modes_hz"] = [float(x) for x in fit.suspension_hz]
        if not fit.success:
            doc["message"] = fit.message
    if scatter is not None:
        doc["scatter_groups"] = list(scatter.groups)
    if frf is not None and frf.H.shape[:2] == np.asarray(model.residues).shape[:2]:
        doc["synthesis_error"] = synthesis_error(lsfd, frf)
    if lsfd.mode_shapes is not None:
        doc["mode_shapes"] = [
            {"output": o, "values": [complex_pair(x) for x in np.asarray(lsfd.mode_shapes)[i, order]]}
            for i, o in enumerate(outs)
        ]
    if lsfd.participation is not None:
        doc["participation"] = [
            {"reference": r, "values": [complex_pair(x) for x in np.asarray(lsfd.participation)[order, j]]}
            for j, r in enumerate(refs)
        ]
    if lsfd.per_frf:
        doc["per_frf"] = [
            {
                "output": sub.model.outputs[0],
                "reference": sub.model.references[0],
                "freq_hz": [_fnum(x) for x in sub.freq_hz],
                "damping": [_fnum(x) for x in sub.damping],
                "sse": _fnum(sub.sse),
                "success": bool(sub.success),
            }
            for sub in lsfd.per_frf
        ]
    if stab is not None:
        doc["stabilization"] = {
            "method": stab.method,
            "band": [float(stab.band[0]), float(stab.band[1])],
            "max_modes": int(max(stab.orders)),
            "selected_poles": [complex_pair(p) for p in np.asarray(
                fit.selected_poles if fit is not None else stab.meta.get("selected_poles", []))],
            "warnings": list(fit.warnings if fit is not None else stab.meta.get("warnings", [])),
        }
    if extra:
        doc.update(extra)
    return doc


def synthesis_error(result: LSFDResult, frf: FRFSet) -> dict:
    """Relative RMS misfit ``||H - G|| / ||H||`` over the fitted band and all FRFs, with ``G``
    synthesised from the model *as measured* (``result.model_raw``: raw poles, the exponential
    window's damping included), so windowed data are compared like with like."""
    from .modal import synthesize

    lo, hi = result.band
    sel = (frf.freq_hz >= lo) & (frf.freq_hz <= hi)
    H = frf.H[..., sel]
    G = synthesize(result.model_raw, frf.freq_hz[sel]).H
    ok = np.isfinite(H)
    den = float(np.sqrt(np.sum(np.abs(H[ok]) ** 2)))
    rel = float(np.sqrt(np.sum(np.abs((H - G)[ok]) ** 2))) / den if den > 0 else float("nan")
    return {"relative_rms": _fnum(rel), "poles": "raw (as measured)",
            "exp_window_tau_s": _fnum(frf.exp_window_tau_s) if frf.exp_window_tau_s else None}


def write_json(path: str | Path, doc: dict) -> None:
    """Write a JSON document (strict: no NaN; NaN values are written as null), atomically."""
    from .atomic import write_json_atomic

    write_json_atomic(path, doc)
