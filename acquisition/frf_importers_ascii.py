"""Parser of DataPhysics SignalCalc ASCII FRF exports (``Hxy*.txt``, one FRF per file).

SignalCalc's single-signal ASCII export is tab-separated text (Latin-1)::

    Units: Ratio
    Ref Chan:Resp Chan<TAB>0-Z:0-Z          reference and response node-direction
    Channel Name<TAB> : ...
    Channel Comment<TAB> : ...

    Frequency<TAB> Real<TAB> Imaginary      the columns
                                            (blank)
    Units:
    Hz<TAB>(m/s²)(N)<TAB>                    x unit, then the ratio's units as (numerator)(denominator)
    0.0000000000000e+000<TAB>-0.1617429<TAB>0
    ...

The file states neither the coherence nor the number of averages nor the windows: the import holds
the FRF alone (the recording says the coherence and the averages are not known). Point labels
``n:{node}:{dir}`` from the ``Ref Chan:Resp Chan`` line unless ``--reference``/``--outputs`` or a
``--points`` map name them. The multi-signal variant ("Data written for ...") is refused: export
one FRF per file.
"""
from __future__ import annotations

import io
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from analysis.frf import FRFSet
from analysis.input_limits import read_bounded_text, text_data_limit_bytes

from .errors import ImportDataError
from .frf_importers import ImportedFRFs, _check_axis, _finite_frf, _guarded, _motion_quantity

__all__ = ["read_signalcalc_ascii", "is_signalcalc_ascii"]

#: how SignalCalc writes unit symbols it has no ASCII for (Latin-1 superscripts)
_UNIT_SYMBOLS = {"\u00b2": "^2", "\u00b3": "^3"}
_DOF = re.compile(r"^\s*(\d+)\s*-\s*([+-]?[XYZxyz])\s*$")


def is_signalcalc_ascii(path: Path) -> bool:
    """Whether ``path`` starts as a SignalCalc ASCII export: a ``Units:`` first line and a
    ``Ref Chan:Resp Chan`` line among the next few (the multi-signal variant counts too, so that its
    refusal names it)."""
    try:
        with Path(path).open("rb") as fh:
            head = fh.read(2048).decode("latin-1")
    except OSError:
        return False
    lines = head.splitlines()
    return bool(lines) and (lines[0].startswith("Data written for")
                            or (lines[0].startswith("Units:") and any(ln.startswith("Ref Chan:Resp Chan")
                                                                      for ln in lines[1:6])))


def _unit(text: str) -> str:
    """``(m/s²)(N)`` -> ``(m/s^2)/N`` (the single-signal export writes a ratio as two bracketed units)."""
    for k, v in _UNIT_SYMBOLS.items():
        text = text.replace(k, v)
    parts = re.findall(r"\(([^()]*)\)", text)
    if len(parts) != 2 or not all(p.strip() for p in parts):
        return text.strip()
    num, den = (p.strip() for p in parts)
    return f"({num})/{den}" if "/" in num else f"{num}/{den}"


def _points(p: Path, line: str) -> tuple[str, str]:
    """(reference, output) point labels from the ``Ref Chan:Resp Chan`` line's ``0-Z:0-Z``."""
    cells = line.split("\t", 1)
    pair = cells[1].strip().split(":") if len(cells) == 2 else []
    found = [_DOF.match(c) for c in pair]
    if len(found) != 2 or not all(found):
        raise ImportDataError(f"{p}: the 'Ref Chan:Resp Chan' line {line.strip()!r} does not give two node-direction "
                              "pairs like 3-Z:7-Y; export the file again, or label it with --reference/--outputs")
    ref, out = (f"n:{int(m.group(1))}:{m.group(2).upper()}" for m in found if m)
    return ref, out


def read_signalcalc_ascii(path: Path, variables: Sequence[str] | None = None) -> ImportedFRFs:
    """The FRF of one SignalCalc ASCII export (see module doc) as an import of one reference with
    no coherence and an unknown number of averages. ``variables`` is not used (one FRF per file).
    Raises :class:`ImportDataError` naming the file and the line for anything else."""
    return _guarded(_read_signalcalc_ascii, Path(path), variables, "SignalCalc ASCII export")


def _read_signalcalc_ascii(p: Path, variables: Sequence[str] | None = None) -> ImportedFRFs:
    try:
        text = read_bounded_text(p, "SignalCalc ASCII export", text_data_limit_bytes(), ImportDataError, "latin-1")
    except OSError as exc:
        raise ImportDataError(f"cannot read {p}: {exc.strerror}") from None
    lines = text.splitlines()
    if lines and lines[0].startswith("Data written for"):
        raise ImportDataError(f"{p}: a multi-signal SignalCalc ASCII export; export one FRF per file (Hxy...txt)")
    if not lines or not lines[0].startswith("Units:"):
        raise ImportDataError(f"{p} is not a SignalCalc ASCII export (its first line should be 'Units: ...'); "
                              "export the FRF again as ASCII")
    ref_line = next((ln for ln in lines[:8] if ln.startswith("Ref Chan:Resp Chan")), None)
    columns = next((i for i, ln in enumerate(lines[:12]) if ln.split("\t", 1)[0].strip() == "Frequency"), None)
    units = next((i for i, ln in enumerate(lines[:14]) if ln.strip() == "Units:"), None)
    if ref_line is None or columns is None or units is None or units + 1 >= len(lines):
        raise ImportDataError(f"{p}: the header lacks the 'Ref Chan:Resp Chan', 'Frequency ...' column or 'Units:' "
                              "line of a SignalCalc ASCII export; the file is cut short or not such an export")
    names = [c.strip() for c in lines[columns].split("\t")]
    if names[:3] not in (["Frequency", "Real", "Imaginary"], ["Frequency", "Real", "Imag"]):
        raise ImportDataError(f"{p}: columns {names}; only Frequency, Real, Imaginary exports are read: export the "
                              "FRF as real and imaginary parts")
    axis_units = lines[units + 1].split("\t")
    if axis_units[0].strip() != "Hz" or len(axis_units) < 2:
        raise ImportDataError(f"{p}: the units line {lines[units + 1].strip()!r} does not start with Hz and the FRF's "
                              "units; export the FRF over frequency")
    unit = _unit(axis_units[1])
    first_data = units + 2
    rows = [ln for ln in lines[first_data:] if ln.strip() and not ln.lstrip().startswith("#")]
    if len(rows) < 2:  # counted before numpy reads them: no data at all is this error, not numpy's warning
        raise ImportDataError(f"{p}: {len(rows)} data line(s); an FRF needs at least two frequencies")
    try:
        data = np.loadtxt(io.StringIO("\n".join(rows)), delimiter="\t", usecols=(0, 1, 2), ndmin=2)
    except ValueError as exc:
        raise ImportDataError(f"{p}: the data after line {first_data} are not three numbers per line ({exc}); the "
                              "file is damaged: export it again") from None
    ref, out = _points(p, ref_line)
    f = _check_axis(p, "Frequency", data[:, 0])
    h = _finite_frf(p, "Real/Imaginary", data[:, 1] + 1j * data[:, 2])
    q = _motion_quantity(p, "the FRF", unit)
    s = FRFSet(freq_hz=f, H=h[None, None, :], quantity=q, outputs=(out,), references=(ref,), unit=unit,
               coherence=None, meta={"source": str(p)})
    return ImportedFRFs([s], [None], str(p), "signalcalc-ascii", {})
