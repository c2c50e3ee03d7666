"""Impact-test recordings: HDF5 schema ``impactlab-recording`` version 1 (``docs/recording-format.md``).

The writer appends as the test goes: every hit (accepted or rejected) is written as raw ADC
counts (int16) with its scaling, journaled and flushed before the analyser is armed again, so a
crash loses no accepted hit (a recording whose writer stopped without closing it is read from its
journal, ``analysis.recording_journal``). FRF results are written per measurement
point when its average is complete. The reader validates the schema and checksums and turns
any damaged, truncated, foreign or wrong-version file into :class:`RecordingError`.

Scaling: a channel's value in engineering units is ``counts * eu_per_count`` (float64), and its
input voltage ``counts * volts_per_count``. :func:`scale_counts` is the one place that does it, so
the session and a replay compute FRFs from bit-identical inputs.
"""
from __future__ import annotations

import contextlib
import json
import logging
import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from analysis.errors import RecordingError
from analysis.frf import FRFSet
from analysis.hit import Hit
from analysis.spectra import WindowSettings, excitation_limit_hz, excited_top_hz

from .recording_changes import journal_left, replay_journal
from .recording_lock import is_lock_error, live_copy, live_copy_file, locked_error, writer_alive
from .recording_schema import (
    _DAMAGE,
    CHANNEL_FIELDS,
    SCHEMA,
    SCHEMA_VERSION,
    _as_str,
    _h5py,
    channel_rows,
    counts_crc32,
    scale_counts,
)

__all__ = [
    "SCHEMA",
    "SCHEMA_VERSION",
    "CHANNEL_FIELDS",
    "scale_counts",
    "counts_crc32",
    "Recording",
    "open_recording",
    "verify_recording",
    "load_frfset",
    "merge_frfsets",
]

log = logging.getLogger(__name__)


def _open_own_copy(path: Path) -> Any:
    """Open for reading a copy of a recording that this reader made for itself (a live copy, a recording rebuilt
    from its journal), without libhdf5's file lock: nobody else writes it, and a child process forked by another
    thread while the copy was being written may still hold the lock that writing took for an instant (the open
    file is inherited until the child execs), which would refuse the read."""
    return _h5py().File(path, "r", locking=False)


class Recording:
    """Read-only view of a recording; validates the schema on open. Use as a context manager.

    A recording an impactlab writer has open is read live: the reader sees every hit flushed
    before it opened (``live`` is True; ``analysis.recording_lock``).

    Examples
    --------
    A recording of two hits on the simulated frame (``python -m acquisition capture``), read back:

    >>> import tempfile
    >>> from pathlib import Path
    >>> from acquisition.cli_capture import main as capture
    >>> folder = tempfile.TemporaryDirectory()
    >>> path = Path(folder.name) / "rec.h5"
    >>> capture(["--device", "sim://?seed=1", "--out", str(path), "--hits", "2", "--auto", "-q"])
    hits accepted: 2, rejected: 0
    ...
    recording written: ...rec.h5
    0
    >>> from analysis import Recording
    >>> with Recording(path) as rec:
    ...     print(rec.n_hits, [h.accepted for h in rec.hits()], rec.measurement_names())
    ...     frf = rec.frfsets()[0]                    # H1 of the two hits, (outputs, references, lines)
    2 [True, True] ['m000']
    >>> frf.H.shape, frf.references, frf.quantity
    ((3, 1, 4097), ('right:6:-X',), 'accelerance')
    >>> folder.cleanup()
    """

    live = False
    #: True when the recording was read from the journal its writer left (it stopped without closing)
    recovered = False

    def __init__(self, path: str | Path) -> None:
        h5py = _h5py()
        self.path = Path(path)
        if not self.path.is_file():
            raise RecordingError(f"recording {self.path} not found: check the path")
        try:
            is_h5 = h5py.is_hdf5(self.path)
        except OSError as exc:
            raise RecordingError(f"cannot read {self.path}: {exc}") from None
        if not is_h5:
            raise RecordingError(
                f"{self.path} is not an HDF5 file: give an impactlab recording (.h5) written by "
                "'python -m acquisition capture' or 'python -m acquisition import'"
            )
        self._live_copy: Path | None = None
        if writer_alive(self.path):  # our own lock, also where libhdf5's is off (HDF5_USE_FILE_LOCKING=FALSE)
            self._f = self._open_live()
        elif journal_left(self.path):
            self._f = self._open_recovered()
        else:
            try:
                self._f = h5py.File(self.path, "r")
            except OSError as exc:
                if not is_lock_error(exc):
                    raise self._unopenable(exc) from None
                self._f = self._open_live()
        self._file_bytes = Path(self._f.filename).stat().st_size
        try:
            self._validate()
        except RecordingError:
            self.close()
            raise
        except _DAMAGE as exc:
            self.close()
            raise RecordingError(f"{self.path} is damaged ({type(exc).__name__}: {exc}); "
                                 "use a backup or re-run the test") from None

    def _open_live(self) -> Any:
        """Open a consistent copy of a recording a writer has open (``analysis.recording_lock``)."""
        if not writer_alive(self.path):
            raise locked_error(self.path)
        try:
            self._live_copy = live_copy(self.path)
        except RecordingError:
            raise
        except OSError as exc:
            raise RecordingError(f"cannot copy {self.path}, which is being written, to read it live: "
                                 f"{exc}; free space in the temporary folder or wait for the writer to finish") from None
        self.live = True
        log.info("%s is being written: reading the hits flushed so far", self.path)
        try:
            return _open_own_copy(self._live_copy)
        except OSError as exc:
            self._remove_live_copy()
            raise self._unopenable(exc) from None

    def _open_recovered(self) -> Any:
        """Open the recording rebuilt from the journal its writer left (the writer stopped without
        closing it): a temporary file, the recording itself unchanged (``analysis.recording_journal``)."""
        fd, name = live_copy_file(self.path)
        os.close(fd)
        self._live_copy = Path(name)
        try:
            n, torn = replay_journal(self.path, self._live_copy)
        except RecordingError:
            self._remove_live_copy()
            raise
        self.recovered = True
        log.warning("%s was not closed by its writer: read from its journal (%d changes%s); 'capture --resume' "
                    "rebuilds the file", self.path, n, ", the last one cut short and left out" if torn else "")
        return _open_own_copy(self._live_copy)

    def _unopenable(self, exc: OSError) -> RecordingError:
        return RecordingError(f"{self.path} is damaged or truncated and cannot be opened ({exc}); recover its intact "
                              f"hits with 'python -m acquisition repair {self.path} --out FIXED.h5', or use a backup")

    def _validate(self) -> None:
        a = self._f.attrs
        schema = a.get("schema")
        if schema is None or _as_str(schema) != SCHEMA:
            raise RecordingError(
                f"{self.path} is an HDF5 file but not an impactlab recording (schema attribute "
                f"{_as_str(schema)!r}, expected {SCHEMA!r})"
            )
        ver = int(a.get("schema_version", -1))
        if ver != SCHEMA_VERSION:
            raise RecordingError(
                f"{self.path} uses recording schema version {ver}; this impactlab reads version {SCHEMA_VERSION}: "
                "use the impactlab release that wrote it or convert the file"
            )
        for g in ("instrument", "setup", "windows", "hits", "frf", "events"):
            if g not in self._f:
                raise RecordingError(f"{self.path} is damaged: group '/{g}' is missing")
        self.instrument = json.loads(_as_str(self._f["instrument"].attrs["json"]))
        self.setup = json.loads(_as_str(self._f["setup"].attrs["json"]))
        self.channels = channel_rows(self._read(self._f["setup/channels"]))
        self.windows = WindowSettings.from_dict(json.loads(_as_str(self._f["windows"].attrs["json"])))
        self.plan = json.loads(_as_str(a.get("plan_json", "{}")))
        self.created_utc = _as_str(a.get("created_utc", ""))
        self.closed_cleanly = "closed_utc" in a

    # -- hits ----------------------------------------------------------------------------------
    def _read(self, ds: Any) -> Any:
        """A dataset's values, after checking that its declared size fits in the file (a damaged
        shape can claim billions of elements; reading it would exhaust memory)."""
        n = int(np.prod(ds.shape, dtype=np.float64)) if ds.shape else 1
        if n > self._file_bytes:
            raise RecordingError(f"{self.path} is damaged: dataset {ds.name} claims {n} elements in a file of "
                                 f"{self._file_bytes} bytes; use a backup or re-run the test")
        return ds[()]

    def _damaged(self, what: str, exc: BaseException) -> RecordingError:
        return RecordingError(f"{self.path}: {what} is damaged ({type(exc).__name__}: {exc}); use a backup or "
                              "re-run the test")

    def hit_names(self) -> list[str]:
        try:
            return sorted(self._f["hits"].keys())
        except _DAMAGE as exc:
            raise self._damaged("the hit index", exc) from None

    @property
    def n_hits(self) -> int:
        return len(self.hit_names())

    def hit(self, index: int) -> Hit:
        """One hit by index; raises RecordingError when it is incomplete or its checksum fails."""
        name = f"{int(index):06d}"
        if name not in self.hit_names():
            raise RecordingError(f"{self.path} has no hit {index} (it holds {self.n_hits})")
        try:
            g = self._f["hits"][name]
            a = g.attrs
            if not a.get("complete", False):
                raise RecordingError(f"hit {index} in {self.path} is incomplete (the writer stopped mid-hit)")
            counts = self._read(g["counts"])
            crc_ok = counts_crc32(counts) == int(a["crc32"])
            if not crc_ok:
                raise RecordingError(
                    f"hit {index} in {self.path} fails its CRC-32 check: the raw data are damaged"
                )
            return Hit(
                index=int(index), counts=counts, eu_per_count=np.asarray(a["eu_per_count"], float),
                volts_per_count=np.asarray(a["volts_per_count"], float), trigger_index=int(a["trigger_index"]),
                sample_rate_hz=float(a["sample_rate_hz"]), sequence=int(a["sequence"]),
                timestamp=float(a["timestamp"]), measurement=int(a["measurement"]), point=_as_str(a["point"]),
                reference=_as_str(a["reference"]), outputs=json.loads(_as_str(a["outputs"])),
                force_channel=int(a["force_channel"]),
                response_channels=[int(i) for i in np.atleast_1d(a["response_channels"])],
                overload=np.asarray(a["overload"], bool), accepted=bool(a["accepted"]),
                reasons=json.loads(_as_str(a["reasons"])), check=json.loads(_as_str(a.get("check_json", "{}"))),
                crc_ok=crc_ok, channel_names=self._channel_names(counts.shape[0]),
            )
        except RecordingError:
            raise
        except _DAMAGE as exc:
            raise RecordingError(f"hit {index} in {self.path} is damaged ({type(exc).__name__}: {exc})") from None

    def _hit_sample_rate(self) -> float | None:
        """The sample rate (Hz) stored with the first hit (for FRFs written before the FRF group
        stored its own), or None for a recording without hits (imported FRFs)."""
        try:
            names = self.hit_names()
            return float(self._f["hits"][names[0]].attrs["sample_rate_hz"]) if names else None
        except (RecordingError, *_DAMAGE):
            return None

    def _channel_names(self, n_channels: int) -> tuple:
        names = tuple(str(c.get("name", "")) for c in self.channels)
        return names if len(names) == n_channels else ()

    def hits(self, accepted_only: bool = False, skip_damaged: bool = False) -> Iterator[Hit]:
        """All hits in order (``accepted_only``: only accepted ones; ``skip_damaged``: drop incomplete ones)."""
        for name in self.hit_names():
            try:
                h = self.hit(int(name))
            except RecordingError:
                if skip_damaged:
                    log.warning("skipping damaged hit %s in %s", name, self.path)
                    continue
                raise
            if accepted_only and not h.accepted:
                continue
            yield h

    # -- events and FRFs -----------------------------------------------------------------------
    def events(self) -> list[tuple[float, str, str]]:
        try:
            ev = self._f["events"]
            t = self._read(ev["time_unix_s"])
            lv = [_as_str(x) for x in self._read(ev["level"])]
            ms = [_as_str(x) for x in self._read(ev["message"])]
            n = min(len(t), len(lv), len(ms))
            return [(float(t[i]), lv[i], ms[i]) for i in range(n)]
        except _DAMAGE as exc:
            raise self._damaged("the event log", exc) from None

    def measurement_names(self) -> list[str]:
        try:
            return sorted(self._f["frf"].keys())
        except _DAMAGE as exc:
            raise self._damaged("the FRF index", exc) from None

    def frf_group(self, name: str) -> dict:
        """All stored arrays and attributes of one measurement's FRF results."""
        try:
            g = self._f["frf"][name]
            out: dict[str, Any] = {k: self._read(g[k]) for k in g.keys()}
            for k, v in g.attrs.items():
                out[k] = _as_str(v) if isinstance(v, (bytes, str)) else v
            out["outputs"] = json.loads(out["outputs"])
            out["windows"] = WindowSettings.from_dict(json.loads(out.pop("windows_json")))
            tau = float(out["exp_window_tau_s"])
            out["exp_window_tau_s"] = None if np.isnan(tau) else tau
            for key in ("sample_rate_hz", "record_s", "pretrigger_s"):  # absent in files written before them
                value = float(out.get(key, float("nan")))
                out[key] = None if np.isnan(value) else value
            return out
        except _DAMAGE as exc:
            raise RecordingError(f"FRF results {name!r} in {self.path} are missing or damaged "
                                 f"({type(exc).__name__}: {exc})") from None

    @property
    def preferred_estimator(self) -> str:
        """The FRF estimate this recording's FRFs are read as by default: the one chosen at replay
        (``replay --estimator H2``), else "H1"."""
        value = self._f.attrs.get("preferred_estimator", "H1")
        est = _as_str(value).upper() if isinstance(value, (bytes, str)) else "H1"
        return est if est in ("H1", "H2") else "H1"

    def frfsets(self, estimator: str | None = None) -> list[FRFSet]:
        """One FRF set per measurement point (one reference each); ``estimator`` "H1" or "H2"
        (default: :attr:`preferred_estimator`)."""
        est = (estimator or self.preferred_estimator).upper()
        if est not in ("H1", "H2"):
            raise ValueError(f"estimator {estimator!r} is not H1 or H2")
        sets = []
        for name in self.measurement_names():
            g = self.frf_group(name)
            try:
                sets.append(self._frfset(name, g, est))
            except _DAMAGE as exc:
                raise RecordingError(f"FRF results {name!r} in {self.path} are damaged ({type(exc).__name__}: {exc}); "
                                     "recompute them with 'python -m acquisition replay'") from None
        return sets

    def _frfset(self, name: str, g: dict, est: str) -> FRFSet:
        if est not in g:
            raise RecordingError(f"{self.path} holds the analyser's {', '.join(k for k in ('H1', 'H2') if k in g)} "
                                 f"only (FRFs imported from an analyser export), no {est}: use the H1 estimate")
        record_s, pretrigger_s = g.get("record_s"), g.get("pretrigger_s")
        if record_s is None:  # FRFs written before the FRF group stored them: the set-up's
            record_s, pretrigger_s = self._setup_record()
        return FRFSet(
            freq_hz=g["freq_hz"], H=g[est][:, None, :], quantity=g["quantity"], outputs=tuple(g["outputs"]),
            references=(g["reference"],), unit=g["unit"],
            coherence=g["coherence"][:, None, :] if "coherence" in g else None,  # an export without coherence
            exp_window_tau_s=g["exp_window_tau_s"], sample_rate_hz=g["sample_rate_hz"] or self._hit_sample_rate(),
            record_s=record_s, pretrigger_s=pretrigger_s,
            meta={"estimator": est, "source": str(self.path),
                  **({"n_averages": int(g["n_averages"])} if int(g["n_averages"]) > 0 else {}),
                  "excitation_limit_hz": self._excitation_limit(g),
                  **({"excitation": "continuous"} if self._continuous() else {}),
                  "measurement": name, "point": g["point"]},
        )

    def _continuous(self) -> bool:
        """Whether the recording's force is a shaker's continuous excitation (an import described so)."""
        return isinstance(self.setup, dict) and self.setup.get("excitation") == "continuous"

    def _excitation_limit(self, g: dict) -> float | None:
        """The top of the band the force excites (Hz) from a measurement's force autospectrum ``Gff``:
        a hammer pulse's fall (:func:`analysis.spectra.excitation_limit_hz`), or for the blocks of a
        shaker's continuous excitation (an import described so) the top of its excited band
        (:func:`analysis.spectra.excited_top_hz`); None without force spectra."""
        if "Gff" not in g:
            return None
        if self._continuous():
            return excited_top_hz(g["freq_hz"], g["Gff"])
        return excitation_limit_hz(g["freq_hz"], g["Gff"])

    def _setup_record(self) -> tuple[float | None, float | None]:
        """Record length (s) and pre-trigger (s) of the analyser's set-up, when the recording holds
        one with a trigger (a capture; an import has none): (None, None) otherwise."""
        try:
            fs = float(self.setup["sample_rate_hz"])
            return (int(self.setup["block_size"]) / fs,
                    int(self.setup["trigger"]["pretrigger_samples"]) / fs)
        except (AttributeError, KeyError, TypeError, ValueError, ZeroDivisionError):
            return None, None

    @property
    def record_s(self) -> float | None:
        """The set-up's record length (s), None when the recording holds no analyser set-up."""
        return self._setup_record()[0]

    @property
    def pretrigger_s(self) -> float | None:
        """The set-up's pre-trigger time (s), None when the recording holds no analyser set-up."""
        return self._setup_record()[1]

    def close(self) -> None:
        if self._f.id.valid:
            self._f.close()
        self._remove_live_copy()

    def _remove_live_copy(self) -> None:
        if self._live_copy is not None:
            with contextlib.suppress(OSError):
                self._live_copy.unlink()
            self._live_copy = None

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


VERIFY_TIMEOUT_S = 300.0


def _read_all(path: str) -> int:
    """Read everything a tool may read (runs in the child of :func:`verify_recording`); number of hits."""
    with Recording(path) as rec:
        n = sum(1 for _ in rec.hits(skip_damaged=True))
        rec.events()
        for name in rec.measurement_names():
            rec.frf_group(name)
        rec.frfsets()
    return n


def verify_recording(path: str | Path, timeout_s: float = VERIFY_TIMEOUT_S) -> int:
    """Read the whole recording in a child process; returns the number of complete hits.

    libhdf5 can crash the process (segmentation fault) on some damaged files, which no Python code
    can catch (found by fuzzing ``tests/test_recording_fuzz.py``). Call this before opening a file
    of unknown integrity in-process (``capture --resume`` does): a crash, a timeout or any damage
    becomes :class:`RecordingError`. Hits cut short by a crash are skipped, as by
    ``Recording.hits(skip_damaged=True)``."""
    from ._isolated import call_isolated

    p = Path(path)
    if not p.is_file():
        raise RecordingError(f"recording {p} not found: check the path")
    try:
        return int(call_isolated(
            _read_all, (str(p),), timeout_s,
            crashed=lambda code: RecordingError(f"{p} is damaged: reading it crashed the HDF5 library (exit code "
                                                f"{code}); use a backup or re-run the test"),
            timed_out=lambda: RecordingError(f"{p}: reading it took over {timeout_s:g} s; the file is damaged or on "
                                             "a stalled drive")))
    except RecordingError:
        raise
    except Exception as exc:  # anything else the reading child met is damage of this file too
        raise RecordingError(f"{p} is damaged ({type(exc).__name__}: {exc}); use a backup or re-run the test") from None


def open_recording(path: str | Path) -> Recording:
    """Open and validate a recording (raises :class:`RecordingError` with a clear message)."""
    return Recording(path)


def merge_frfsets(sets: Sequence[FRFSet]) -> FRFSet:
    """Combine single-reference FRF sets into one ``H[n_out, n_ref, n_freq]``.

    Outputs and references are the union in order of first appearance (roving hammer: the
    references grow; roving accelerometer: the outputs grow). Combinations never measured are NaN.
    Sets that repeat an (output, reference) pair: the later one wins.
    """
    if not sets:
        raise RecordingError("the recording holds no FRF results: capture or replay at least one measurement point")
    f0 = sets[0].freq_hz
    for s in sets[1:]:
        if s.freq_hz.shape != f0.shape or not np.allclose(s.freq_hz, f0):
            raise RecordingError("measurement points have different frequency axes and cannot be combined")
        if s.quantity != sets[0].quantity:
            raise RecordingError(f"measurement points mix quantities {sets[0].quantity} and {s.quantity}")
    outs: list[str] = []
    refs: list[str] = []
    for s in sets:
        outs += [o for o in s.outputs if o not in outs]
        refs += [r for r in s.references if r not in refs]
    H = np.full((len(outs), len(refs), f0.size), np.nan + 0j)
    C: np.ndarray | None = np.full((len(outs), len(refs), f0.size), np.nan)
    for s in sets:
        for i, o in enumerate(s.outputs):
            for j, r in enumerate(s.references):
                H[outs.index(o), refs.index(r)] = s.H[i, j]
                if s.coherence is not None and C is not None:
                    C[outs.index(o), refs.index(r)] = s.coherence[i, j]
    taus = {s.exp_window_tau_s for s in sets}
    if len(taus) > 1:
        raise RecordingError(
            "measurement points were processed with different exponential windows (tau "
            + ", ".join("none" if s.exp_window_tau_s is None else f"{s.exp_window_tau_s:.6g} s" for s in sets)
            + "): the fit cannot remove one window from all of them; recompute the FRFs with one window "
            "('python -m acquisition replay REC.h5 --out NEW.h5 --exp-window ...')")
    rates = {s.sample_rate_hz for s in sets if s.sample_rate_hz is not None}
    if len(rates) > 1:
        raise RecordingError(f"measurement points were sampled at different rates {sorted(rates)} Hz and cannot be "
                             "combined into one FRF set")
    ests = {s.meta.get("estimator") for s in sets}
    meta = dict(sets[0].meta)
    meta.pop("measurement", None)
    meta.pop("point", None)
    n_avg = [s.meta.get("n_averages") for s in sets]
    if all(n is not None for n in n_avg):  # averages not known for a point (an analyser export): none said
        meta["n_averages"] = n_avg
    else:
        meta.pop("n_averages", None)
    meta["excitation_limit_hz"] = [s.meta.get("excitation_limit_hz") for s in sets]
    if len(ests) > 1:
        meta["estimator"] = "mixed"
    if all(s.coherence is None for s in sets):  # an analyser export without coherence: none stated
        C = None
    return FRFSet(freq_hz=f0, H=H, quantity=sets[0].quantity, outputs=tuple(outs), references=tuple(refs),
                  unit=sets[0].unit, coherence=C, exp_window_tau_s=sets[0].exp_window_tau_s, meta=meta,
                  sample_rate_hz=next(iter(rates)) if rates else None, record_s=sets[0].record_s,
                  pretrigger_s=sets[0].pretrigger_s)


def load_frfset(path: str | Path, estimator: str | None = None) -> FRFSet:
    """All FRF results of a recording as one :class:`FRFSet` (see :func:`merge_frfsets`)."""
    with Recording(path) as rec:
        return merge_frfsets(rec.frfsets(estimator))
