"""Where the report's inputs come from: the one place that reads a recording's test record and the
one place that runs or loads a modal fit (their APIs are the ones most likely to change).

:class:`FitData` is the report's neutral view of a fit: structure poles, the model as measured
(window damping included, for synthesis against the data), standard deviations, residues aligned
with the FRF set's outputs/references.
"""
from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import ReportInputError
from ..frf import FRFSet
from ..input_limits import NESTING_LIMIT, RESULT_LIMIT_BYTES, read_bounded_text, too_deeply_nested
from ..modal import ModalModel

if TYPE_CHECKING:
    from ..stabilization import StabilizationResult

__all__ = [
    "FitData",
    "ReportInputError",
    "TestRecord",
    "load_diagnosis",
    "load_fit_json",
    "read_test_record",
    "recording_device",
    "run_fit",
    "unknown_as_none",
]


log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FitData:
    """A modal fit as the report shows it.

    model : structure model (window-corrected poles, rad/s); model_raw : as measured.
    freq_hz_std, damping_std : (m,) standard deviations (NaN when unknown).
    band : (lo, hi) Hz fitted; stab : a StabilizationResult or None; source : "fit_auto" or a path.
    """

    model: ModalModel
    model_raw: ModalModel
    freq_hz_std: np.ndarray
    damping_std: np.ndarray
    band: tuple
    stab: Any = None
    source: str = ""
    warnings: tuple = ()


@dataclass
class TestRecord:
    """The test as recorded: JSON-able descriptions and per-point time data (EU, s)."""

    device: str = ""
    date: str = ""
    instrument: dict = field(default_factory=dict)
    setup: dict = field(default_factory=dict)
    channels: list = field(default_factory=list)
    windows: Any = None
    plan: dict = field(default_factory=dict)
    hits: list = field(default_factory=list)
    #: point label -> dict(fs_hz, trigger_index, force (n_hits, n), responses (n_hits, n_resp, n), outputs)
    points: dict = field(default_factory=dict)


def unknown_as_none(value: Any) -> Any:
    """``value`` with every non-finite float (the recording's "unknown", NaN) replaced by None, through
    nested dicts and lists; other values unchanged. A new object: the input is not modified."""
    if isinstance(value, dict):
        return {k: unknown_as_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [unknown_as_none(v) for v in value]
    if isinstance(value, (float, np.floating)) and not np.isfinite(value):
        return None
    return value


def read_test_record(path: str | Path) -> TestRecord:
    """Test description, hit log and accepted hits' time data of a recording."""
    from ..recording import Recording

    rec = TestRecord()
    with Recording(path) as r:
        # a recording marks what the test did not know (an imported file's sensitivity and input
        # range) as NaN; the report says "unknown" (None), and its JSON stays standard
        rec.instrument = unknown_as_none(dict(r.instrument))
        rec.setup = unknown_as_none(dict(r.setup))
        rec.channels = [unknown_as_none(dict(c)) for c in r.channels]
        rec.windows = r.windows
        rec.plan = unknown_as_none(dict(r.plan))
        rec.date = r.created_utc
        rec.device = str(rec.plan.get("device") or rec.instrument.get("url") or rec.instrument.get("model") or "")
        for h in r.hits(skip_damaged=True):
            rec.hits.append({"index": h.index, "point": h.point, "accepted": bool(h.accepted),
                             "reasons": [str(x) for x in h.reasons], "peak_n": float(np.max(np.abs(
                                 h.data[h.force_channel])))})
            if not h.accepted:
                continue
            d = h.data
            p = rec.points.setdefault(h.point, {"fs_hz": h.sample_rate_hz, "trigger_index": h.trigger_index,
                                                "outputs": list(h.outputs), "force": [], "responses": []})
            p["force"].append(d[h.force_channel])
            p["responses"].append(d[h.response_channels])
    for p in rec.points.values():
        p["force"] = np.asarray(p["force"])
        p["responses"] = np.asarray(p["responses"])
    return rec


def recording_device(path: str | Path) -> str:
    """The device a recording was made with (the plan's ``device``, else the instrument's model)."""
    from ..recording import Recording

    with Recording(path) as r:
        return str(r.plan.get("device") or r.instrument.get("url") or r.instrument.get("model") or "")


def run_fit(frf: FRFSet, **options: Any) -> FitData:
    """The automatic fit (:func:`analysis.pipeline.fit_auto` with ``options``, e.g. ``band``) as
    :class:`FitData`."""
    from ..pipeline import fit_auto

    fit = fit_auto(frf, **options)
    result, stab = fit.lsfd, fit.stabilization
    warnings = tuple(fit.warnings) + tuple(fit.problems)
    return FitData(model=result.model, model_raw=result.model_raw, freq_hz_std=np.asarray(result.freq_hz_std, float),
                   damping_std=np.asarray(result.damping_std, float), band=tuple(result.band), stab=stab,
                   source="automatic fit (analysis.pipeline.fit_auto)", warnings=warnings)


def _cpx(pair: Any) -> complex:
    return complex(float(pair[0]), float(pair[1])) if pair is not None else complex("nan")


def load_fit_json(path: str | Path, frf: FRFSet) -> FitData:
    """A fit written by ``python -m analysis fit --json``; residues are matched to ``frf`` by label."""
    from ..lsfd import seen_through_window

    p = Path(path)
    try:
        text = read_bounded_text(p, "--fit file", RESULT_LIMIT_BYTES, ReportInputError)
        if too_deeply_nested(text):
            raise ReportInputError(f"{p} is nested too deeply to be a fit file (more than {NESTING_LIMIT} levels); write "
                                   "it with 'python -m analysis fit INPUT --json FIT.json'")
        doc = json.loads(text)
        poles = np.array([_cpx(q["pole"]) for q in doc["poles"]])
        fstd = np.array([np.nan if q.get("freq_hz_std") is None else q["freq_hz_std"] for q in doc["poles"]], float)
        zstd = np.array([np.nan if q.get("damping_std") is None else q["damping_std"] for q in doc["poles"]], float)
        R = np.zeros((frf.n_outputs, frf.n_references, poles.size), complex)
        for item in doc["residues"]:
            o, r = frf.outputs.index(item["output"]), frf.references.index(item["reference"])
            R[o, r] = [_cpx(v) for v in item["values"]]
        resid: dict[str, Any] = {}
        for key in ("upper_residual", "lower_residual"):
            if doc.get(key):
                a = np.zeros((frf.n_outputs, frf.n_references), complex)
                for item in doc[key]:
                    a[frf.outputs.index(item["output"]), frf.references.index(item["reference"])] = _cpx(item["value"])
                resid[key] = a
        model = ModalModel(poles=poles, residues=R, quantity=doc.get("quantity", frf.quantity),
                           residual_form=doc.get("residual_form", "physical"), outputs=frf.outputs,
                           references=frf.references, **resid)
        band = (float(doc["band"][0]), float(doc["band"][1]))
        check_fit_values(p, poles, R, band)
    except ReportInputError:
        raise
    except FileNotFoundError:
        raise ReportInputError(f"fit file {p} not found: check the path or leave --fit out to fit here") from None
    except (OSError, ValueError, KeyError, TypeError, IndexError) as exc:
        raise ReportInputError(f"{p} is not a fit of this input ({type(exc).__name__}: {exc}); write it with "
                               "'python -m analysis fit INPUT --json FIT.json' on the same INPUT") from None
    return FitData(model=model, model_raw=seen_through_window(model, frf.exp_window_tau_s), freq_hz_std=fstd,
                   damping_std=zstd, band=band, stab=_redo_stabilization(frf, doc.get("stabilization")), source=str(p),
                   warnings=tuple(doc.get("warnings", ()) or ()))


def check_fit_values(path: Path, poles: np.ndarray, residues: np.ndarray, band: tuple) -> None:
    """Refuse a fit file with a non-finite or unstable pole, a non-finite residue or band, naming the field."""
    from ..finite_checks import first_nonfinite

    for k, lam in enumerate(poles):
        if not np.isfinite(lam):
            raise ReportInputError(f"{path}: field poles[{k}].pole is {lam} (not a finite number); write the fit "
                                   "again with 'python -m analysis fit INPUT --json FIT.json'")
        if lam.real >= 0:
            raise ReportInputError(f"{path}: field poles[{k}].pole {lam} has a real part >= 0 (an unstable pole, "
                                   "negative damping); write the fit again with 'python -m analysis fit'")
    bad = first_nonfinite(residues)
    if bad is not None:
        raise ReportInputError(f"{path}: field residues (output {bad[0] + 1}, reference {bad[1] + 1}) values[{bad[2]}] "
                               "is not a finite number; write the fit again")
    if not all(np.isfinite(band)) or band[0] >= band[1]:
        raise ReportInputError(f"{path}: field band {list(band)} is not an increasing pair of finite Hz")


def _redo_stabilization(frf: FRFSet, info: dict | None) -> StabilizationResult | None:
    """The fit's stabilization diagram again, from the settings its JSON records (method, band,
    largest model size): a deterministic function of the FRFs. None when the JSON has none."""
    from ..stabilization import stabilization

    if not info:
        return None
    try:
        method = str(info["method"])
        return stabilization(frf, int(info["max_modes"]), method=method.split("+")[0],
                             band=(float(info["band"][0]), float(info["band"][1])), refine_lsfd="+lsfd" in method)
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        log.warning("no stabilization diagram: the fit file's stabilization settings cannot be used (%s)", exc)
        return None


def load_diagnosis(path: str | Path | None) -> dict | None:
    """A diagnosis written by ``python -m analysis diagnose --json`` (None stays None)."""
    if path is None:
        return None
    p = Path(path)
    try:
        doc = json.loads(read_bounded_text(p, "--diagnosis file", RESULT_LIMIT_BYTES, ReportInputError))
    except ReportInputError:
        raise
    except FileNotFoundError:
        raise ReportInputError(f"diagnosis file {p} not found: check the path") from None
    except (OSError, ValueError) as exc:
        raise ReportInputError(f"cannot read diagnosis {p}: {exc}; write it with 'python -m analysis diagnose "
                               "... --json DIAG.json'") from None
    if not isinstance(doc, dict) or "verdict" not in doc:
        raise ReportInputError(f"{p} is not a diagnosis document (no 'verdict'); write it with 'python -m analysis "
                               "diagnose ... --json DIAG.json'")
    return doc
