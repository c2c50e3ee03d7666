"""Turn measured impact time data from other systems into recordings.

Readers return an :class:`ImportedTest` (the file's float time histories in engineering units, one
array per hit); :func:`channel_roles` fixes the force and response channels and their point labels,
:func:`imported_hits` makes the :class:`analysis.hit.Hit` of each block (int16 counts, trigger,
channel roles) and :func:`write_imported` writes them as a schema-v1 recording with FRFs computed
by the same code path as a capture.

Formats
-------
* LabVIEW ``.lvm`` text (:func:`read_lvm`): header keys ``Separator``, ``Decimal_Separator``
  (``,`` or ``.``; not both a comma), each segment (= one hit) with its own channel header
  (``Channels``, ``Samples``, ``Y_Unit_Label``, ``Delta_X``) and a data table whose first column is
  the X value (possibly empty) and a trailing ``Comment`` column. Every segment must share the first
  one's ``Delta_X`` and column headings; columns in another order are matched by heading.
* DataPhysics SignalCalc ``.mat`` exports (:func:`read_dataphysics_mat`): ``X1..Xn`` raw blocks
  ``[t, value]`` (``t < 0`` is the pre-trigger), ``W1..Wn`` the analyser-windowed blocks,
  ``Sensitivity`` (mV/EU), ``Unit``.
* SEP005 JSON (:func:`read_sep005_test`): one ``group`` per hit, channels matched by name.
* numpy arrays (:func:`read_numpy`): ``.npy`` files, one per hit, shaped ``(n_ch, n)`` or
  ``(n, n_ch)``, with a description (JSON or TOML, :func:`load_description`)::

      sample_rate_hz = 25600          # or time_row = 0: a row holding the time (s)
      layout = "channels_first"       # or "samples_first"
      time_row = 0                    # optional: index of a time channel to drop
      [[channels]]                    # one per (remaining) channel, in order
      name = "force"; quantity = "force"; unit = "N"; point = "n:1:Z"
      [[channels]]
      name = "acc"; quantity = "acceleration"; unit = "m/s^2"; point = "n:2:Z"

Quantisation: each hit and channel gets ``eu_per_count = max|x| / 32767`` (a full-scale range
fitted to the hit); the quantisation error is below 2e-5 of the peak, far under the noise of any
hammer test. A hit where that is not so (one glitch far above the rest of a channel, which the
counts would turn into zeros) is refused (:func:`int16_rest_change`). ``volts_per_count =
eu_per_count * sensitivity`` when the sensitivity is known (NaN otherwise; infinite or zero
sensitivities are refused).

Nothing is stored altered: what cannot be read as the file holds it (complex time values,
channels that change order or sampling between hits, two different records for one channel) is
refused with :class:`ImportDataError` naming the file, the field and what to do.
"""
from __future__ import annotations

import logging
import math
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from analysis.finite_checks import describe_nonfinite
from analysis.hit import Hit
from analysis.input_limits import read_bounded_text, text_data_limit_bytes
from analysis.outputs import check_outputs
from analysis.points import PointLabelError, parse_point
from analysis.recording_writer import RecordingWriter, whole_recording
from analysis.spectra import WindowSettings

from .errors import ImportDataError, NonFiniteSamples
from .hitcheck import HitCheckSettings, check_hit
from .textdoc import read_document

__all__ = [
    "ImportDataError",
    "NonFiniteSamples",
    "drop_nonfinite_hits",
    "read_dropping_nonfinite",
    "ImportedTest",
    "source_files",
    "read_lvm",
    "read_dataphysics_mat",
    "read_sep005_test",
    "read_numpy",
    "load_description",
    "quantize",
    "detect_trigger",
    "write_imported",
    "imported_hits",
    "combine_imports",
    "ChannelRoles",
    "channel_roles",
]

log = logging.getLogger(__name__)

_UNIT_QUANTITY = {
    "n": ("force", "N"), "newton": ("force", "N"), "newtons": ("force", "N"), "lbf": ("force", "lbf"),
    "g": ("acceleration", "g"), "m/s^2": ("acceleration", "m/s^2"), "m/s2": ("acceleration", "m/s^2"),
    "m/s/s": ("acceleration", "m/s^2"), "m/s": ("velocity", "m/s"), "m": ("displacement", "m"),
    "v": ("voltage", "V"), "volt": ("voltage", "V"), "volts": ("voltage", "V"),
}


#: the highest sample rate accepted from a file (Hz); no impact-test analyser comes near it
MAX_SAMPLE_RATE_HZ = 1e7


@dataclass
class ImportedTest:
    """Time data of one test as read from its file(s): ``hits[k]`` is ``(n_ch, n)`` float in
    engineering units, one block per hit.

    fs_hz : sample rate (Hz).
    channels : dicts with name, quantity, unit, sensitivity (mV/EU or NaN), point.
    trigger_indices : per hit, the sample the windows start at (empty when the file has none: the
        trigger is then found on the force channel).
    source, meta : where the data came from and the reader's notes (format, ...).

    This is the file's content, not yet a set of :class:`analysis.hit.Hit`: the values are kept as
    read (a reader is checked against the file's numbers exactly, and several files are combined
    before anything is decided), and what makes a block a hit (which channel is the force, the
    responses' point labels, the trigger found on the force) may still be set by the user.
    :func:`imported_hits` makes the hits once those are fixed.
    """

    fs_hz: float
    channels: list
    hits: list
    trigger_indices: list
    source: str
    meta: dict = field(default_factory=dict)

    def force_channel(self) -> int:
        idx = [i for i, c in enumerate(self.channels) if c["quantity"] == "force"]
        if len(idx) != 1:
            raise ImportDataError(
                f"{self.source}: found {len(idx)} force channels ({[c['name'] for c in self.channels]}); "
                "name the hammer channel with --force-channel K (1-based)"
            )
        return idx[0]

    def response_channels(self) -> list[int]:
        f = self.force_channel()
        motion = [i for i, c in enumerate(self.channels)
                  if i != f and c["quantity"] in ("acceleration", "velocity", "displacement")]
        if not motion:
            raise ImportDataError(f"{self.source}: no response channel with a motion unit (g, m/s^2, m/s, m); "
                               "name them with --responses")
        return motion


def _unit_info(label: str) -> tuple[str, str]:
    key = label.strip().lower()
    return _UNIT_QUANTITY.get(key, ("unknown", label.strip()))


def _num(text: str, decimal: str) -> float:
    t = text.strip()
    if not t:
        return math.nan
    if decimal == ",":
        t = t.replace(",", ".")
    return float(t)


#: what malformed content makes the parsing code raise; readers turn it into ImportDataError
_MALFORMED = (KeyError, IndexError, ValueError, TypeError, ZeroDivisionError, OverflowError, AttributeError, EOFError)


def _checked(test: ImportedTest) -> ImportedTest:
    """``test`` after the consistency checks every importer's output must pass."""
    if not (isinstance(test.fs_hz, (int, float)) and math.isfinite(test.fs_hz) and test.fs_hz > 0):
        raise ImportDataError(f"{test.source}: the sample rate {test.fs_hz!r} Hz is not a positive number; check "
                              "the sample interval / rate in the file or the description")
    if test.fs_hz > MAX_SAMPLE_RATE_HZ:
        raise ImportDataError(f"{test.source}: the sample rate {test.fs_hz:.6g} Hz is above the largest accepted, "
                              f"{MAX_SAMPLE_RATE_HZ:g} Hz; check the sample interval (Delta_X) or rate in the file")
    if not test.hits:
        raise ImportDataError(f"{test.source}: no hit (no time data) found")
    n_ch = len(test.channels)
    for k, h in enumerate(test.hits):
        if h.ndim != 2 or h.shape[0] != n_ch or h.shape[1] < 2 or h.shape != test.hits[0].shape:
            raise ImportDataError(f"{test.source}: hit {k + 1} has shape {h.shape}; expected ({n_ch} channels, "
                                  f">= 2 samples), the same for every hit")
    _require_finite_hits(test)
    for k, c in enumerate(test.channels):
        s = c.get("sensitivity", math.nan) if isinstance(c, dict) else math.nan
        if not (isinstance(s, (int, float)) and (math.isnan(s) or (math.isfinite(s) and s != 0))):
            raise ImportDataError(f"{test.source}: channel {k + 1} ({c.get('name', '')}): the Sensitivity {s!r} "
                                  "(mV/EU) is not a finite nonzero number; correct it in the file or the description "
                                  "(or leave it out: unknown)")
    return test


def _nonfinite_hits(test: ImportedTest) -> list[tuple[int, int, str]]:
    """(hit, channel, description of the first bad sample) of every hit holding a non-finite sample."""
    out = []
    for k, h in enumerate(test.hits):
        for c in range(h.shape[0]):
            what = describe_nonfinite(h[c])
            if what is not None:
                out.append((k, c, what))
                break
    return out


def _require_finite_hits(test: ImportedTest) -> None:
    """Raise :class:`NonFiniteSamples` naming the file, hit, channel and first sample of a NaN/inf."""
    bad = _nonfinite_hits(test)
    if bad:
        k, c, what = bad[0]
        name = test.channels[c].get("name", f"ch{c + 1}") if c < len(test.channels) else f"ch{c + 1}"
        raise NonFiniteSamples(
            f"{test.source}: hit {k + 1}, channel {c + 1} ({name}): {what}; {len(bad)} of {len(test.hits)} hit(s) "
            "hold non-finite samples: fix the export, or import with --drop-nonfinite to leave those hits out", test)


def drop_nonfinite_hits(test: ImportedTest) -> tuple[ImportedTest, int]:
    """``test`` without the hits that hold a non-finite sample, and how many were dropped (a new
    test; ``test`` is not changed). Raises :class:`ImportDataError` when no hit is left."""
    bad = {k for k, _, _ in _nonfinite_hits(test)}
    keep = [k for k in range(len(test.hits)) if k not in bad]
    if not keep:
        raise ImportDataError(f"{test.source}: every hit ({len(test.hits)}) holds non-finite samples; nothing to import")
    triggers = [test.trigger_indices[k] for k in keep] if len(test.trigger_indices) == len(test.hits) else []
    meta = {**test.meta, "dropped_nonfinite_hits": len(bad)}
    return ImportedTest(test.fs_hz, test.channels, [test.hits[k] for k in keep], triggers, test.source, meta), len(bad)


def read_dropping_nonfinite(read: Callable[..., ImportedTest], *args: Any, drop: bool = False,
                            **kwargs: Any) -> ImportedTest:
    """``read(*args, **kwargs)``; with ``drop``, hits holding non-finite samples are left out (and
    counted in ``meta["dropped_nonfinite_hits"]``) instead of failing the import."""
    try:
        return read(*args, **kwargs)
    except NonFiniteSamples as exc:
        if not drop:
            raise
        if not isinstance(exc.test, ImportedTest):
            raise
        test, n = drop_nonfinite_hits(exc.test)
        log.warning("%s: left out %d hit(s) holding non-finite samples", test.source, n)
        return test


def _parsed(read: Callable[[], ImportedTest], what: str, advice: str) -> ImportedTest:
    """``read()`` checked (:func:`_checked`); a malformed input (any of ``_MALFORMED``) becomes one
    :class:`ImportDataError`: ``what`` (the problem), the parser's words, then ``advice``."""
    try:
        return _checked(read())
    except ImportDataError:
        raise
    except _MALFORMED as exc:
        raise ImportDataError(f"{what} ({type(exc).__name__}: {exc}); {advice}") from None


def read_lvm(path: str | Path) -> ImportedTest:
    """Read a LabVIEW measurement file; each segment is one hit (see module doc).

    Raises :class:`ImportDataError` for anything that is not a well-formed .lvm file."""
    return _parsed(lambda: _read_lvm(path), f"{path} is not a well-formed .lvm file",
                   "export it again from LabVIEW (Write To Measurement File)")


#: LabVIEW's names of the field separators (header key ``Separator``)
LVM_SEPARATORS = {"Tab": "\t", "Comma": ",", "Semicolon": ";", "Space": " "}


def _lvm_header_entry(line: str) -> tuple[str, str]:
    """(key, value) of an .lvm file-header line: the key ends at the first tab, comma, semicolon or
    space (LabVIEW writes the header with the file's own separator)."""
    m = re.match(r"([^\t,; ]*)[\t,; ]?(.*)", line)
    return (m.group(1), m.group(2)) if m else ("", "")


def _lvm_row(header: dict[str, list[str]], key: str, n_ch: int) -> list[str] | None:
    """The ``n_ch`` cells of a segment-header row (stripped, missing cells empty), None without the row."""
    if key not in header:
        return None
    cells = [c.strip() for c in header[key][:n_ch]]
    return cells + [""] * (n_ch - len(cells))


@dataclass
class _LvmSegment:
    """One .lvm segment as read: its header rows, column headings and data ``(n_ch, n)``."""

    header: dict[str, list[str]]
    headings: list[str]
    data: np.ndarray


def _lvm_delta_x(p: Path, k: int, seg: _LvmSegment, decimal: str) -> float:
    """The sample interval (s) of segment ``k`` (1-based): its channels' ``Delta_X``, which must agree."""
    cells = _lvm_row(seg.header, "Delta_X", seg.data.shape[0]) or []
    values = [_num(c, decimal) for c in cells if c]
    if not values:
        raise ImportDataError(f"{p}: segment {k} has no Delta_X (sample interval) in its header; export it again "
                              "from LabVIEW")
    if any(not math.isclose(v, values[0], rel_tol=1e-9) for v in values):
        raise ImportDataError(f"{p}: segment {k} gives its channels different Delta_X ({', '.join(cells)} s); one "
                              "hit has one sample rate: save the channels at one rate, or import them separately")
    return values[0]


def _lvm_in_first_order(p: Path, k: int, seg: _LvmSegment, first: _LvmSegment) -> np.ndarray:
    """Segment ``k``'s data with its columns in the order of segment 1, matched by heading; its
    ``Y_Unit_Label`` must then be segment 1's. Raises :class:`ImportDataError` when the segments
    hold other channels."""
    n_ch = first.data.shape[0]
    heads, first_heads = seg.headings, first.headings
    if heads == first_heads:
        order = list(range(n_ch))
    elif sorted(heads) == sorted(first_heads) and len(set(first_heads)) == n_ch:
        order = [heads.index(h) for h in first_heads]
    else:
        raise ImportDataError(f"{p}: segment {k} holds the columns {heads}, segment 1 {first_heads}; every segment "
                              "must hold the same channels: import the segments separately")
    units, first_units = _lvm_row(seg.header, "Y_Unit_Label", n_ch), _lvm_row(first.header, "Y_Unit_Label", n_ch)
    if units is not None and first_units is not None and [units[i] for i in order] != first_units:
        raise ImportDataError(f"{p}: segment {k} gives the columns {first_heads} the Y_Unit_Label "
                              f"{[units[i] for i in order]}, segment 1 {first_units}; a channel keeps its unit in "
                              "every segment: correct the labels, or import the segments separately")
    return seg.data[order]


def _lvm_file_header(p: Path, lines: list[str]) -> tuple[str, str, int]:
    """(field separator, decimal mark, index of the first line after it) from the file header of an
    .lvm; refuses a separator LabVIEW does not write and one that is also the decimal mark."""
    sep_name, decimal = "Tab", "."
    i = 0
    while i < len(lines) and not lines[i].startswith("***End_of_Header***"):
        key, val = _lvm_header_entry(lines[i])
        if key == "Separator":
            sep_name = val.strip(" \t,;")
            if sep_name not in LVM_SEPARATORS:
                raise ImportDataError(f"{p}: Separator {sep_name!r} is not one LabVIEW writes "
                                      f"({', '.join(LVM_SEPARATORS)}); correct the header line")
        elif key == "Decimal_Separator":
            decimal = val.strip(" \t")[:1] or "."
        elif key == "X_Columns" and val.strip(" \t,;") == "Multi":
            raise ImportDataError(f"{p}: X_Columns = Multi (one time column per channel) is not supported; "
                                  "save the file from LabVIEW with X_Columns One or No")
        i += 1
    sep = LVM_SEPARATORS[sep_name]
    if decimal == sep:
        raise ImportDataError(f"{p}: Separator is {sep_name} and Decimal_Separator is {decimal!r}: a number's "
                              "decimal mark cannot be told from the field separator; save the file again from "
                              "LabVIEW with another Separator (Tab) or the decimal point")
    i += 1
    return sep, decimal, i


def _read_lvm(path: str | Path) -> ImportedTest:
    p = Path(path)
    try:
        lines = read_bounded_text(p, ".lvm file", text_data_limit_bytes(), ImportDataError, "latin-1").splitlines()
    except OSError as exc:
        raise ImportDataError(f"cannot read {p}: {exc.strerror}") from None
    if not lines or not lines[0].startswith("LabVIEW Measurement"):
        raise ImportDataError(f"{p} is not a LabVIEW .lvm file (first line should be 'LabVIEW Measurement')")
    sep, decimal, i = _lvm_file_header(p, lines)
    segments: list[_LvmSegment] = []
    while i < len(lines):
        while i < len(lines) and not lines[i].startswith("Channels"):
            i += 1
        if i >= len(lines):
            break
        header: dict[str, list[str]] = {}
        while i < len(lines) and not lines[i].startswith("***End_of_Header***"):
            cells = lines[i].split(sep)
            header[cells[0]] = cells[1:]
            i += 1
        i += 1  # end of header
        if i >= len(lines) or not lines[i].startswith("X_Value"):
            raise ImportDataError(f"{p}: segment {len(segments) + 1} has no 'X_Value' column line after its header")
        n_ch = int(header["Channels"][0])
        headings = [h.strip() for h in lines[i].split(sep)[1:1 + n_ch]]
        headings += [""] * (n_ch - len(headings))
        i += 1
        rows = []
        while i < len(lines) and lines[i].strip() and not lines[i].startswith(("Channels", "***")):
            cells = lines[i].split(sep)
            try:
                rows.append([_num(c, decimal) for c in cells[1:1 + n_ch]])
            except ValueError:
                raise ImportDataError(f"{p}: line {i + 1} is not numeric: {lines[i][:60]!r}") from None
            i += 1
        data = np.asarray(rows, dtype=float).T
        k = len(segments) + 1
        if data.shape[0] != n_ch:
            raise ImportDataError(f"{p}: segment {k} has {data.shape[0]} data columns, header says {n_ch}")
        declared = {c for c in (_lvm_row(header, "Samples", n_ch) or []) if c}
        if declared and declared != {str(data.shape[1])}:
            raise ImportDataError(f"{p}: segment {k} holds {data.shape[1]} rows but its header says Samples "
                                  f"{', '.join(sorted(declared))}: the file is cut short or damaged; export it again")
        segments.append(_LvmSegment(header, headings, data))
    if not segments:
        raise ImportDataError(f"{p}: no data segment found")
    first = segments[0]
    dx = _lvm_delta_x(p, 1, first, decimal)
    labels = _lvm_row(first.header, "Y_Unit_Label", first.data.shape[0]) or []
    channels = []
    for k in range(first.data.shape[0]):
        q, unit = _unit_info(labels[k] if k < len(labels) else "")
        channels.append({"name": f"ch{k + 1}", "quantity": q, "unit": unit, "sensitivity": math.nan,
                         "point": f"n:{k + 1}:Z"})
    hits = [first.data]
    for k, seg in enumerate(segments[1:], start=2):
        if seg.data.shape != first.data.shape:
            raise ImportDataError(f"{p}: segment {k} has shape {seg.data.shape}, segment 1 {first.data.shape}")
        dx_k = _lvm_delta_x(p, k, seg, decimal)
        if not math.isclose(dx_k, dx, rel_tol=1e-9):
            raise ImportDataError(f"{p}: segment {k} has Delta_X {dx_k:.9g} s, segment 1 {dx:.9g} s; one recording "
                                  "has one sample rate: import the segments sampled at other rates separately")
        hits.append(_lvm_in_first_order(p, k, seg, first))
    test = ImportedTest(1.0 / dx, channels, hits, [], str(p), {"format": "lvm", "segments": len(hits)})
    return test


def read_dataphysics_mat(path: str | Path, windowed: bool = False) -> ImportedTest:
    """Read a DataPhysics SignalCalc ``.mat`` export: ``Xk`` (or ``Wk`` with ``windowed``) blocks
    of two columns (time s, value). Raises :class:`ImportDataError` for anything else."""
    p = Path(path)
    m = _loadmat_isolated(p)
    return _parsed(lambda: _dataphysics_from(p, m, windowed),
                   f"{p} does not hold DataPhysics time blocks of two columns (time, value)",
                   "export the time data again")


#: longest a damaged MATLAB file may keep the reader busy (s)
LOADMAT_TIMEOUT_S = 60.0


def _loadmat(path: str) -> dict:
    """``scipy.io.loadmat`` without the ``__header__``-style entries (runs in the child process)."""
    import scipy.io

    try:
        m = scipy.io.loadmat(path)
    except Exception as exc:  # scipy.io raises many types (struct, zlib, Unicode, MatReadError...) on damaged files
        raise ImportDataError(f"{path} is not a readable MATLAB file ({type(exc).__name__}: {exc})") from None
    return {k: v for k, v in m.items() if not k.startswith("__")}


def _loadmat_isolated(p: Path) -> dict:
    """``scipy.io.loadmat`` in a child process: some damaged .mat files crash scipy's reader with a
    segmentation fault (found by fuzzing, scipy 1.x ``_mio5.read_var_array``); in a child that
    becomes an :class:`ImportDataError` instead of killing the program. Bounded by
    :data:`LOADMAT_TIMEOUT_S`."""
    from analysis._isolated import call_isolated

    if not p.is_file():
        raise ImportDataError(f"{p} not found: check the path")
    return call_isolated(
        _loadmat, (str(p),), LOADMAT_TIMEOUT_S,
        crashed=lambda code: ImportDataError(f"{p} is not a readable MATLAB file (the reader crashed, exit code "
                                             f"{code}); the file is damaged: export it again"),
        timed_out=lambda: ImportDataError(f"{p}: reading the MATLAB file took over {LOADMAT_TIMEOUT_S:g} s; the "
                                          "file is damaged or not a MATLAB file"))


def _real_values(p: Path, what: str, value: Any) -> np.ndarray:
    """``value`` as a float array; complex values are accepted only with a zero imaginary part (else
    :class:`ImportDataError` naming ``what``: dropping the imaginary part would change the data)."""
    a = np.asarray(value)
    if np.iscomplexobj(a):
        imag = np.abs(np.imag(a))
        if np.any(imag != 0):
            worst = float(np.max(imag[imag != 0]))
            raise ImportDataError(f"{p}: {what} holds complex values (imaginary part up to {worst:.3g}); measured "
                                  "time data and sensitivities are real: export the time signals (not spectra) again")
        a = np.real(a)
    return np.asarray(a, float)


def _dataphysics_from(p: Path, m: dict, windowed: bool) -> ImportedTest:
    key = "W" if windowed else "X"
    ks = sorted(int(k[1:]) for k in m if re.fullmatch(key + r"\d+", k))
    if not ks:
        raise ImportDataError(f"{p} holds no '{key}1..{key}n' time blocks: is it a DataPhysics time export?")
    blocks = [_real_values(p, f"block {key}{k}", m[f"{key}{k}"]) for k in ks]
    for k, b in zip(ks, blocks):
        if b.ndim != 2 or b.shape[1] != 2 or b.shape[0] < 2 or b.shape != blocks[0].shape:
            raise ImportDataError(f"{p}: block {key}{k} has shape {b.shape}; each block must be (n >= 2, 2) columns "
                                  "time and value, all of the same length")
    t = blocks[0][:, 0]
    dt = np.diff(t)
    if not (np.all(np.isfinite(t)) and np.all(dt > 0)):
        raise ImportDataError(f"{p}: the time column of {key}{ks[0]} is not strictly increasing")
    data = np.stack([b[:, 1] for b in blocks])
    fs = 1.0 / float(np.median(np.diff(t)))
    sens = _real_values(p, "Sensitivity", m.get("Sensitivity", np.full(len(ks), np.nan))).ravel()
    units = [str(u).strip() for u in np.asarray(m.get("Unit", [""] * len(ks))).ravel()]
    channels = []
    for j, k in enumerate(ks):
        q, unit = _unit_info(units[j] if j < len(units) else "")
        channels.append({"name": f"ch{k}", "quantity": q, "unit": unit,
                         "sensitivity": float(sens[j]) if j < sens.size else math.nan, "point": f"n:{k}:Z"})
    trig = int(np.searchsorted(t, 0.0 - 1e-12 * abs(t[1] - t[0])))
    meta = {"format": "dataphysics-mat", "windowed": windowed}
    return ImportedTest(fs, channels, [data], [trig], str(p), meta)


def load_description(path: str | Path) -> dict:
    """Read a JSON or TOML channel description (see module doc)."""
    p = Path(path)
    out = read_document(p, "description (--describe)", ImportDataError)
    if not isinstance(out, dict):
        raise ImportDataError(f"description {p} must be a JSON object / TOML table with 'channels', got "
                              f"{type(out).__name__}")
    return out


def read_numpy(paths: Sequence[str | Path], description: dict) -> ImportedTest:
    """Read ``.npy`` hits (one file per hit) described by ``description`` (see module doc).

    Raises :class:`ImportDataError` for unreadable arrays or a description that does not fit them."""
    if not isinstance(description, dict):
        raise ImportDataError(f"the description must be a mapping with 'channels', got {type(description).__name__}")
    return _parsed(lambda: _read_numpy(paths, description), "the arrays do not fit the description",
                   "check channels, layout, time_row and sample_rate_hz")


def _read_numpy(paths: Sequence[str | Path], description: dict) -> ImportedTest:
    if not paths:
        raise ImportDataError("no .npy file given")
    chans = description.get("channels")
    if not isinstance(chans, list) or not chans:
        raise ImportDataError("the description needs a 'channels' list (name, quantity or unit, point per channel)")
    layout = description.get("layout", "channels_first")
    if layout not in ("channels_first", "samples_first"):
        raise ImportDataError(f"description layout {layout!r} must be 'channels_first' or 'samples_first'")
    time_row = description.get("time_row")
    fs = description.get("sample_rate_hz")
    hits = []
    for path in paths:
        try:
            a = _load_npy(Path(path))
        except ImportDataError:
            raise
        except (OSError, ValueError, EOFError) as exc:
            raise ImportDataError(f"cannot read {path} as a numpy array ({type(exc).__name__}: {exc})") from None
        if not isinstance(a, np.ndarray) or a.dtype.kind not in "biuf":
            raise ImportDataError(f"{path}: expected a real numeric array, got "
                                  f"{getattr(a, 'dtype', type(a).__name__)}")
        a = np.asarray(a, float)
        if a.ndim != 2:
            raise ImportDataError(f"{path}: expected a 2-D array (channels x samples), got shape {a.shape}")
        if layout == "samples_first":
            a = a.T
        if time_row is not None:
            t = a[int(time_row)]
            if fs is None:
                if t.size < 2:
                    raise ImportDataError(f"{path}: the time row has {t.size} sample(s); at least 2 are needed for "
                                          "the sample rate")
                fs = 1.0 / float(np.median(np.diff(t)))
            a = np.delete(a, int(time_row), axis=0)
        if a.shape[0] != len(chans):
            raise ImportDataError(f"{path}: {a.shape[0]} channels but the description lists {len(chans)}")
        hits.append(a)
    if fs is None or not float(fs) > 0:
        raise ImportDataError("the description needs sample_rate_hz (or time_row, a row of times in s)")
    channels = []
    for k, c in enumerate(chans):
        unit = str(c.get("unit", ""))
        q = c.get("quantity") or _unit_info(unit)[0]
        channels.append({"name": str(c.get("name", f"ch{k + 1}")), "quantity": q, "unit": unit or _unit_info(q)[1],
                         "sensitivity": float(c.get("sensitivity", math.nan)), "point": str(c.get("point", f"n:{k + 1}:Z"))})
    for h in hits[1:]:
        if h.shape != hits[0].shape:
            raise ImportDataError(f"hits have different shapes {hits[0].shape} and {h.shape}; import them separately")
    return ImportedTest(float(fs), channels, hits, [], ", ".join(str(p) for p in paths),
                        {"format": "numpy", "sources": [str(p) for p in paths]})


def _load_npy(path: Path) -> np.ndarray:
    """``np.load`` after checking that the array the header claims fits in the file (a damaged or
    hostile header can claim terabytes); raises ImportDataError naming both sizes."""
    with path.open("rb") as fh:
        try:
            version = np.lib.format.read_magic(fh)
            shape, _, dtype = (np.lib.format.read_array_header_1_0(fh) if version == (1, 0)
                               else np.lib.format.read_array_header_2_0(fh))
        except (ValueError, EOFError, SyntaxError):
            return np.load(str(path), allow_pickle=False)  # let numpy name the problem
        claimed = float(np.prod(shape, dtype=float)) * dtype.itemsize
        available = path.stat().st_size - fh.tell()
    if claimed > available:
        raise ImportDataError(f"{path}: the header claims an array of shape {shape} ({claimed:.3g} bytes) but the "
                              f"file holds {available} bytes of data; the file is damaged or cut short")
    return np.load(str(path), allow_pickle=False)


def quantize(data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """int16 counts and EU per count per channel for ``data[n_ch, n]`` (full scale = max |x|)."""
    d = np.asarray(data, float)
    peak = np.max(np.abs(d), axis=1)
    eu = np.where(peak > 0, peak / 32767.0, 1.0)
    counts = np.clip(np.rint(d / eu[:, None]), -32768, 32767).astype(np.int16)
    return counts, eu


#: the part of a channel :func:`int16_rest_change` looks at: the samples below this fraction of its peak
INT16_REST_FRACTION = 1e-2
#: the largest rms change 16-bit counts may make to that part of a channel, relative to its rms; real
#: hammer tests stay near 0.02 (the rest spans tens of counts), a glitch 1e5 times the signal gives 1
INT16_MAX_REST_CHANGE = 0.1


def int16_rest_change(data: np.ndarray, counts: np.ndarray, eu_per_count: np.ndarray) -> np.ndarray:
    """Per channel of ``data[n_ch, n]`` stored as ``counts * eu_per_count`` (:func:`quantize`): the
    rms of the rounding error over the samples below :data:`INT16_REST_FRACTION` of the channel's
    peak, relative to their rms (0 where those samples are all zero or there are none). Near 1 means
    the counts lose that part of the channel: one sample (a glitch) sets a scale the rest is below."""
    d = np.asarray(data, float)
    out = np.zeros(d.shape[0])
    for c in range(d.shape[0]):
        ax = np.abs(d[c])
        rest = ax < INT16_REST_FRACTION * np.max(ax)
        scale = float(np.max(ax[rest])) if np.any(rest) else 0.0
        if scale > 0:  # the rounding error never exceeds the sample: both ratios stay <= 1 (no overflow)
            err = (counts[c, rest] * eu_per_count[c] - d[c, rest]) / scale
            out[c] = float(np.sqrt(np.mean(err ** 2) / np.mean((d[c, rest] / scale) ** 2)))
    return out


#: the smallest channel peak :func:`quantize` scales (a smaller one would need a subnormal step)
INT16_MIN_PEAK = float(np.finfo(float).tiny) * 32767.0
#: the largest channel peak :func:`quantize` scales (counts * step must stay a finite float)
INT16_MAX_PEAK = float(np.finfo(float).max) / 2


def _quantized(test: ImportedTest, k: int, data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`quantize` of hit ``k``, refused (:class:`ImportDataError` naming the hit, channel and
    sample) when the 16-bit counts would not keep a channel: its peak too small or too large to
    scale, or part of it lost beside a far larger sample (:func:`int16_rest_change`)."""
    peaks = np.max(np.abs(data), axis=1)
    for c in np.flatnonzero(((peaks > 0) & (peaks < INT16_MIN_PEAK)) | (peaks > INT16_MAX_PEAK)):
        raise ImportDataError(f"{test.source}: hit {k + 1}, channel {c + 1} ({test.channels[c].get('name', '')}): "
                              f"its largest sample is {peaks[c]:.3g}, outside what 16-bit samples can be scaled to "
                              f"({INT16_MIN_PEAK:.3g} to {INT16_MAX_PEAK:.3g}); check the units of the file")
    counts, eu = quantize(data)
    change = int16_rest_change(data, counts, eu)
    for c in np.flatnonzero(change > INT16_MAX_REST_CHANGE):
        x = np.abs(data[c])
        i = int(np.argmax(x))
        rest = x < INT16_REST_FRACTION * x[i]
        name = test.channels[c].get("name", f"ch{c + 1}")
        raise ImportDataError(
            f"{test.source}: hit {k + 1}, channel {c + 1} ({name}): sample {i + 1} is {data[c, i]:.3g} while "
            f"{int(np.sum(rest))} of its {x.size} samples stay within +-{np.max(x[rest]):.3g}; the recording's "
            f"16-bit samples scaled to that peak (step {eu[c]:.3g}) would change those by {change[c]:.0%} rms: "
            "remove the glitch from the file (or cut the block short of it) and import again")
    return counts, eu


def detect_trigger(force: np.ndarray, level: float = 0.1) -> int:
    """First sample where |force| reaches ``level`` times its peak (the window origin of an import)."""
    f = np.abs(np.asarray(force, float))
    return int(np.argmax(f >= level * f.max())) if f.max() > 0 else 0


def read_sep005_test(path: str | Path) -> ImportedTest:
    """An SEP005 JSON file (:mod:`analysis.sep005`) as a test: each ``group`` of channels is one hit
    (no groups: the whole file is one hit); channel quantities from the SEP005 codes ('f' force,
    'a' acceleration, ...), points from the ``point`` key (else the channel name), trigger samples
    from ``trigger_index`` when every channel of a hit has it (else found on the force).
    Raises :class:`ImportDataError` for anything else."""
    return _parsed(lambda: _read_sep005_test(path), f"{path} is not an SEP005 test impactlab can import",
                   "check the groups, fs and trigger_index of its channels")


#: the keys of an SEP005 channel that must be the same, for one channel name, in every hit
_SEP005_SAME_IN_EVERY_HIT = ("unit_str", "quantity", "point")


def _sep005_hit(path: str | Path, g: str, chans: list[dict], first_g: str, first: list[dict]) -> list[dict]:
    """The channels of hit (group) ``g`` in the order of the first hit's, matched by name; refuses
    other names, a name given twice, another unit, quantity or point under one name, channels of
    different lengths."""
    names, first_names = [str(c["name"]) for c in chans], [str(c["name"]) for c in first]
    if chans is first:
        ordered = chans
    else:
        if len(set(names)) != len(names):
            twice = sorted({n for n in names if names.count(n) > 1})
            raise ImportDataError(f"{path}: hit {g!r} names more than one channel {twice}; the hits' channels are "
                                  "matched by name: give each channel of a hit its own name")
        if sorted(names) != sorted(first_names):
            raise ImportDataError(f"{path}: hit {g!r} has the channels {names}, hit {first_g!r} {first_names}; "
                                  "every hit needs the same channel names: correct the names, or import the hits "
                                  "separately")
        by_name = {str(c["name"]): c for c in chans}
        ordered = [by_name[n] for n in first_names]
    for c, c1 in zip(ordered, first):
        for key in _SEP005_SAME_IN_EVERY_HIT:
            if str(c.get(key, "")) != str(c1.get(key, "")):
                raise ImportDataError(f"{path}: channel {c['name']!r} has {key} {c.get(key)!r} in hit {g!r} but "
                                      f"{c1.get(key)!r} in hit {first_g!r}; a channel keeps its {key} in every hit: "
                                      "correct the file, or import the hits separately")
        if c["data"].size != ordered[0]["data"].size:
            raise ImportDataError(f"{path}: hit {g!r}: channel {c['name']!r} holds {c['data'].size} samples, "
                                  f"{ordered[0]['name']!r} {ordered[0]['data'].size}; the channels of a hit are "
                                  "sampled together: export them whole")
    return ordered


def _read_sep005_test(path: str | Path) -> ImportedTest:
    from analysis.sep005 import QUANTITY_CODES, SEP005Error, read_sep005

    try:
        channels = read_sep005(path)
    except SEP005Error as exc:
        raise ImportDataError(str(exc)) from None
    by_code = {v: k for k, v in QUANTITY_CODES.items()}
    groups: dict[str, list[dict]] = {}
    for ch in channels:
        groups.setdefault(str(ch.get("group", "")), []).append(ch)
    first_g, first = next(iter(groups.items()))
    fs = float(first[0]["fs"])
    hits, triggers = [], []
    for g, chans in groups.items():
        if len(chans) != len(first) or any(float(c["fs"]) != fs for c in chans):
            raise ImportDataError(f"{path}: hit {g!r} has {len(chans)} channels at {[c['fs'] for c in chans]} Hz; "
                                  f"every hit needs the {len(first)} channels of the first at {fs:g} Hz")
        chans = _sep005_hit(path, g, chans, first_g, first)  # the first hit is checked against itself
        hits.append(np.vstack([c["data"] for c in chans]))
        if all("trigger_index" in c for c in chans):
            marks = {int(c["trigger_index"]) for c in chans}
            if len(marks) != 1:
                raise ImportDataError(f"{path}: hit {g!r}: its channels give different trigger_index values "
                                      f"{sorted(marks)}; a hit has one trigger: correct the file")
            triggers.append(marks.pop())
    meta_chans = []
    for c in first:
        name = str(c["name"])
        quantity = by_code.get(str(c.get("quantity", "")), None)
        if quantity is None:
            quantity, _ = _unit_info(str(c["unit_str"]))
        meta_chans.append({"name": name, "quantity": quantity, "unit": str(c["unit_str"]),
                           "sensitivity": float("nan"), "point": str(c.get("point", name))})
    return ImportedTest(fs, meta_chans, hits, triggers if len(triggers) == len(hits) else [], str(path),
                        {"format": "SEP005"})


@dataclass(frozen=True)
class ChannelRoles:
    """What an import makes of the file's channels: the channel table (quantities and point labels
    as given or relabelled), the force channel and the response channels (0-based)."""

    channels: list
    force_channel: int
    response_channels: list

    @property
    def reference(self) -> str:
        return str(self.channels[self.force_channel]["point"])

    @property
    def outputs(self) -> list:
        return [str(self.channels[i]["point"]) for i in self.response_channels]

    def describe(self) -> list:
        """One line per used channel: ``force: channel 2 'Force' [N] -> n:1:Z`` (1-based numbers)."""
        def line(role: str, i: int) -> str:
            c = self.channels[i]
            return f"{role}: channel {i + 1} {c.get('name', '')!r} [{c.get('unit', '')}] -> {c['point']}"
        return [line("force", self.force_channel)] + [line("response", i) for i in self.response_channels]


def channel_roles(
    test: ImportedTest,
    *,
    reference: str | None = None,
    outputs: Sequence[str] | None = None,
    force_channel: int | None = None,
    response_channels: Sequence[int] | None = None,
) -> ChannelRoles:
    """The force and response channels of ``test`` and their point labels: from the file, or as
    given (``force_channel``/``response_channels`` 0-based; ``reference``/``outputs`` relabel them)."""
    chans = [dict(c) for c in test.channels]
    if force_channel is not None:
        if not 0 <= force_channel < len(chans):
            raise ImportDataError(f"force channel {force_channel + 1} does not exist (1..{len(chans)})")
        for i, c in enumerate(chans):
            if c["quantity"] == "force" and i != force_channel:
                c["quantity"] = "unknown"
        chans[force_channel]["quantity"] = "force"
        if chans[force_channel]["unit"] in ("", "?", "V"):
            chans[force_channel]["unit"] = "N"
    tmp = ImportedTest(test.fs_hz, chans, test.hits, test.trigger_indices, test.source, test.meta)
    fch = tmp.force_channel()
    rch = list(response_channels) if response_channels is not None else tmp.response_channels()
    for i in rch:
        if not 0 <= i < len(chans) or i == fch:
            raise ImportDataError(f"response channel {i + 1} does not exist or is the force channel")
        if chans[i]["quantity"] not in ("acceleration", "velocity", "displacement"):
            chans[i]["quantity"] = "acceleration"
    try:
        if reference is not None:
            chans[fch]["point"] = str(parse_point(reference))
        if outputs is not None:
            if len(outputs) != len(rch):
                raise ImportDataError(f"{len(outputs)} output labels for {len(rch)} response channels")
            for i, lab in zip(rch, outputs):
                chans[i]["point"] = str(parse_point(lab))
    except PointLabelError as exc:
        raise ImportDataError(str(exc)) from None
    for c in chans:
        p = parse_point(c["point"])
        c.setdefault("direction", p.direction)
        c["direction"] = p.direction
    return ChannelRoles(chans, fch, rch)


#: what a channel of every file of one import must share (:func:`combine_imports`)
_SAME_IN_EVERY_FILE = ("name", "quantity", "unit", "point", "sensitivity")


def _same_value(a: Any, b: Any) -> bool:
    """``a == b``, NaN equal to NaN (an unknown sensitivity)."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return bool(a == b)


def combine_imports(tests: Sequence[ImportedTest]) -> ImportedTest:
    """One test from several files read alike (e.g. one .lvm per hit): the hits in the order given.
    The files must share the sample rate, the block shape and the channels (name, quantity, unit,
    point, sensitivity, in order); the files' trigger samples are kept
    for the leading hits that all have one (the others' triggers are found on the force). Raises
    :class:`ImportDataError` naming the file that differs."""
    if not tests:
        raise ImportDataError("no file to import")
    first = tests[0]
    hits: list = list(first.hits)
    triggers: list = list(first.trigger_indices)
    for t in tests[1:]:
        if t.fs_hz != first.fs_hz or t.hits[0].shape != first.hits[0].shape:
            raise ImportDataError(f"{t.source} differs in sample rate or block size from {first.source}; "
                                  "import the files separately")
        for c, (a, b) in enumerate(zip(t.channels, first.channels)):
            differ = [key for key in _SAME_IN_EVERY_FILE if not _same_value(a.get(key), b.get(key))]
            if differ:
                raise ImportDataError(f"{t.source}: channel {c + 1} has {differ[0]} {a.get(differ[0])!r}, in "
                                      f"{first.source} {b.get(differ[0])!r}; the files of one import hold the same "
                                      "channels in the same order: import the files separately")
        triggers = triggers + list(t.trigger_indices) if len(triggers) == len(hits) else []
        hits += t.hits
    meta = dict(first.meta)
    meta["sources"] = [src for t in tests for src in source_files(t)]
    return ImportedTest(first.fs_hz, first.channels, hits, triggers, first.source, meta)


def source_files(test: ImportedTest) -> list[str]:
    """The files ``test`` was read from (``meta["sources"]`` when several, else ``source``)."""
    return [str(p) for p in test.meta.get("sources", ())] or [test.source]


def imported_hits(test: ImportedTest, roles: ChannelRoles) -> list[Hit]:
    """The hits of ``test`` with the channel ``roles`` (:func:`channel_roles`), not yet checked:
    each block quantised to int16 counts (:func:`quantize`), its trigger from the file or found on
    the force (:func:`detect_trigger`), ``volts_per_count`` from the sensitivities (NaN unknown),
    ``sequence`` the import order, ``timestamp`` the time of the import (s since the epoch).
    Raises :class:`ImportDataError` naming the hit, channel and sample when the 16-bit counts would
    lose part of a channel (:func:`int16_rest_change`, e.g. a glitch far above the rest)."""
    chans, fch, rch = roles.channels, roles.force_channel, roles.response_channels
    ref, outs = roles.reference, roles.outputs
    names = tuple(str(c["name"]) for c in chans)
    sens = np.array([c["sensitivity"] for c in chans], float)
    hits = []
    for k, data in enumerate(test.hits):
        trig = test.trigger_indices[k] if k < len(test.trigger_indices) else detect_trigger(data[fch])
        counts, eu = _quantized(test, k, data)
        hits.append(Hit(counts=counts, eu_per_count=eu, volts_per_count=eu * sens * 1e-3, sample_rate_hz=test.fs_hz,
                        trigger_index=trig, force_channel=fch, response_channels=rch, point=ref, reference=ref,
                        outputs=outs, measurement=0, channel_names=names, timestamp=time.time(), sequence=k))
    return hits


def write_imported(
    test: ImportedTest,
    out: str | Path,
    *,
    windows: WindowSettings = WindowSettings(),
    reference: str | None = None,
    outputs: Sequence[str] | None = None,
    force_channel: int | None = None,
    response_channels: Sequence[int] | None = None,
    check_settings: HitCheckSettings = HitCheckSettings(),
    overwrite: bool = False,
    roles: ChannelRoles | None = None,
) -> list:
    """Write ``test`` as a recording (one measurement) and return its averages.

    Refused before anything is written (:func:`analysis.outputs.check_outputs`) when ``out`` is
    one of the files ``test`` was read from or a recording a live writer holds.

    Hits failing the automatic checks (double hits) are stored as rejected with the reason.
    ``reference``/``outputs`` relabel the force and response channels (point labels); ``roles``,
    when given, are the channel roles already made by :func:`channel_roles` (the four relabelling
    arguments are then not used).
    """
    from .session import average_recorded_hits  # session imports this module's siblings; keep it local

    check_outputs([out], source_files(test))  # never onto a file it was read from, nor one a live writer holds
    if roles is None:
        roles = channel_roles(test, reference=reference, outputs=outputs, force_channel=force_channel,
                              response_channels=response_channels)
    chans, ref = roles.channels, roles.reference
    setup = {"sample_rate_hz": test.fs_hz, "block_size": int(test.hits[0].shape[1]),
             "channels": chans, "imported_from": test.source, "format": test.meta.get("format")}
    instrument = {"vendor": "imported", "model": str(test.meta.get("format", "")), "source": test.source}
    hits = imported_hits(test, roles)  # refuses what 16-bit counts cannot hold before the file is opened
    with whole_recording(out, overwrite) as tmp, RecordingWriter(
            tmp, instrument=instrument, setup=setup, channels=chans, windows=windows,
            plan={"mode": "imported", "points": [ref]}, overwrite=True) as w:
        w.log("INFO", f"imported {len(test.hits)} hit(s) from {test.source}; " + "; ".join(roles.describe()))
        kept: list[Hit] = []
        for k, hit in enumerate(hits):
            chk = check_hit(hit.force, hit.sample_rate_hz, [False] * len(chans), list(hit.channel_names),
                            check_settings)
            hit = hit.with_verdict(chk.verdict.accept is not False, chk.verdict.reasons, chk.to_dict())
            hit = hit.with_index(w.write_hit(hit))
            if not hit.accepted:
                w.log("INFO", f"hit {k} rejected: {'; '.join(chk.verdict.reasons)}")
            else:
                kept.append(hit)
        if not kept:
            raise ImportDataError(f"{test.source}: every hit failed the checks (double hits); nothing to average")
        averages = average_recorded_hits(kept, windows, chans)
        for avg in averages:
            avg.write(w)
    return averages
