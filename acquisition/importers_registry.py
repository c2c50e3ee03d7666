"""The formats ``python -m acquisition import`` reads: one :class:`ImportFormat` row each.

A row is everything the command knows about a format: its ``--format`` name, what it holds (the
text of ``--help`` and of the error messages), the file extensions it comes in, a content test
when several formats share an extension, the options it takes beyond the common ones, and the
reader. The command's dispatch (:func:`format_for`), its ``--help`` format list
(:func:`formats_help`), the check of the options given (:func:`check_options`) and the text of
an unknown input (:func:`unknown_format_error`) are all made from :data:`IMPORT_FORMATS`, so a
new format is one row, its reader and its test.

Two kinds of rows: ``time`` (measured time histories: the reader returns
:class:`~acquisition.importers_data.ImportedTest` objects, the command makes hits and FRFs as a
capture does) and ``frf`` (an analyser's own FRFs: the reader returns
:class:`~acquisition.frf_importers.ImportedFRFs`, written as they are).
"""
from __future__ import annotations

import importlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import ImportDataError, UsageError

__all__ = ["ImportFormat", "ReadOptions", "IMPORT_FORMATS", "TIME_OPTIONS", "FRF_OPTIONS", "format_names",
           "format_for", "formats_help", "check_options", "unknown_format_error"]


@dataclass(frozen=True)
class ReadOptions:
    """What a reader may need from the command line: ``windowed`` (DataPhysics ``Wk`` blocks),
    ``describe`` (the channel description of ``.npy`` arrays), ``drop_nonfinite`` (leave out hits
    holding NaN/inf samples), ``variables`` (the FRF variables of an analyser export)."""

    windowed: bool = False
    describe: str | None = None
    drop_nonfinite: bool = False
    variables: tuple[str, ...] | None = None


@dataclass(frozen=True)
class ImportFormat:
    """One input format of ``import``.

    name : the ``--format`` value.
    kind : ``"time"`` (time histories -> hits) or ``"frf"`` (an analyser's FRFs and coherence).
    help : what the files hold, in a few words (the ``--help`` list and the error messages).
    extensions : the file name endings (lower case, with the dot) it is detected by.
    read : ``read(paths, options)`` -> a list of imports (one per file, or one for all files).
    options : the command-line options it takes beyond the common ones (``--out``, ``--reference``...).
    requires : the options it cannot do without.
    detect : ``detect(path)`` -> whether a file of one of ``extensions`` holds this format (None:
        any file of those extensions does; rows sharing an extension are tried in table order).
    text : parsed as text (held whole in memory: the text-input size limit applies).
    """

    name: str
    kind: str
    help: str
    extensions: tuple[str, ...]
    read: Callable[[Sequence[Path], ReadOptions], list[Any]]
    options: tuple[str, ...] = ()
    requires: tuple[str, ...] = ()
    detect: Callable[[Path], bool] | None = None
    text: bool = False

    def label(self) -> str:
        """``name (help; .ext)``: the row as the help list and the error messages show it."""
        return f"{self.name} ({self.help}; {', '.join(self.extensions)})"


#: the options of every time-data row (the hammer channel, the windows the FRFs are computed with)
TIME_OPTIONS = ("--force-channel", "--responses", "--force-window", "--exp-window", "--drop-nonfinite")
#: the options of every analyser-FRF row (a roving test's map, the window the analyser applied)
FRF_OPTIONS = ("--points", "--analyser-exp-window")


# -- readers: each row's reader is a parser of its own module, wrapped to the one signature -------------

def _read_lvm(paths: Sequence[Path], o: ReadOptions) -> list[Any]:
    from .importers_data import read_dropping_nonfinite
    from .importers_parse import read_lvm

    return [read_dropping_nonfinite(read_lvm, p, drop=o.drop_nonfinite) for p in paths]


def _read_dataphysics(paths: Sequence[Path], o: ReadOptions) -> list[Any]:
    from .importers_data import read_dropping_nonfinite
    from .importers_parse import read_dataphysics_mat

    return [read_dropping_nonfinite(read_dataphysics_mat, p, windowed=o.windowed, drop=o.drop_nonfinite)
            for p in paths]


def _read_numpy(paths: Sequence[Path], o: ReadOptions) -> list[Any]:
    from .importers_data import read_dropping_nonfinite
    from .importers_parse import load_description, read_numpy

    assert o.describe is not None  # the row requires --describe (check_options)
    return [read_dropping_nonfinite(read_numpy, list(paths), load_description(o.describe), drop=o.drop_nonfinite)]


def _described_reader(fmt: str) -> Callable[[Sequence[Path], ReadOptions], list[Any]]:
    """The reader of a described-array row (``.csv``, ``.hdf5``): all files read as one test with
    the description of ``--describe``."""
    def read(paths: Sequence[Path], o: ReadOptions) -> list[Any]:
        from .importers_data import read_dropping_nonfinite
        from .importers_parse import load_description, read_described

        assert o.describe is not None  # the row requires --describe (check_options)
        return [read_dropping_nonfinite(read_described, list(paths), load_description(o.describe), fmt,
                                        drop=o.drop_nonfinite)]
    read.__name__ = f"read_{fmt}"
    return read


def _read_sep005(paths: Sequence[Path], o: ReadOptions) -> list[Any]:
    from .importers_data import read_dropping_nonfinite
    from .importers_parse import read_sep005_test

    return [read_dropping_nonfinite(read_sep005_test, p, drop=o.drop_nonfinite) for p in paths]


def _frf_reader(module: str, name: str) -> Callable[[Sequence[Path], ReadOptions], list[Any]]:
    """The reader of an FRF-export row: ``acquisition.<module>.<name>(path, variables)`` for each file
    (imported when a file is read: ``--help`` loads no reader)."""
    def read(paths: Sequence[Path], o: ReadOptions) -> list[Any]:
        reader = getattr(importlib.import_module(f"acquisition.{module}"), name)
        return [reader(p, o.variables) for p in paths]
    read.__name__ = name
    return read


def _mat_detect(module: str, name: str) -> Callable[[Path], bool]:
    """The content test of a ``.mat`` row: ``acquisition.<module>.<name>`` on the file's variables
    (name -> MATLAB class, listed in a child process: a damaged file cannot crash the command)."""
    def detect(path: Path) -> bool:
        from .frf_importers import mat_variables

        test: Callable[[dict], bool] = getattr(importlib.import_module(f"acquisition.{module}"), name)
        return test(mat_variables(path))
    return detect


def _ascii_detect(path: Path) -> bool:
    from .frf_importers_ascii import is_signalcalc_ascii

    return is_signalcalc_ascii(path)


#: every format ``import`` reads, one row each; rows sharing an extension are tried in this order
IMPORT_FORMATS: tuple[ImportFormat, ...] = (
    ImportFormat("lvm", "time", "LabVIEW measurement text, one segment per hit", (".lvm",),
                 _read_lvm, TIME_OPTIONS, text=True),
    ImportFormat("mat", "time", "DataPhysics SignalCalc .mat time blocks X1..Xn", (".mat",),
                 _read_dataphysics, TIME_OPTIONS + ("--windowed",),
                 detect=_mat_detect("importers_parse", "dataphysics_detect")),
    ImportFormat("signalcalc-frf", "frf", "DataPhysics SignalCalc .mat H1 and coherence, H{r}_{k} and C{r}_{k}",
                 (".mat",), _frf_reader("frf_importers", "read_signalcalc_frf"), FRF_OPTIONS + ("--variables",),
                 detect=_mat_detect("frf_importers", "signalcalc_detect")),
    ImportFormat("testlab-frf", "frf", "LMS Test.Lab .mat FRF structs, with the ...Coherence.mat beside", (".mat",),
                 _frf_reader("frf_importers", "read_testlab_frf"), FRF_OPTIONS + ("--variables",),
                 detect=_mat_detect("frf_importers", "testlab_detect")),
    ImportFormat("npy", "time", "numpy arrays, one file per hit, described by --describe", (".npy",),
                 _read_numpy, TIME_OPTIONS + ("--describe",), requires=("--describe",)),
    ImportFormat("sep005", "time", "SEP005 JSON time channels, one group per hit", (".json",),
                 _read_sep005, TIME_OPTIONS, text=True),
    ImportFormat("csv", "time", "CSV table, one column per signal, described by --describe (columns, channels, "
                 "sample rate; block_samples for a continuous excitation)", (".csv",), _described_reader("csv"),
                 TIME_OPTIONS + ("--describe",), requires=("--describe",), text=True),
    ImportFormat("hdf5", "time", "a 2-D dataset of HDF5 files, described by --describe (dataset, channels, sample "
                 "rate)", (".hdf5",), _described_reader("hdf5"), TIME_OPTIONS + ("--describe",),
                 requires=("--describe",)),
    ImportFormat("signalcalc-ascii", "frf", "DataPhysics SignalCalc ASCII FRF export Hxy*.txt, no coherence",
                 (".txt",), _frf_reader("frf_importers_ascii", "read_signalcalc_ascii"), FRF_OPTIONS,
                 detect=_ascii_detect, text=True),
    ImportFormat("uff58", "frf", "Universal File Format dataset 58 FRFs with their coherence records",
                 (".uff", ".unv"), _frf_reader("frf_importers", "read_uff58_frfs"), FRF_OPTIONS, text=True),
)


def format_names(kind: str | None = None) -> tuple[str, ...]:
    """The ``--format`` names of the rows (of one ``kind`` when given), in table order."""
    return tuple(r.name for r in IMPORT_FORMATS if kind is None or r.kind == kind)


def formats_help() -> str:
    """The ``--format`` help: every row's name, what it holds and its extensions."""
    return "; ".join(r.label() for r in IMPORT_FORMATS) + "; default: from the extension and content"


def unknown_format_error(path: Path, tried: Sequence[ImportFormat] = ()) -> UsageError:
    """The error of a file no row reads: what was tried (the rows of its extension, when any) and
    every row's name and extensions, so the user can give ``--format``."""
    listing = "; ".join(f"{r.name} ({', '.join(r.extensions)})" for r in IMPORT_FORMATS)
    if tried:
        why = (f"its extension {path.suffix.lower()} is read as {' or '.join(r.name for r in tried)}, and its content "
               f"is not that")
    else:
        why = f"no format is read from the extension {path.suffix.lower() or '(none)'!r}"
    return UsageError(f"{path}: unknown input format: {why}; give --format NAME, one of: {listing}")


def format_for(fmt: str | None, path: Path, given: Sequence[str] = ()) -> ImportFormat:
    """The row of ``--format fmt``, or (no ``fmt``) the first row whose extension ``path`` has, that
    takes the format-specific options of ``given`` (the options used: ``--points`` makes a ``.mat``
    an FRF export) and whose content test the file passes. Raises :class:`UsageError` (the rows
    listed) when none does, and :class:`ImportDataError` when ``path`` is missing and its format
    cannot be told."""
    if fmt is not None:
        for r in IMPORT_FORMATS:
            if r.name == fmt:
                return r
        raise UsageError(f"--format {fmt}: not a format of import; one of: {', '.join(format_names())}")
    rows = [r for r in IMPORT_FORMATS if path.suffix.lower() in r.extensions]
    if not rows:
        raise unknown_format_error(path)
    specific = {o for r in IMPORT_FORMATS for o in r.options} & set(given)
    taking = [r for r in rows if specific <= set(r.options)]
    if any(r.detect is not None for r in rows) and not path.is_file():
        raise ImportDataError(f"{path} not found: check the path")
    for r in taking + [r for r in rows if r not in taking]:  # the content decides; check_options names a clash
        if r.detect is None or r.detect(path):
            return r
    raise unknown_format_error(path, rows)


def check_options(row: ImportFormat, given: Sequence[str]) -> None:
    """Refuse an option of ``given`` (the command-line options used) that the format of ``row`` does
    not take, and a missing option it requires: one :class:`UsageError` naming the option and the
    formats it belongs to."""
    row_options = {o for r in IMPORT_FORMATS for o in r.options}
    foreign = [o for o in given if o in row_options and o not in row.options]
    if not foreign:
        missing = [o for o in row.requires if o not in given]
        if missing:
            raise UsageError(f"{row.name} input needs {' '.join(missing)} ({row.help})")
        return
    takers = {r.kind for o in foreign for r in IMPORT_FORMATS if o in r.options}
    names = ", ".join(foreign)
    if takers == {"time"} and row.kind == "frf":
        hint = " (the window it applied: --analyser-exp-window)" if "--exp-window" in foreign else ""
        raise UsageError(f"{names}: for time data only; {row.name} holds the analyser's FRFs{hint}")
    if takers == {"frf"} and row.kind == "time":
        raise UsageError(f"{names}: for analyser FRF exports only (--format {'|'.join(format_names('frf'))}); "
                         f"{row.name} holds time data (label it with --reference/--outputs)")
    owners = sorted({r.name for o in foreign for r in IMPORT_FORMATS if o in r.options})
    raise UsageError(f"{names}: for --format {'|'.join(owners)} only, not {row.name} ({row.help})")
