"""Load the INPUT of the fit commands: a recording (HDF5) or a UFF file with dataset-58 FRFs.

The format is chosen from the file's first bytes (HDF5 signature) and, failing that, its
suffix: ``.h5``/``.hdf5``/``.hdf`` -> :func:`analysis.recording.load_frfset`;
``.uff``/``.unv``/``.uf``/``.txt`` (or any other text file) -> :func:`analysis.uff.read_uff58`
(FRFs matched by node/direction labels). Every failure becomes :class:`InputError` with a
message that names the file, the problem and what to do.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import InputError
from .frf import FRFSet

__all__ = ["InputError", "load_input", "detect_format", "parse_band_text", "parse_float_list"]

_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
_H5_SUFFIXES = {".h5", ".hdf5", ".hdf"}
_UFF_SUFFIXES = {".uff", ".unv", ".uf", ".txt", ".asc"}


def detect_format(path: str | Path) -> str:
    """"recording" or "uff" for an existing file; raises InputError otherwise."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"input file {p} not found: check the path")
    if not p.is_file():
        raise InputError(f"input {p} is not a file: give a recording (.h5) or a UFF 58 file (.uff)")
    try:
        with p.open("rb") as fh:
            head = fh.read(512)
    except OSError as exc:
        raise InputError(f"cannot read {p}: {exc.strerror or exc}; check its permissions") from None
    if head.startswith(_HDF5_MAGIC) or p.suffix.lower() in _H5_SUFFIXES:
        return "recording"
    if p.suffix.lower() in _UFF_SUFFIXES or head.lstrip().startswith(b"-1"):
        return "uff"
    raise InputError(
        f"cannot tell the format of {p} (suffix {p.suffix or 'none'!r}): give a recording (.h5) "
        "or a UFF file with dataset-58 FRFs (.uff/.unv)"
    )


def load_input(path: str | Path, *, estimator: str | None = None) -> FRFSet:
    """The FRFs of a recording or a UFF 58 file as one :class:`FRFSet`.

    ``estimator`` chooses the recording's FRF estimate ("H1" or "H2"). FRFs that are entirely
    missing (NaN, e.g. output/reference combinations a UFF file does not hold) are not allowed
    by the fitter: the error names them.
    """
    fmt = detect_format(path)
    if fmt == "recording":
        try:
            from analysis.recording import load_frfset
        except ImportError as exc:  # pragma: no cover - depends on the installed tree
            raise InputError(f"reading recordings needs analysis.recording ({exc})") from None
        try:
            frf = load_frfset(path, estimator=estimator)
        except (OSError, ValueError, KeyError) as exc:
            raise InputError(f"cannot read recording {path}: {exc}") from None
    else:
        from .input_limits import check_input_file, text_data_limit_bytes

        check_input_file(path, "input", text_data_limit_bytes(), InputError)  # the UFF reader holds it all
        try:
            from .uff import read_uff58
        except ImportError as exc:  # pragma: no cover - depends on the installed tree
            raise InputError(f"reading UFF files needs analysis.uff ({exc})") from None
        try:
            frf = read_uff58(path)
        except (OSError, ValueError, KeyError, IndexError) as exc:
            raise InputError(f"cannot read UFF file {path}: {exc}") from None
    bad = ~np.all(np.isfinite(frf.H), axis=2)
    if np.any(bad):
        names = [f"{frf.outputs[o]}/{frf.references[r]}" for o, r in zip(*np.nonzero(bad))]
        raise InputError(
            f"{path}: {len(names)} FRF(s) hold missing or non-finite values ({', '.join(names[:5])}"
            f"{'...' if len(names) > 5 else ''}); remove them from the file or measure them"
        )
    return frf


def parse_band_text(text: str | None) -> tuple[float, float] | None:
    """``"LO:HI"`` (Hz) -> (lo, hi); None stays None. Raises InputError for anything else."""
    if text is None:
        return None
    parts = str(text).split(":")
    if len(parts) != 2:
        raise InputError(f"bad band {text!r}: write LO:HI in Hz, e.g. --band 5:200")
    try:
        lo, hi = float(parts[0]), float(parts[1])
    except ValueError:
        raise InputError(f"bad band {text!r}: LO and HI must be numbers in Hz, e.g. --band 5:200") from None
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo < 0 or lo >= hi:
        raise InputError(f"bad band {text!r}: need 0 <= LO < HI (Hz)")
    return lo, hi


def parse_float_list(text: str, what: str = "frequencies") -> list[float]:
    """``"F1,F2,..."`` -> floats (positive, finite). Raises InputError naming the bad item."""
    out = []
    for item in str(text).split(","):
        item = item.strip()
        if not item:
            continue
        try:
            v = float(item)
        except ValueError:
            raise InputError(f"bad {what} {text!r}: {item!r} is not a number (write e.g. 12.9,34.9,50.8)") from None
        if not np.isfinite(v) or v <= 0:
            raise InputError(f"bad {what} {text!r}: {item!r} must be a positive number")
        out.append(v)
    if not out:
        raise InputError(f"no {what} given in {text!r}")
    return out
