"""Parsers of measured time data: each format's file -> :class:`~acquisition.importers_data.ImportedTest`.

One reader per format (the formats and their fields: :mod:`acquisition.importers`):
:func:`read_lvm` (LabVIEW text), :func:`read_dataphysics_mat` (DataPhysics SignalCalc time blocks),
:func:`read_sep005_test` (SEP005 JSON), :func:`read_numpy` (``.npy`` arrays with a description,
:func:`load_description`). A reader only parses: the values are kept as the file holds them and
checked (:func:`acquisition.importers_data._parsed`); anything malformed is one
:class:`ImportDataError` line naming the file and what to do.
"""
from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from analysis.input_limits import read_bounded_text, text_data_limit_bytes

from .errors import ImportDataError
from .importers_data import ImportedTest, _parsed, unit_info
from .textdoc import read_document

__all__ = ["read_lvm", "read_dataphysics_mat", "dataphysics_detect", "read_csv_table", "read_hdf5_dataset",
           "read_described", "read_sep005_test", "read_numpy", "load_description",
           "LVM_SEPARATORS", "LOADMAT_TIMEOUT_S", "loadmat_isolated"]

def _num(text: str, decimal: str) -> float:
    t = text.strip()
    if not t:
        return math.nan
    if decimal == ",":
        t = t.replace(",", ".")
    return float(t)


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
        q, unit = unit_info(labels[k] if k < len(labels) else "")
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


def dataphysics_detect(whos: dict) -> bool:
    """A DataPhysics time export: time blocks ``X{k}`` among a MATLAB file's variables (name -> class)."""
    return any(re.fullmatch(r"X\d+", n) for n in whos)


def read_dataphysics_mat(path: str | Path, windowed: bool = False) -> ImportedTest:
    """Read a DataPhysics SignalCalc ``.mat`` export: ``Xk`` (or ``Wk`` with ``windowed``) blocks
    of two columns (time s, value). Raises :class:`ImportDataError` for anything else."""
    p = Path(path)
    m = loadmat_isolated(p)
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


def loadmat_isolated(p: Path) -> dict:
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
        q, unit = unit_info(units[j] if j < len(units) else "")
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
    return read_described(paths, description, "numpy")


def read_csv_table(paths: Sequence[str | Path], description: dict) -> ImportedTest:
    """Read CSV tables of time data (a heading row, one column per signal, one row per sample) with
    the ``columns`` of ``description`` naming, by heading, the columns that are its ``channels``
    (the others, e.g. a sample-rate column, are left out). Raises :class:`ImportDataError`."""
    return read_described(paths, description, "csv")


def read_hdf5_dataset(paths: Sequence[str | Path], description: dict) -> ImportedTest:
    """Read the 2-D HDF5 dataset ``description["dataset"]`` (e.g. ``InputTask/data``) of each file;
    ``sample_rate_hz`` may name a dataset of the file holding it. Raises :class:`ImportDataError`."""
    return read_described(paths, description, "hdf5")


#: the array loaders of :func:`read_described`: format -> (what the files are, loader)
_ARRAY_FORMATS = ("numpy", "csv", "hdf5")


def read_described(paths: Sequence[str | Path], description: dict, fmt: str) -> ImportedTest:
    """Time data in files of arrays (``fmt``: numpy ``.npy``, ``csv`` tables, ``hdf5`` datasets)
    described by ``description`` (the channels, the layout, the sample rate; for a continuous
    excitation the block length: see the module doc of :mod:`acquisition.importers`)."""
    if not isinstance(description, dict):
        raise ImportDataError(f"the description must be a mapping with 'channels', got {type(description).__name__}")
    if fmt not in _ARRAY_FORMATS:
        raise ValueError(f"unknown array format {fmt!r}")
    return _parsed(lambda: _read_described(paths, description, fmt), "the arrays do not fit the description",
                   "check channels, columns, layout, time_row, sample_rate_hz and block_samples")


def _load_array(path: Path, description: dict, fmt: str) -> tuple[np.ndarray, float | None]:
    """The 2-D array of one file as the description's ``layout`` has it, and the sample rate (Hz)
    when the file states it (an HDF5 dataset named by ``sample_rate_hz``)."""
    if fmt == "numpy":
        return _load_npy(path), None
    if fmt == "csv":
        return _load_csv(path, description), None
    return _load_hdf5(path, description)


def _load_csv(path: Path, description: dict) -> np.ndarray:
    """The ``columns`` (headings) of a CSV table as a (samples, columns) array."""
    import csv

    columns = description.get("columns")
    if not isinstance(columns, list) or not columns or not all(isinstance(c, str) for c in columns):
        raise ImportDataError("a CSV import needs 'columns' in the description: the headings of the columns to "
                              "import, in the order of its channels")
    try:
        text = read_bounded_text(path, "CSV file", text_data_limit_bytes(), ImportDataError, "utf-8")
    except OSError as exc:
        raise ImportDataError(f"cannot read {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise ImportDataError(f"{path} is not UTF-8 text; save it as CSV") from None
    rows = csv.reader(text.splitlines())
    heading = [h.strip() for h in next(rows, [])]
    missing = [c for c in columns if c not in heading]
    if missing:
        raise ImportDataError(f"{path}: no column {', '.join(repr(c) for c in missing)} (its headings: {heading}); "
                              "correct 'columns' in the description")
    index = [heading.index(c) for c in columns]
    values = []
    for line, cells in enumerate(rows, 2):
        if not any(c.strip() for c in cells):
            continue
        try:
            values.append([float(cells[i]) for i in index])
        except (ValueError, IndexError):
            raise ImportDataError(f"{path}, line {line}: the columns {columns} do not all hold a number; the file is "
                                  "damaged or cut short: export it again") from None
    if layout := description.get("layout"):
        if layout != "samples_first":
            raise ImportDataError(f"a CSV table holds one sample per row: layout {layout!r} must be 'samples_first' "
                                  "or left out")
    return np.asarray(values, float).reshape(-1, len(columns))


def _load_hdf5(path: Path, description: dict) -> tuple[np.ndarray, float | None]:
    """The dataset ``description["dataset"]`` of an HDF5 file, and its sample rate when
    ``sample_rate_hz`` names a dataset of the file."""
    import h5py

    from analysis.work_limits import memory_budget_bytes

    name = description.get("dataset")
    if not isinstance(name, str) or not name:
        raise ImportDataError("an HDF5 import needs 'dataset' in the description: the path of the 2-D dataset "
                              "of time data (e.g. InputTask/data)")
    try:
        with h5py.File(path, "r") as f:
            ds = f.get(name)
            if not isinstance(ds, h5py.Dataset) or ds.ndim != 2 or ds.dtype.kind not in "biuf":
                raise ImportDataError(f"{path}: no 2-D numeric dataset {name!r} (it holds {sorted(f.keys())}); correct "
                                      "'dataset' in the description")
            if ds.size * 8 > memory_budget_bytes():
                raise ImportDataError(f"{path}: dataset {name!r} of shape {ds.shape} is larger than the memory one "
                                      "import may use")
            data = np.asarray(ds[()], float)
            rate = description.get("sample_rate_hz")
            fs = None
            if isinstance(rate, str):
                r = f.get(rate)
                if not isinstance(r, h5py.Dataset) or r.size != 1:
                    raise ImportDataError(f"{path}: sample_rate_hz names {rate!r}, which is not a one-value dataset "
                                          "of the file")
                fs = float(np.asarray(r[()]).ravel()[0])
    except OSError as exc:
        raise ImportDataError(f"{path} is not a readable HDF5 file ({exc})") from None
    return data, fs


def _read_described(paths: Sequence[str | Path], description: dict, fmt: str) -> ImportedTest:
    if not paths:
        raise ImportDataError(f"no {fmt} file given")
    chans = description.get("channels")
    if not isinstance(chans, list) or not chans:
        raise ImportDataError("the description needs a 'channels' list (name, quantity or unit, point per channel)")
    layout = description.get("layout", "samples_first" if fmt == "csv" else "channels_first")
    if layout not in ("channels_first", "samples_first"):
        raise ImportDataError(f"description layout {layout!r} must be 'channels_first' or 'samples_first'")
    time_row = description.get("time_row")
    fs = description.get("sample_rate_hz")
    hits = []
    for path in paths:
        try:
            a, file_fs = _load_array(Path(path), description, fmt)
        except ImportDataError:
            raise
        except (OSError, ValueError, EOFError) as exc:
            raise ImportDataError(f"cannot read {path} as a numpy array ({type(exc).__name__}: {exc})") from None
        if file_fs is not None:
            fs = file_fs
        a = _signals(Path(path), a, layout, description.get("columns") if fmt == "hdf5" else None)
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
        hits += _blocks(Path(path), a, description)
    if isinstance(fs, str) or fs is None or not float(fs) > 0:
        raise ImportDataError("the description needs sample_rate_hz (or time_row, a row of times in s)")
    channels = []
    for k, c in enumerate(chans):
        unit = str(c.get("unit", ""))
        q = c.get("quantity") or unit_info(unit)[0]
        channels.append({"name": str(c.get("name", f"ch{k + 1}")), "quantity": q, "unit": unit or unit_info(q)[1],
                         "sensitivity": float(c.get("sensitivity", math.nan)), "point": str(c.get("point", f"n:{k + 1}:Z"))})
    for h in hits[1:]:
        if h.shape != hits[0].shape:
            raise ImportDataError(f"hits have different shapes {hits[0].shape} and {h.shape}; import them separately")
    excitation = description.get("excitation", "impact")
    if excitation not in ("impact", "continuous"):
        raise ImportDataError(f"description excitation {excitation!r} must be 'impact' (hammer hits) or 'continuous' "
                              "(a shaker's periodic, random or swept excitation)")
    triggers = [0] * len(hits) if excitation == "continuous" else []
    return ImportedTest(float(fs), channels, hits, triggers, ", ".join(str(p) for p in paths),
                        {"format": fmt, "sources": [str(p) for p in paths], "excitation": excitation})


def _signals(path: Path, a: Any, layout: str, columns: Any) -> np.ndarray:
    """``a`` as a float (signals x samples) array: transposed for ``samples_first``, only the
    ``columns`` (signal indices) when given."""
    if not isinstance(a, np.ndarray) or a.dtype.kind not in "biuf":
        raise ImportDataError(f"{path}: expected a real numeric array, got {getattr(a, 'dtype', type(a).__name__)}")
    a = np.asarray(a, float)
    if a.ndim != 2:
        raise ImportDataError(f"{path}: expected a 2-D array (channels x samples), got shape {a.shape}")
    if layout == "samples_first":
        a = a.T
    if columns is not None:
        if not isinstance(columns, list) or not all(isinstance(c, int) and 0 <= c < a.shape[0] for c in columns):
            raise ImportDataError(f"{path}: 'columns' must list signal indices 0..{a.shape[0] - 1} of the dataset")
        a = a[columns]
    return a


def _blocks(path: Path, a: np.ndarray, description: dict) -> list[np.ndarray]:
    """``a`` (channels x samples) as the blocks the description asks for: whole (no
    ``block_samples``), or cut into blocks of ``block_samples`` after leaving out ``skip_blocks``
    (e.g. the transient first period of a periodic excitation); a rest shorter than a block is left out."""
    n = description.get("block_samples")
    if n is None:
        return [a]
    skip = description.get("skip_blocks", 0)
    if not (isinstance(n, int) and n >= 2 and isinstance(skip, int) and skip >= 0):
        raise ImportDataError("block_samples must be a whole number >= 2 and skip_blocks a whole number >= 0")
    count = a.shape[1] // n
    if count <= skip:
        raise ImportDataError(f"{path}: {a.shape[1]} samples make {count} block(s) of {n}, none left after skipping "
                              f"{skip}")
    return [a[:, k * n:(k + 1) * n] for k in range(skip, count)]


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
            quantity, _ = unit_info(str(c["unit_str"]))
        meta_chans.append({"name": name, "quantity": quantity, "unit": str(c["unit_str"]),
                           "sensitivity": float("nan"), "point": str(c.get("point", name))})
    return ImportedTest(fs, meta_chans, hits, triggers if len(triggers) == len(hits) else [], str(path),
                        {"format": "SEP005"})
