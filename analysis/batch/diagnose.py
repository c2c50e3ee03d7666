"""Diagnose the flagged units of a fleet on the cluster that fitted them, and say what was found.

A flagged unit's diagnosis is the call of ``python -m analysis diagnose --measured UNIT --simulated
SIM``; this module never makes it itself: the face hands its function (``run(measured, simulated,
band=, estimator=) -> Diagnosis``) to :func:`diagnose_one`, which a Dask worker runs, so this library
module imports no simulator. :func:`diagnose_one` never raises for a bad unit: a diagnosis that fails
is a result with ``status = "error"`` and the reason. Results live in ``DIR/diagnoses/<unit>.json``
and are reused, like the fits, when the unit's content (SHA-256), the SIM's content and the options
are unchanged (:func:`diagnosis_key`).

The structure checks refuse a SIM that is not the fleet's structure: before any work
(:func:`structure_problem`, :func:`peaks_problem`) other points, a frequency range that does not cover
the fleet's band, or resonances (the peaks of the first CMIF curve, :func:`cmif_peaks_hz`) that do not
pair with the first unit's within :data:`PEAKS_TOLERANCE`; after the fits (:func:`modes_problem`) modes
that do not pair with the fleet's reference modes.
"""
from __future__ import annotations

import hashlib
import json
import os
import socket
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .fleet import MIN_PAIRED_FRACTION, pair_modes
from .task import batch_row, stored_if_current
from .unit_modes import UnitModes

if TYPE_CHECKING:
    from ..frf import FRFSet

__all__ = ["DIAGNOSIS_SCHEMA", "PLACE_KEYS", "PEAKS_TOLERANCE", "diagnosis_key", "diagnose_one", "diagnosis_summary",
           "diagnosis_is_current", "describe_diagnosis", "structure_problem", "modes_problem", "peaks_problem",
           "cmif_peaks_hz"]

#: version 2: the SIM's global cause scales every stiffness alike (:mod:`analysis.batch.scatter`); a result of
#: version 1 is diagnosed again
DIAGNOSIS_SCHEMA = "impactlab.batch-diagnosis/2"

#: the largest relative difference (-) of a SIM's resonance from the first unit's, after their common shift,
#: for the two to pair (:func:`peaks_problem`): on the default frame a unit's defect moves a few modes by up to
#: ~5 %, which the half of the peaks that must pair tolerates; a frame with other columns, beam or span pairs
#: fewer than half of its peaks with a unit's at 3 % (at 5 % some did by chance)
PEAKS_TOLERANCE = 0.03

#: parameters that name where a cause acts (a support, a joint, an element, a node, a member)
PLACE_KEYS = ("support", "joint", "element", "point", "node", "component", "member")

#: the words of a cause that lowers (first) or raises (second) its factor; others: its name in words
_WORDS: dict[str, tuple[str, str]] = {
    "support_stiffness": ("loose support", "stiff support"),
    "joint_stiffness": ("soft joint", "stiff joint"),
    "element_stiffness": ("cracked element", "stiffened element"),
    "member_stiffness": ("soft member", "stiff member"),
    "member_mass": ("light member", "heavy member"),
    "stiffness_shift": ("softer material", "stiffer material"),
}


def diagnosis_key(simulated_sha256: str, band: Sequence[float] | None, estimator: str | None) -> str:
    """A short fingerprint of what changes a unit's diagnosis besides the unit: the SIM's content
    (SHA-256), the band (Hz) and the FRF estimator."""
    text = json.dumps({"schema": DIAGNOSIS_SCHEMA, "simulated": simulated_sha256,
                       "band": None if band is None else [float(b) for b in band], "estimator": estimator},
                      sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _plain(x: Any) -> Any:
    """``x`` with NumPy scalars and arrays as plain Python (for JSON)."""
    if isinstance(x, Mapping):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    return x


def diagnosis_summary(doc: Mapping[str, Any]) -> dict[str, Any]:
    """``{"verdict", "named": [{"effect", "parameters"}], "trace"}`` of a diagnosis document (the JSON
    of ``analysis diagnose``). ``trace`` is the document's own decision trace when it carries one;
    otherwise the candidate causes as ranked, each ``{"effect", "parameters", "gain_db",
    "significant", "adequate"}`` (the fields the document has)."""
    trace = doc.get("trace")
    if trace is None:
        keep = ("effect", "parameters", "gain_db", "significant", "adequate")
        trace = [{k: c[k] for k in keep if k in c} for c in doc.get("causes") or []]
    return _plain({"verdict": doc.get("verdict"),
                   "named": [{"effect": c["effect"], "parameters": c.get("parameters") or {}}
                             for c in doc.get("named") or []],
                   "trace": trace})


def diagnose_one(path: str, name: str, sha256: str, simulated: str, key: str, run: Callable[..., Any],
                 band: Sequence[float] | None = None, estimator: str | None = None) -> dict[str, Any]:
    """Diagnose one unit (the function a Dask worker runs): ``run(path, simulated, band=, estimator=)``
    is ``analysis diagnose``'s own function; returns the result document ``{schema, input, path, sha256,
    key, simulated, status: "ok"|"error", error, diagnosis, seconds, cpu_seconds, worker}`` with
    ``diagnosis`` as :func:`diagnosis_summary`, ``seconds`` the wall time and ``cpu_seconds`` the
    worker process's CPU time (s) of the diagnosis."""
    import warnings

    doc: dict[str, Any] = {"schema": DIAGNOSIS_SCHEMA, "input": name, "path": str(path), "sha256": sha256,
                           "key": key, "simulated": str(simulated), "status": "ok", "error": None,
                           "diagnosis": None, "worker": f"{socket.gethostname()}:{os.getpid()}"}
    with batch_row(doc), warnings.catch_warnings():   # its progress lines stay out of a worker's stderr
        warnings.simplefilter("ignore")
        diag = run(path, simulated, band=band, estimator=estimator)
        doc["diagnosis"] = diagnosis_summary(diag.to_json())
    return doc


def diagnosis_is_current(path: Path, sha256: str, key: str) -> dict[str, Any] | None:
    """The stored diagnosis at ``path`` if it is of this unit's content (``sha256``) with this SIM
    and options (``key``) and complete; None otherwise."""
    return stored_if_current(path, DIAGNOSIS_SCHEMA, sha256, key, lambda d: d.get("key"))


def _times(v: float) -> str:
    """``x0.18``; a factor within 5 % of one with three decimals (``x0.995``), a large one ``x84``."""
    if abs(v - 1.0) < 0.05:
        return f"x{v:.3f}"
    return f"x{v:.2f}" if abs(v) < 10 else f"x{v:.3g}"


def _factors(params: Mapping[str, Any]) -> str:
    """``x0.18`` for a cause's one factor (``factor``, or ``stiffness_factor`` before a derived
    ``factor``); ``x0.27 translational, x0.05 rotational`` for ``factor_translational`` and
    ``factor_rotational`` (one ``x0.18`` when they agree within 1 %); masses in kg."""
    parts = []
    plain = "stiffness_factor" in params            # the stiffness's factor before a derived frequency factor
    if plain:
        parts.append(_times(float(params["stiffness_factor"])))
    split = [float(v) for k, v in params.items() if k.startswith("factor_") and isinstance(v, (int, float))]
    if len(split) > 1 and max(split) <= 1.01 * min(split):        # one factor for all of them: say it once
        params = {**{k: v for k, v in params.items() if not k.startswith("factor_")}, "factor": split[0]}
    for k, v in params.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            continue
        if k in ("factor", "stiffness_factor"):
            if not plain:
                parts.append(_times(v))
            plain = True
        elif k.startswith("factor_"):
            parts.append(f"{_times(v)} {k[len('factor_'):].replace('_', ' ')}")
        elif k.endswith("_kg"):
            parts.append(f"{v:.2g} kg")
    return ", ".join(parts)


def _lowers(params: Mapping[str, Any]) -> bool:
    """Whether the cause lowers what it scales (its stiffness factor, else its first factor, below one)."""
    f = [float(v) for k, v in sorted(params.items(), key=lambda kv: kv[0] != "stiffness_factor")
         if "factor" in k and isinstance(v, (int, float))]
    return not f or f[0] < 1.0


def _cause_phrase(effect: str, params: Mapping[str, Any]) -> str:
    words = _WORDS.get(effect)
    what = (words[0] if _lowers(params) else words[1]) if words else effect.replace("_", " ")
    place = next((str(params[k]) for k in PLACE_KEYS if isinstance(params.get(k), str)), None)
    if place is None and words and effect in ("support_stiffness", "joint_stiffness"):
        what = what + "s (all)"
    factors = _factors(params)
    return what + (f" at {place}" if place else "") + (f", {factors}" if factors else "")


def describe_diagnosis(name: str, result: Mapping[str, Any]) -> str:
    """One short line a person reads, from a unit's diagnosis result document (:func:`diagnose_one`):
    ``unit-012 flagged: loose support at left:0, x0.18``; two named causes are joined by ``+``; a
    diagnosis that named nothing says its verdict, one that failed says why."""
    if result.get("status") != "ok":
        return f"{name} flagged: diagnosis failed ({result.get('error')})"
    summary = result.get("diagnosis") or {}
    named = summary.get("named") or []
    if not named:
        return f"{name} flagged: no cause named (verdict {summary.get('verdict')})"
    return f"{name} flagged: " + " + ".join(_cause_phrase(str(c["effect"]), c.get("parameters") or {})
                                            for c in named)


def structure_problem(fleet_outputs: Sequence[str], fleet_references: Sequence[str], fleet_band_hz: Sequence[float],
                      sim_outputs: Sequence[str], sim_references: Sequence[str],
                      sim_freq_hz: np.ndarray | None, line_spacing_hz: float) -> str | None:
    """Why a SIM's points or frequency range are not the fleet's (a sentence), or None. The points
    must be the same sets of ``component:node:direction`` labels (outputs and references); an FRF
    SIM's lines (``sim_freq_hz``, Hz; None for a model simulated at the fleet's lines) must cover the
    fleet's band within one line (``line_spacing_hz``)."""
    missing = [o for o in fleet_outputs if o not in sim_outputs] + [r for r in fleet_references
                                                                     if r not in sim_references]
    if missing or len(set(sim_outputs)) != len(set(fleet_outputs)) or set(sim_references) != set(fleet_references):
        return (f"its points ({len(sim_outputs)} outputs {', '.join(sim_outputs[:4])}{' ...' if len(sim_outputs) > 4 else ''}; "
                f"references {', '.join(sim_references)}) are not the fleet's ({len(fleet_outputs)} outputs "
                f"{', '.join(fleet_outputs[:4])}{' ...' if len(fleet_outputs) > 4 else ''}; references "
                f"{', '.join(fleet_references)})")
    if sim_freq_hz is not None and sim_freq_hz.size:
        lo, hi = float(fleet_band_hz[0]), float(fleet_band_hz[1])
        if sim_freq_hz[0] > lo + line_spacing_hz or sim_freq_hz[-1] < hi - line_spacing_hz:
            return (f"its frequency range {sim_freq_hz[0]:.4g}..{sim_freq_hz[-1]:.4g} Hz does not cover the "
                    f"fleet's {lo:.4g}..{hi:.4g} Hz")
    return None


def _unpaired(reference: UnitModes, sim: UnitModes, tol: float) -> tuple[int, int, float, float] | None:
    """How few of ``reference``'s modes pair with ``sim``'s (:func:`~analysis.batch.fleet.pair_modes`:
    common shift, then frequency and MAC within ``tol``): ``(paired, sim's modes in the span, span lo, hi
    (Hz))`` when fewer than :data:`~analysis.batch.fleet.MIN_PAIRED_FRACTION` of the reference's modes, or of
    the SIM's modes in the same span (the reference's lowest to highest mode, moved by the common shift,
    widened by ``tol``), pair; None when enough do (a different frame with many more modes pairs some of
    them by chance, but leaves most of its own unpaired)."""
    if reference.n_modes == 0:
        return None
    p = pair_modes(reference, sim, tol)
    n = int(np.sum(p.index >= 0))
    shift = float(np.exp(p.common_shift)) if np.isfinite(p.common_shift) else 1.0
    lo, hi = reference.freq_hz.min() * shift / (1 + tol), reference.freq_hz.max() * shift * (1 + tol)
    own = int(np.sum((sim.freq_hz >= lo) & (sim.freq_hz <= hi)))
    if n < MIN_PAIRED_FRACTION * reference.n_modes or n < MIN_PAIRED_FRACTION * own:
        return n, own, lo, hi
    return None


def _listed(f: np.ndarray) -> str:
    return ", ".join(f"{x:.4g}" for x in f[:5]) + (" ..." if f.size > 5 else "")


def modes_problem(reference: UnitModes, sim: UnitModes, tol: float = 0.05) -> str | None:
    """Why a SIM's modes are not the fleet's (a sentence), or None: at least
    :data:`~analysis.batch.fleet.MIN_PAIRED_FRACTION` of the fleet's reference modes, and of the SIM's modes
    in their span, must pair (:func:`_unpaired`, frequency and MAC within ``tol``)."""
    return _unpaired_sentence(reference, sim, tol, ("the fleet's", "reference modes", "modes", "", "fleet"))


def _frequencies(f_hz: np.ndarray) -> UnitModes:
    """Resonances known by their frequency only (Hz) as :class:`UnitModes` (no shapes: paired by frequency)."""
    f = np.sort(np.asarray(f_hz, float))
    nan = np.full(f.size, np.nan)
    return UnitModes(freq_hz=f, damping=nan, freq_std_hz=nan, damping_std=nan, shapes=np.zeros((0, f.size), complex),
                     outputs=())


def cmif_peaks_hz(frf: FRFSet) -> np.ndarray:
    """The resonances an FRF set shows, before any fit: the frequencies (Hz) of the peaks of its first CMIF
    curve in dB by the modal-peaks rule (:data:`analysis.peaks.PEAK_RULES`, ``modal_peaks``)."""
    from ..mif import cmif
    from ..peaks import PEAK_RULES

    c = cmif(frf)[:, 0]
    ok = np.isfinite(c) & (c > 0)
    if np.count_nonzero(ok) < 3:
        return np.zeros(0)
    f, db = frf.freq_hz[ok], 20.0 * np.log10(c[ok])
    return f[PEAK_RULES["modal_peaks"].find(db)[0]]


def peaks_problem(unit_peaks_hz: np.ndarray, sim_peaks_hz: np.ndarray, tol: float = PEAKS_TOLERANCE) -> str | None:
    """Why a SIM's resonances are not those of the fleet's first unit (a sentence), or None: the peaks
    (Hz, :func:`cmif_peaks_hz` of the unit and of the SIM's FRFs at the unit's points and lines) pair as
    :func:`modes_problem`'s modes, by frequency only, within ``tol`` (relative, after the common shift)."""
    return _unpaired_sentence(_frequencies(unit_peaks_hz), _frequencies(sim_peaks_hz), tol,
                              ("the first unit's", "resonances", "", f" within {100 * tol:g} %", "unit"))


def _unpaired_sentence(ref: UnitModes, sim: UnitModes, tol: float, words: tuple[str, str, str, str, str]) -> str | None:
    """The sentence of :func:`modes_problem` and :func:`peaks_problem` (None when the two pair):
    ``words`` = (whose, what, what of the SIM, how close, the reference's short name)."""
    bad = _unpaired(ref, sim, tol)
    if bad is None:
        return None
    n, own, lo, hi = bad
    whose, what, theirs, within, short = words
    return (f"only {n} of {whose} {ref.n_modes} {what} and of its {own}{' ' + theirs if theirs else ''} in "
            f"{lo:.4g}..{hi:.4g} Hz pair{within} ({short}: {_listed(ref.freq_hz)} Hz; "
            f"it: {_listed(sim.freq_hz[sim.freq_hz >= lo])} Hz)")
