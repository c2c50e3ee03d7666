"""Turn an analyser's own FRF exports (H1 and coherence it computed) into recordings.

A time-data import (:mod:`acquisition.importers`) recomputes the FRFs from the hits; an FRF export
holds no hits, only what the analyser averaged. Its recording has no ``/hits``; each reference
point is one FRF group with ``freq_hz``, ``H1``, ``coherence``, the number of averages when the
file says it (0 = not known) and the point labels (``docs/recording-format.md``).

Formats (each one row of :data:`acquisition.importers_registry.IMPORT_FORMATS`; the SignalCalc ASCII
export's parser is :mod:`acquisition.frf_importers_ascii`):

* ``signalcalc-frf``: DataPhysics SignalCalc ``.mat``: ``H{r}_{k}`` (two complex columns
  [f Hz, H]) and ``C{r}_{k}`` ([f Hz, coherence]) from reference channel ``r`` to channel ``k``;
  ``Unit`` and ``ChanNum`` per channel. The export does not store the number of averages nor the
  analyser's windows. Labels ``n:{r}:Z`` and ``n:{k}:Z`` unless ``--reference``/``--outputs``.
* ``testlab-frf``: LMS Test.Lab MATLAB structs (``x_values``, ``y_values``, ``function_record``),
  as the UNESP BERT dataset has them: ``...FRF.mat`` with the FRF structs and, beside it,
  ``...Coherence.mat`` with the ``Coherence`` struct. The values are MKS; they are stored in the
  struct's display unit (its ``label``, via ``unit_transformation.factor``). Channel labels
  ``Acc1:+X`` become point labels ``Acc:1:X``.
* ``signalcalc-ascii``: one FRF per ``Hxy*.txt`` file, no coherence (:mod:`acquisition.frf_importers_ascii`).
* ``uff58``: Universal File Format dataset 58 (:func:`analysis.uff.read_uff58`): FRF records
  (function type 4) and their ordinary coherence (type 6), matched by node and direction; the
  number of averages from ID line 2 (``... averages N ...``) when every reference's records state
  it; one import set per reference.

Anything that cannot be stored as read (a missing coherence, axes that differ, a unit that is
not a motion per excitation, non-finite values, a coherence outside [0, 1]) is refused with one
:class:`ImportDataError` line naming the file and the variable.
"""
from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from analysis.frf import FRFSet
from analysis.points import PointLabelError, parse_point
from analysis.recording_writer import FRFPoint, RecordingWriter, whole_recording
from analysis.spectra import WindowSettings, same_window_tau, tau_from_end_fraction

from .errors import ImportDataError

__all__ = ["ImportedFRFs", "read_signalcalc_frf", "read_testlab_frf", "read_uff58_frfs", "signalcalc_detect",
           "testlab_detect", "mat_variables", "relabel", "combine_frf_imports", "write_frf_recording",
           "COHERENCE_TOLERANCE", "PointMapRow", "read_point_map", "with_analyser_window", "point_of_testlab_label"]

#: how far a stored coherence may stray outside [0, 1] (rounding of the export) before it is refused
COHERENCE_TOLERANCE = 1e-6

#: response unit (numerator of the FRF unit, lower case) -> FRF quantity
_MOTION_QUANTITY = {"g": "accelerance", "m/s^2": "accelerance", "m/s2": "accelerance", "m/s/s": "accelerance",
                    "m/s": "mobility", "m": "receptance"}


@dataclass
class ImportedFRFs:
    """FRFs read from analyser exports: ``sets`` one :class:`FRFSet` per reference (one reference
    each, with coherence), ``n_averages`` per set (None: the file does not say), ``source`` the
    files, ``fmt`` the format name."""

    sets: list
    n_averages: list
    source: str
    fmt: str
    meta: dict = field(default_factory=dict)


def _fail(path: Path, what: str) -> ImportDataError:
    return ImportDataError(f"{path}: {what}")


def _motion_quantity(path: Path, var: str, unit: str) -> str:
    """The FRF quantity of ``unit`` (``g/N``, ``(m/s)/V``...) from its numerator; refused otherwise."""
    num = unit.split("/", 1)[0].strip() if not unit.startswith("(") else unit[1:unit.find(")")].strip()
    q = _MOTION_QUANTITY.get(num.lower())
    if q is None:
        raise _fail(path, f"{var}: unit {unit!r} is not a motion (g, m/s^2, m/s, m) per excitation; only "
                          "accelerance, mobility and receptance FRFs can be imported")
    return q


def _real(path: Path, var: str, x: np.ndarray, refused: str) -> np.ndarray:
    """``x`` as real numbers: a complex array with a zero imaginary part read exactly, any other complex
    array refused with ``refused`` (what the values are, what to do)."""
    x = np.asarray(x)
    if np.iscomplexobj(x):
        if np.any(x.imag != 0):
            raise _fail(path, f"{var}: {refused}")
        x = x.real
    return x.astype(float)


def _coherence(path: Path, var: str, c: np.ndarray) -> np.ndarray:
    c = _real(path, var, c, "the coherence is complex; export the coherence magnitude")
    if not np.all(np.isfinite(c)):
        raise _fail(path, f"{var}: the coherence holds NaN or infinite values; export it again")
    if c.min() < -COHERENCE_TOLERANCE or c.max() > 1 + COHERENCE_TOLERANCE:
        raise _fail(path, f"{var}: coherence values from {c.min():.6g} to {c.max():.6g} lie outside [0, 1]; "
                          "is it the coherence variable?")
    return np.clip(c, 0.0, 1.0)


def _finite_frf(path: Path, var: str, h: np.ndarray) -> np.ndarray:
    h = np.asarray(h).astype(complex)
    if not np.all(np.isfinite(h)):
        k = int(np.argmin(np.isfinite(h).ravel()))
        raise _fail(path, f"{var}: value {k} is {h.ravel()[k]}; the FRF holds NaN or infinite values: export it again")
    return h


def _check_axis(path: Path, var: str, f: np.ndarray) -> np.ndarray:
    f = _real(path, var, f, "the frequency column is complex")
    if f.size < 2 or not np.all(np.isfinite(f)) or np.any(np.diff(f) <= 0) or f[0] < 0:
        raise _fail(path, f"{var}: the frequencies are not a non-negative, strictly increasing axis")
    return f


# -- loading --------------------------------------------------------------------------------------

def _variables(path: Path) -> dict:
    """The MATLAB variables of ``path`` as loaded (in a child process, see
    :func:`acquisition.importers_parse.loadmat_isolated`)."""
    from .importers_parse import loadmat_isolated

    return loadmat_isolated(path)


def _whos(path: str) -> dict:
    """Name -> MATLAB class of the variables of ``path`` (runs in the child process)."""
    import scipy.io

    try:
        return {name: cls for name, _, cls in scipy.io.whosmat(path)}
    except Exception as exc:  # scipy.io raises many types on damaged files
        raise ImportDataError(f"{path} is not a readable MATLAB file ({type(exc).__name__}: {exc})") from None


def mat_variables(path: str | Path) -> dict:
    """Name -> class of a MATLAB file's variables, read in a child process (a damaged file may crash
    scipy's reader); raises :class:`ImportDataError` for an unreadable file."""
    from analysis._isolated import call_isolated

    from .importers_parse import LOADMAT_TIMEOUT_S

    p = Path(path)
    if not p.is_file():
        raise ImportDataError(f"{p} not found: check the path")
    result: dict = call_isolated(
        _whos, (str(p),), LOADMAT_TIMEOUT_S,
        crashed=lambda code: ImportDataError(f"{p} is not a readable MATLAB file (the reader crashed, exit code "
                                             f"{code}); export it again"),
        timed_out=lambda: ImportDataError(f"{p}: listing the MATLAB variables took over {LOADMAT_TIMEOUT_S:g} s; "
                                          "the file is damaged or not a MATLAB file"))
    return result


# -- DataPhysics SignalCalc ---------------------------------------------------------------------------

_SC_H = re.compile(r"H(\d+)_(\d+)")


def signalcalc_detect(whos: dict) -> bool:
    """A SignalCalc FRF export: ``H{r}_{k}`` variables (a file that also holds time blocks ``X{k}``
    is read as time data first, unless ``--format signalcalc-frf`` or an FRF option says otherwise:
    the registry's row order)."""
    return any(_SC_H.fullmatch(n) for n in whos)


def _channel_units(path: Path, m: dict) -> dict:
    """Channel number -> unit string from ``Unit`` (and ``ChanNum`` when present)."""
    if "Unit" not in m:
        raise _fail(path, "no 'Unit' variable (the channels' engineering units); export with the channel table")
    units = [str(u).strip() for u in np.asarray(m["Unit"]).ravel()]
    nums = (np.asarray(m["ChanNum"], float).ravel().astype(int).tolist() if "ChanNum" in m
            else list(range(1, len(units) + 1)))
    if len(nums) != len(units):
        raise _fail(path, f"'ChanNum' lists {len(nums)} channels but 'Unit' {len(units)}")
    return dict(zip(nums, units))


#: what malformed content makes the parsing code raise; the readers turn it into ImportDataError
_MALFORMED = (KeyError, IndexError, ValueError, TypeError, AttributeError, OverflowError, ZeroDivisionError)


def _guarded(read: Callable[[Path, Sequence[str] | None], ImportedFRFs], path: Path,
             variables: Sequence[str] | None, what: str) -> ImportedFRFs:
    """``read(path, variables)``; content the checks did not foresee (a field of another type) becomes
    one :class:`ImportDataError` naming the file, ``what`` it should be, and the parser's words."""
    try:
        return read(path, variables)
    except ImportDataError:
        raise
    except _MALFORMED as exc:
        raise ImportDataError(f"{path} is not a well-formed {what} ({type(exc).__name__}: {exc}); export it "
                              "again") from None


def read_signalcalc_frf(path: Path, variables: Sequence[str] | None = None) -> ImportedFRFs:
    """Read the H1 and coherence of a DataPhysics SignalCalc ``.mat`` export (see module doc):
    one :class:`FRFSet` per reference channel ``r``; ``variables`` (e.g. ``H1_2,H1_3``) limits the
    FRFs read. Raises :class:`ImportDataError` naming the file and variable for anything else."""
    return _guarded(_read_signalcalc_frf, Path(path), variables, "SignalCalc FRF export")


def _chosen(path: Path, names: list[str], variables: Sequence[str] | None, what: str) -> list[str]:
    """The FRFs ``names`` of the file ``path`` limited to the ``variables`` asked for (all when none are);
    an asked-for name the file lacks is an :class:`ImportDataError` naming ``what`` it is and what it holds."""
    if not variables:
        return names
    missing = [v for v in variables if v not in names]
    if missing:
        raise _fail(path, f"no {what} {', '.join(missing)} (it holds {', '.join(names) or 'none'})")
    return [n for n in names if n in variables]


def _read_signalcalc_frf(path: Path, variables: Sequence[str] | None = None) -> ImportedFRFs:
    p = Path(path)
    m = _variables(p)
    names = sorted((n for n in m if _SC_H.fullmatch(n)), key=lambda n: tuple(int(x) for x in _SC_H.findall(n)[0]))
    names = _chosen(p, names, variables, "FRF variable")
    if not names:
        raise _fail(p, "holds no 'H{r}_{k}' FRF variables: is it a SignalCalc FRF export (save H1 and coherence)?")
    units = _channel_units(p, m)
    by_ref: dict[int, list[tuple[int, np.ndarray, np.ndarray]]] = {}
    freq: np.ndarray | None = None
    for name in names:
        r, k = (int(x) for x in _SC_H.fullmatch(name).groups())  # type: ignore[union-attr]
        cname = f"C{r}_{k}"
        if cname not in m:
            raise _fail(p, f"{name} has no coherence {cname}; export the coherence with the FRF")
        h, c = np.asarray(m[name]), np.asarray(m[cname])
        for var, a in ((name, h), (cname, c)):
            if a.ndim != 2 or a.shape[1] != 2 or a.shape[0] < 2:
                raise _fail(p, f"{var} has shape {a.shape}; expected two columns (frequency Hz, value)")
        f = _check_axis(p, name, h[:, 0])
        if freq is None:
            freq = f
        elif f.shape != freq.shape or not np.allclose(f, freq, rtol=1e-9, atol=0):
            raise _fail(p, f"{name}: its frequency axis differs from {names[0]}'s; export the FRFs alike")
        fc = _check_axis(p, cname, c[:, 0])
        if fc.shape != f.shape or not np.allclose(fc, f, rtol=1e-9, atol=0):
            raise _fail(p, f"{cname}: its frequency axis differs from {name}'s")
        by_ref.setdefault(r, []).append((k, _finite_frf(p, name, h[:, 1]), _coherence(p, cname, c[:, 1])))
    assert freq is not None
    fs, record_s, pretrigger_s = _signalcalc_timing(p, m)
    sets = []
    for r, rows in by_ref.items():
        ref_unit = units.get(r)
        if ref_unit is None:
            raise _fail(p, f"H{r}_*: reference channel {r} is not in the channel table ('ChanNum'/'Unit')")
        unit_set = {units.get(k) for k, _, _ in rows}
        if None in unit_set or len(unit_set) != 1:
            raise _fail(p, f"H{r}_*: the response channels have units {sorted(str(u) for u in unit_set)}; a recording "
                           "holds one unit: import them separately (--variables)")
        unit = f"{unit_set.pop()}/{ref_unit}"
        q = _motion_quantity(p, f"H{r}_{rows[0][0]}", unit)
        sets.append(FRFSet(freq_hz=freq, H=np.stack([h for _, h, _ in rows])[:, None, :], quantity=q,
                           outputs=tuple(f"n:{k}:Z" for k, _, _ in rows), references=(f"n:{r}:Z",), unit=unit,
                           coherence=np.stack([c for _, _, c in rows])[:, None, :], sample_rate_hz=fs,
                           record_s=record_s, pretrigger_s=pretrigger_s,
                           meta={"estimator": "H1", "source": str(p)}))
    return ImportedFRFs(sets, [None] * len(sets), str(p), "signalcalc-frf",
                        {"variables": names})


def _signalcalc_timing(p: Path, m: dict) -> tuple[float | None, float | None, float | None]:
    """Sample rate (Hz), record length (s) and pre-trigger (s) from the export's time block ``X1``
    when it has one ([t, value], t < 0 before the trigger); (None, None, None) otherwise."""
    x = m.get("X1")
    if x is None:
        return None, None, None
    t = np.asarray(x, float)
    if t.ndim != 2 or t.shape[1] != 2 or t.shape[0] < 2 or not np.all(np.diff(t[:, 0]) > 0):
        raise _fail(p, f"X1 has shape {t.shape} or a time column that is not increasing; expected (time s, value)")
    dt = float(np.median(np.diff(t[:, 0])))
    return 1.0 / dt, t.shape[0] * dt, max(0.0, -float(t[0, 0]))


# -- LMS Test.Lab structs (UNESP BERT) --------------------------------------------------------------

_TL_FIELDS = ("x_values", "y_values", "function_record")
_TL_LABEL = re.compile(r"^\s*([A-Za-z_]+?)(\d*)\s*:\s*([+-]?)([XYZxyz])\s*$")


def testlab_detect(whos: dict) -> bool:
    """A Test.Lab FRF export: struct variables whose name starts with ``FRF``."""
    return any(n.startswith("FRF") and cls == "struct" for n, cls in whos.items())


def _field(path: Path, var: str, s: Any, *names: str) -> Any:
    """``s[names[0]][0, 0][names[1]]...`` of a loaded MATLAB struct; a missing field is refused."""
    cur = s
    for name in names:
        try:
            cur = cur[name]
            while isinstance(cur, np.ndarray) and cur.dtype == object and cur.shape == (1, 1):
                cur = cur[0, 0]
            if isinstance(cur, np.ndarray) and cur.dtype.names and cur.shape == (1, 1):
                cur = cur[0, 0]
        except (KeyError, ValueError, IndexError, TypeError):
            raise _fail(path, f"{var}: no field {'.'.join(names)}; is it a Test.Lab function struct?") from None
    return cur


def _strings(a: Any) -> list:
    return [str(np.asarray(x).ravel()[0]) if np.asarray(x).size else "" for x in np.asarray(a, dtype=object).ravel()]


def _numbers(a: Any) -> list:
    return [float(np.asarray(x, float).ravel()[0]) for x in np.asarray(a, dtype=object).ravel()]


def point_of_testlab_label(label: str) -> str:
    """The point label of a Test.Lab channel label: ``Acc1:+X`` -> ``Acc:1:X``, ``Shaker:-X`` ->
    ``Shaker:1:-X`` (no number: node 1). Raises :class:`ImportDataError` for another form."""
    m = _TL_LABEL.match(label)
    if not m:
        raise ImportDataError(f"channel label {label!r} is not NAME[NUMBER]:[+-]X|Y|Z; give the point labels "
                              "with --reference and --outputs")
    name, num, sign, axis = m.groups()
    return str(parse_point(f"{name}:{num or 1}:{'-' if sign == '-' else ''}{axis.upper()}"))


@dataclass
class _TLFunction:
    var: str
    freq: np.ndarray
    values: np.ndarray  # (n_ch, n_freq) in the display unit
    unit: str
    primary: list
    reference: list
    averages: list


def _testlab_function(path: Path, var: str, s: Any, kind: str) -> _TLFunction:
    x = _field(path, var, s, "x_values")
    try:
        start = float(np.asarray(_field(path, var, x, "start_value"), float).ravel()[0])
        inc = float(np.asarray(_field(path, var, x, "increment"), float).ravel()[0])
        n = int(np.asarray(_field(path, var, x, "number_of_values"), float).ravel()[0])
    except (ValueError, IndexError, TypeError):
        raise _fail(path, f"{var}: x_values start_value/increment/number_of_values are not numbers") from None
    if not (math.isfinite(start) and math.isfinite(inc) and inc > 0 and n >= 2 and start >= 0):
        raise _fail(path, f"{var}: the frequency axis (start {start:g} Hz, increment {inc:g} Hz, {n} values) is not "
                          "a non-negative increasing axis")
    y = _field(path, var, s, "y_values")
    vals = np.asarray(_field(path, var, y, "values"))
    if vals.dtype.kind not in "biufc" or vals.ndim != 2 or n not in vals.shape:
        raise _fail(path, f"{var}: y_values.values has shape {vals.shape} (type {vals.dtype}); expected "
                          f"{n} values per channel")
    vals = vals if vals.shape[1] == n and vals.shape[0] != n else vals.T
    q = _field(path, var, y, "quantity")
    unit = _strings(_field(path, var, q, "label"))[0] if q is not None else ""
    try:
        factor = float(np.asarray(_field(path, var, q, "unit_transformation", "factor"), float).ravel()[0])
        offset = float(np.asarray(_field(path, var, q, "unit_transformation", "offset"), float).ravel()[0])
    except (ValueError, IndexError, TypeError):
        raise _fail(path, f"{var}: y_values.quantity.unit_transformation is not numbers") from None
    if not (math.isfinite(factor) and factor > 0 and offset == 0):
        raise _fail(path, f"{var}: unit transformation factor {factor:g}, offset {offset:g}: cannot store the values "
                          f"in {unit!r} as read")
    fr = _field(path, var, s, "function_record")
    primary = _strings(_field(path, var, fr, "primary_channel", "label"))
    reference = _strings(_field(path, var, fr, "reference_channel", "label"))
    averages = _numbers(_field(path, var, fr, "average", "nr_of_averages"))
    ftype = _strings(_field(path, var, fr, "type"))[0]
    if ftype != kind:
        raise _fail(path, f"{var}: function type {ftype!r}, expected {kind!r}")
    if kind == "FRF":
        methods = set(_strings(_field(path, var, fr, "frf", "method")))
        if methods != {"H1"}:
            raise _fail(path, f"{var}: FRF estimator {sorted(methods)}; only H1 FRFs are imported")
    n_ch = vals.shape[0]
    if not (len(primary) == len(reference) == len(averages) == n_ch):
        raise _fail(path, f"{var}: {n_ch} channels of values but {len(primary)} primary / {len(reference)} reference "
                          f"channel labels and {len(averages)} average counts")
    freq = start + inc * np.arange(n)
    values = vals * factor if kind == "FRF" else vals
    return _TLFunction(var, freq, values, unit, primary, reference, averages)


def _coherence_path(path: Path) -> Path:
    stem = path.stem
    if not stem.endswith("FRF"):
        raise _fail(path, "a Test.Lab FRF file's name ends in 'FRF' (e.g. Run__FRF.mat) so that its coherence file "
                          "(Run__Coherence.mat) can be found beside it")
    return path.with_name(stem[: -len("FRF")] + "Coherence" + path.suffix)


def read_testlab_frf(path: Path, variables: Sequence[str] | None = None) -> ImportedFRFs:
    """Read the H1 FRF structs of a Test.Lab ``...FRF.mat`` and their coherence from the
    ``...Coherence.mat`` beside it (see module doc); ``variables`` names the FRF structs to read
    (default: every ``FRF*`` struct; they must share one quantity). Raises :class:`ImportDataError`."""
    return _guarded(_read_testlab_frf, Path(path), variables, "Test.Lab FRF export")


def _read_testlab_frf(path: Path, variables: Sequence[str] | None = None) -> ImportedFRFs:
    p = Path(path)
    m = _variables(p)
    structs = [n for n in m if n.startswith("FRF") and isinstance(m[n], np.ndarray) and m[n].dtype.names]
    structs = _chosen(p, structs, variables, "FRF struct")
    if not structs:
        raise _fail(p, "holds no 'FRF*' Test.Lab function structs")
    funcs = [_testlab_function(p, n, m[n], "FRF") for n in structs]
    quantities = {f.var: _motion_quantity(p, f.var, f.unit) for f in funcs}
    if len(set(quantities.values())) > 1 or len({f.unit for f in funcs}) > 1:
        listing = ", ".join(f"{f.var} ({quantities[f.var]}, {f.unit})" for f in funcs)
        raise _fail(p, f"holds FRFs of different units: {listing}; a recording holds one: choose with "
                       "--variables NAME[,NAME]")
    cp = _coherence_path(p)
    if not cp.is_file():
        raise _fail(p, f"its coherence file {cp.name} is not beside it; export the coherence too")
    cm = _variables(cp)
    cvars = [n for n in cm if n.startswith("Coherence") and isinstance(cm[n], np.ndarray) and cm[n].dtype.names]
    if not cvars:
        raise _fail(cp, "holds no 'Coherence' Test.Lab struct")
    cohs = [_testlab_function(cp, n, cm[n], "Coherence") for n in cvars]
    coh_by = {(pr, rf): (c, i) for c in cohs for i, (pr, rf) in enumerate(zip(c.primary, c.reference))}
    freq = funcs[0].freq
    rows: dict[str, list[tuple[str, np.ndarray, np.ndarray, float]]] = {}
    for f in funcs:
        if f.freq.shape != freq.shape or not np.allclose(f.freq, freq, rtol=1e-9, atol=0):
            raise _fail(p, f"{f.var}: its frequency axis differs from {funcs[0].var}'s")
        for i, (pr, rf) in enumerate(zip(f.primary, f.reference)):
            hit = coh_by.get((pr, rf))
            if hit is None:
                raise _fail(cp, f"no coherence of {pr}/{rf} (FRF {f.var}); export the coherence of every FRF")
            c, j = hit
            if c.freq.shape != freq.shape or not np.allclose(c.freq, freq, rtol=1e-9, atol=0):
                raise _fail(cp, f"{c.var}: its frequency axis differs from {f.var}'s")
            rows.setdefault(rf, []).append((pr, _finite_frf(p, f"{f.var}[{pr}]", f.values[i]),
                                            _coherence(cp, f"{c.var}[{pr}]", c.values[j]), f.averages[i]))
    sets, n_avg = [], []
    unit, q = funcs[0].unit, quantities[funcs[0].var]
    for rf, rr in rows.items():
        avgs = {a for *_, a in rr}
        if len(avgs) != 1 or not (next(iter(avgs)) >= 1):
            raise _fail(p, f"reference {rf}: the FRFs give {sorted(avgs)} averages; one count per reference is stored")
        sets.append(FRFSet(freq_hz=freq, H=np.stack([h for _, h, _, _ in rr])[:, None, :], quantity=q,
                           outputs=tuple(point_of_testlab_label(pr) for pr, *_ in rr), references=(point_of_testlab_label(rf),),
                           unit=unit, coherence=np.stack([c for _, _, c, _ in rr])[:, None, :],
                           record_s=1.0 / float(freq[1] - freq[0]), meta={"estimator": "H1", "source": str(p)}))
        n_avg.append(int(next(iter(avgs))))
    return ImportedFRFs(sets, n_avg, str(p), "testlab-frf", {"variables": structs, "coherence_file": str(cp)})


def read_uff58_frfs(path: Path, variables: Sequence[str] | None = None) -> ImportedFRFs:
    """The FRFs and coherence of a UFF 58 file (see module doc), one set per reference with the
    outputs it was measured at. A file with coherence records must have one for every FRF (else
    refused, naming the FRF); without any, the import holds no coherence. ``variables`` is not used.
    Raises :class:`ImportDataError` naming the file for a damaged or incomplete file."""
    return _guarded(_read_uff58_frfs, Path(path), variables, "UFF 58 file")


def _read_uff58_frfs(p: Path, variables: Sequence[str] | None = None) -> ImportedFRFs:
    from analysis.uff import UFFError, read_uff58

    try:
        s = read_uff58(p)
    except UFFError as exc:
        raise ImportDataError(str(exc)) from None
    if s.quantity not in _MOTION_QUANTITY.values():
        raise _fail(p, f"its FRFs are {s.quantity}; only accelerance, mobility and receptance FRFs can be imported")
    averages = s.meta.get("n_averages")
    sets, n_avg = [], []
    for j, ref in enumerate(s.references):
        rows = [i for i in range(s.n_outputs) if np.all(np.isfinite(s.H[i, j]))]
        coh = None
        if s.coherence is not None:
            missing = [s.outputs[i] for i in rows if not np.all(np.isfinite(s.coherence[i, j]))]
            if missing:
                raise _fail(p, f"the FRF of {missing[0]}/{ref} has no coherence record while other FRFs have one; "
                               "export the coherence of every FRF (or of none)")
            coh = np.stack([_coherence(p, f"coherence {s.outputs[i]}/{ref}", s.coherence[i, j]) for i in rows])[:, None]
        sets.append(FRFSet(freq_hz=s.freq_hz, H=s.H[rows, j][:, None, :], quantity=s.quantity,
                           outputs=tuple(s.outputs[i] for i in rows), references=(ref,), unit=s.unit, coherence=coh,
                           exp_window_tau_s=s.exp_window_tau_s,
                           meta={"source": str(p), **({"estimator": s.meta["estimator"]} if "estimator" in s.meta
                                                      else {})}))
        n_avg.append(int(averages[j]) if isinstance(averages, list) and averages[j] else None)
    return ImportedFRFs(sets, n_avg, str(p), "uff58", {})


def relabel(imp: ImportedFRFs, reference: str | None, outputs: Sequence[str] | None) -> ImportedFRFs:
    """``imp`` with the reference and output point labels given (``--reference``, ``--outputs``);
    with a label given, the import must hold one reference / as many outputs."""
    try:
        ref = str(parse_point(reference)) if reference is not None else None
        outs = tuple(str(parse_point(o)) for o in outputs) if outputs is not None else None
    except PointLabelError as exc:
        raise ImportDataError(str(exc)) from None
    sets = []
    for s in imp.sets:
        if ref is not None and len(imp.sets) != 1:
            raise ImportDataError(f"{imp.source} holds FRFs of {len(imp.sets)} references; --reference labels one")
        if outs is not None and len(outs) != s.n_outputs:
            raise ImportDataError(f"{len(outs)} output labels for {s.n_outputs} FRFs of reference "
                                  f"{s.references[0]} in {imp.source}")
        sets.append(FRFSet(freq_hz=s.freq_hz, H=s.H, quantity=s.quantity, outputs=outs or s.outputs,
                           references=(ref,) if ref else s.references, unit=s.unit, coherence=s.coherence,
                           exp_window_tau_s=s.exp_window_tau_s, meta=dict(s.meta), sample_rate_hz=s.sample_rate_hz,
                           record_s=s.record_s, pretrigger_s=s.pretrigger_s))
    return ImportedFRFs(sets, list(imp.n_averages), imp.source, imp.fmt, dict(imp.meta))


def with_analyser_window(imp: ImportedFRFs, window: WindowSettings) -> ImportedFRFs:
    """``imp`` with the exponential window the analyser applied to the responses recorded on every
    FRF (``--analyser-exp-window``): the fit removes its decay, ``1/tau``, from the damping. A window
    given by its end value needs the record length and pre-trigger the export states (the time block
    of a SignalCalc file); raises :class:`ImportDataError` when they are not known."""
    sets = []
    for s in imp.sets:
        tau = window.exp_window_tau_s
        if tau is None and window.exp_window_end_fraction is not None:
            if s.record_s is None or s.pretrigger_s is None:
                raise ImportDataError(f"{imp.source}: the export does not state its record length and pre-trigger, "
                                      "so a window given by its end value cannot be turned into a time constant; give "
                                      "--analyser-exp-window as tau in s")
            tau = tau_from_end_fraction(window.exp_window_end_fraction, s.record_s - s.pretrigger_s)
        sets.append(FRFSet(freq_hz=s.freq_hz, H=s.H, quantity=s.quantity, outputs=s.outputs, references=s.references,
                           unit=s.unit, coherence=s.coherence, exp_window_tau_s=tau, meta=dict(s.meta),
                           sample_rate_hz=s.sample_rate_hz, record_s=s.record_s, pretrigger_s=s.pretrigger_s))
    return ImportedFRFs(sets, list(imp.n_averages), imp.source, imp.fmt, dict(imp.meta))


def combine_frf_imports(imports: Sequence[ImportedFRFs]) -> ImportedFRFs:
    """One import from several files (a roving test): their reference sets in order. The files must
    share the frequency axis, unit and sample rate, and each reference must come from one file."""
    if not imports:
        raise ImportDataError("no file to import")
    first = imports[0].sets[0]
    sets: list[FRFSet] = []
    n_avg: list = []
    seen: dict[str, str] = {}
    for imp in imports:
        for s, n in zip(imp.sets, imp.n_averages):
            if (s.freq_hz.shape != first.freq_hz.shape or not np.allclose(s.freq_hz, first.freq_hz)
                    or s.unit != first.unit or s.sample_rate_hz != first.sample_rate_hz
                    or not same_window_tau(s.exp_window_tau_s, first.exp_window_tau_s)):
                raise ImportDataError(f"{imp.source} differs in frequency axis, unit, sample rate or window from "
                                      f"{imports[0].source}; import the files separately")
            r = s.references[0]
            if r in seen:
                raise ImportDataError(f"{imp.source} and {seen[r]} both hold FRFs of reference {r}; give each file "
                                      "its reference point (--points MAP.csv)")
            seen[r] = imp.source
            sets.append(s)
            n_avg.append(n)
    return ImportedFRFs(sets, n_avg, ", ".join(i.source for i in imports), imports[0].fmt, dict(imports[0].meta))


@dataclass(frozen=True)
class PointMapRow:
    """One row of a ``--points`` map: the file, the reference point it holds the FRFs of, and the
    output points of its response channels in file order (None: as in the file or ``--outputs``)."""

    file: Path
    reference: str
    outputs: tuple | None


def read_point_map(path: str | Path) -> list[PointMapRow]:
    """Read a roving test's point map: CSV with a header ``file,reference[,outputs]``, one row per
    file (``file`` relative to the map's folder; ``outputs`` the response channels' point labels,
    separated by spaces or ``;``). Raises :class:`ImportDataError` naming the map and the line."""
    import csv

    from analysis.input_limits import read_bounded_text, text_data_limit_bytes

    p = Path(path)
    try:
        text = read_bounded_text(p, "point map (--points)", text_data_limit_bytes(), ImportDataError)
    except OSError as exc:
        raise ImportDataError(f"cannot read the point map {p}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise ImportDataError(f"{p}: the point map is not UTF-8 text; save it as CSV") from None
    rows = list(csv.reader(text.splitlines()))
    header = [h.strip().lower() for h in rows[0]] if rows else []
    if header[:2] != ["file", "reference"] or any(h not in ("file", "reference", "outputs") for h in header):
        raise ImportDataError(f"{p}: the point map's first line must be the header file,reference[,outputs]; "
                              f"got {rows[0] if rows else 'an empty file'}")
    out: list[PointMapRow] = []
    seen: set = set()
    for line, cells in enumerate(rows[1:], 2):
        if not any(c.strip() for c in cells):
            continue
        if len(cells) != len(header):
            raise ImportDataError(f"{p}, line {line}: {len(cells)} fields, the header has {len(header)}")
        rec = dict(zip(header, (c.strip() for c in cells)))
        file = p.parent / rec["file"]
        if file in seen:
            raise ImportDataError(f"{p}, line {line}: {rec['file']} is listed twice")
        seen.add(file)
        try:
            ref = str(parse_point(rec["reference"]))
            outs = (tuple(str(parse_point(o)) for o in re.split(r"[;\s]+", rec["outputs"]) if o)
                    if rec.get("outputs") else None)
        except PointLabelError as exc:
            raise ImportDataError(f"{p}, line {line}: {exc}") from None
        out.append(PointMapRow(file, ref, outs))
    if not out:
        raise ImportDataError(f"{p}: the point map lists no file")
    return out


def write_frf_recording(imp: ImportedFRFs, out: str | Path, overwrite: bool = False) -> None:
    """Write ``imp`` as a recording without hits: one FRF group per reference (H1, coherence,
    number of averages, point labels), written whole beside ``out`` and renamed over it."""
    first = imp.sets[0]
    ref_unit = first.unit.rsplit("/", 1)[-1].strip()
    resp_unit = first.unit.rsplit("/", 1)[0].strip().strip("()")
    chans = [{"name": "reference", "point": first.references[0], "direction": parse_point(first.references[0]).direction,
              "quantity": "force" if ref_unit in ("N", "lbf") else "voltage", "unit": ref_unit}]
    for o in dict.fromkeys(o for s in imp.sets for o in s.outputs):
        chans.append({"name": o, "point": o, "direction": parse_point(o).direction,
                      "quantity": {"accelerance": "acceleration", "mobility": "velocity",
                                   "receptance": "displacement"}[first.quantity], "unit": resp_unit})
    setup = {"imported_from": imp.source, "format": imp.fmt, "frequency_lines": int(first.freq_hz.size),
             "line_spacing_hz": float(first.line_spacing_hz), "channels": chans, **imp.meta}
    if first.sample_rate_hz is not None:
        setup["sample_rate_hz"] = first.sample_rate_hz
    refs = [s.references[0] for s in imp.sets]
    instrument = {"vendor": "imported", "model": imp.fmt, "source": imp.source}
    with whole_recording(out, overwrite) as tmp, RecordingWriter(
            tmp, instrument=instrument, setup=setup, channels=chans,
            windows=WindowSettings(exp_window_tau_s=first.exp_window_tau_s),
            plan={"mode": "imported", "points": refs}, overwrite=True, journal=False) as w:
        w.log("INFO", f"imported the analyser's FRFs of {len(refs)} reference(s) from {imp.source} ({imp.fmt})")
        for j, (s, n) in enumerate(zip(imp.sets, imp.n_averages)):
            w.write_frf(FRFPoint(j, s.references[0]), s, None, n_averages=n,
                        windows=WindowSettings(exp_window_tau_s=s.exp_window_tau_s))
