"""Turn measured impact time data from other systems into recordings.

Readers return an :class:`ImportedTest` (the file's float time histories in engineering units, one
array per hit); :func:`channel_roles` fixes the force and response channels and their point labels,
:func:`imported_hits` makes the :class:`analysis.hit.Hit` of each block (int16 counts, trigger,
channel roles) and :func:`write_imported` writes them as a schema-v1 recording with FRFs computed
by the same code path as a capture.

Formats
-------
* LabVIEW ``.lvm`` text (:func:`read_lvm`): header keys ``Separator``, ``Decimal_Separator``
  (``,`` or ``.``), each segment (= one hit) with its own channel header (``Channels``,
  ``Samples``, ``Y_Unit_Label``, ``Delta_X``) and a data table whose first column is the
  X value (possibly empty) and a trailing ``Comment`` column.
* DataPhysics SignalCalc ``.mat`` exports (:func:`read_dataphysics_mat`): ``X1..Xn`` raw blocks
  ``[t, value]`` (``t < 0`` is the pre-trigger), ``W1..Wn`` the analyser-windowed blocks,
  ``Sensitivity`` (mV/EU), ``Unit``.
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
fitted to the hit); the relative quantisation error is below 2e-5 of the peak, far under the
noise of any hammer test. ``volts_per_count = eu_per_count * sensitivity`` when the sensitivity
is known (NaN otherwise).
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


def _read_lvm(path: str | Path) -> ImportedTest:
    p = Path(path)
    try:
        lines = read_bounded_text(p, ".lvm file", text_data_limit_bytes(), ImportDataError, "latin-1").splitlines()
    except OSError as exc:
        raise ImportDataError(f"cannot read {p}: {exc.strerror}") from None
    if not lines or not lines[0].startswith("LabVIEW Measurement"):
        raise ImportDataError(f"{p} is not a LabVIEW .lvm file (first line should be 'LabVIEW Measurement')")
    sep, decimal = "\t", "."
    i = 0
    while i < len(lines) and not lines[i].startswith("***End_of_Header***"):
        key, _, val = lines[i].partition("\t")
        if key == "Separator":
            sep = {"Tab": "\t", "Comma": ",", "Semicolon": ";", "Space": " "}.get(val.strip(), "\t")
        elif key == "Decimal_Separator":
            decimal = val.strip() or "."
        elif key == "X_Columns" and val.strip() == "Multi":
            raise ImportDataError(f"{p}: X_Columns = Multi (one time column per channel) is not supported; "
                                  "save the file from LabVIEW with X_Columns One or No")
        i += 1
    i += 1
    segments: list[tuple[dict, np.ndarray]] = []
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
        i += 1
        n_ch = int(header["Channels"][0])
        rows = []
        while i < len(lines) and lines[i].strip() and not lines[i].startswith(("Channels", "***")):
            cells = lines[i].split(sep)
            try:
                rows.append([_num(c, decimal) for c in cells[1:1 + n_ch]])
            except ValueError:
                raise ImportDataError(f"{p}: line {i + 1} is not numeric: {lines[i][:60]!r}") from None
            i += 1
        data = np.asarray(rows, dtype=float).T
        if data.shape[0] != n_ch:
            raise ImportDataError(f"{p}: segment {len(segments) + 1} has {data.shape[0]} data columns, header says {n_ch}")
        segments.append((header, data))
    if not segments:
        raise ImportDataError(f"{p}: no data segment found")
    h0 = segments[0][0]
    try:
        dx = _num(h0["Delta_X"][0], decimal)
    except (KeyError, IndexError, ValueError):
        raise ImportDataError(f"{p}: the segment header has no Delta_X (sample interval)") from None
    labels = [u for u in h0.get("Y_Unit_Label", [])][: segments[0][1].shape[0]]
    channels = []
    for k in range(segments[0][1].shape[0]):
        q, unit = _unit_info(labels[k] if k < len(labels) else "")
        channels.append({"name": f"ch{k + 1}", "quantity": q, "unit": unit, "sensitivity": math.nan,
                         "point": f"n:{k + 1}:Z"})
    hits = []
    for k, (_, d) in enumerate(segments):
        if d.shape != segments[0][1].shape:
            raise ImportDataError(f"{p}: segment {k + 1} has shape {d.shape}, segment 1 {segments[0][1].shape}")
        hits.append(d)
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


def _dataphysics_from(p: Path, m: dict, windowed: bool) -> ImportedTest:
    key = "W" if windowed else "X"
    ks = sorted(int(k[1:]) for k in m if re.fullmatch(key + r"\d+", k))
    if not ks:
        raise ImportDataError(f"{p} holds no '{key}1..{key}n' time blocks: is it a DataPhysics time export?")
    blocks = [np.asarray(m[f"{key}{k}"], float) for k in ks]
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
    sens = np.asarray(m.get("Sensitivity", np.full(len(ks), np.nan)), float).ravel()
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
    first = next(iter(groups.values()))
    names = [str(c["name"]) for c in first]
    fs = float(first[0]["fs"])
    hits, triggers = [], []
    for g, chans in groups.items():
        if len(chans) != len(first) or any(float(c["fs"]) != fs for c in chans):
            raise ImportDataError(f"{path}: hit {g!r} has {len(chans)} channels at {[c['fs'] for c in chans]} Hz; "
                                  f"every hit needs the {len(first)} channels of the first at {fs:g} Hz")
        n = min(c["data"].size for c in chans)
        hits.append(np.vstack([c["data"][:n] for c in chans]))
        if all("trigger_index" in c for c in chans):
            triggers.append(int(chans[0]["trigger_index"]))
    meta_chans = []
    for c, name in zip(first, names):
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


def combine_imports(tests: Sequence[ImportedTest]) -> ImportedTest:
    """One test from several files read alike (e.g. one .lvm per hit): the hits in the order given.
    The files must share the sample rate and the block shape; the files' trigger samples are kept
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
    ``sequence`` the import order, ``timestamp`` the time of the import (s since the epoch)."""
    chans, fch, rch = roles.channels, roles.force_channel, roles.response_channels
    ref, outs = roles.reference, roles.outputs
    names = tuple(str(c["name"]) for c in chans)
    sens = np.array([c["sensitivity"] for c in chans], float)
    hits = []
    for k, data in enumerate(test.hits):
        trig = test.trigger_indices[k] if k < len(test.trigger_indices) else detect_trigger(data[fch])
        counts, eu = quantize(data)
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
    with whole_recording(out, overwrite) as tmp, RecordingWriter(
            tmp, instrument=instrument, setup=setup, channels=chans, windows=windows,
            plan={"mode": "imported", "points": [ref]}, overwrite=True) as w:
        w.log("INFO", f"imported {len(test.hits)} hit(s) from {test.source}; " + "; ".join(roles.describe()))
        kept: list[Hit] = []
        for k, hit in enumerate(imported_hits(test, roles)):
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
