"""Fuzzing the importers (LabVIEW .lvm text, numpy + description, DataPhysics-like .mat, SignalCalc ASCII
and UFF 58 FRF exports) and the 16-bit counts an import stores.

Whatever the file holds, a reader either returns a consistent :class:`ImportedTest` (finite
positive sample rate, every hit ``(n_channels, n)``, sensitivities finite and nonzero or unknown)
or raises :class:`ImportDataError` with a message; never a KeyError/IndexError/ZeroDivisionError/
numpy error. The counts of an imported hit give back every sample within half a step, or the hit
is refused. Cases per test: ``IMPACTLAB_FUZZ_EXAMPLES`` (default 200).
"""
from __future__ import annotations

import io
import json
import math
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from acquisition.importers import (
    ImportDataError,
    ImportedTest,
    channel_roles,
    imported_hits,
    load_description,
    read_dataphysics_mat,
    read_lvm,
    read_numpy,
)

N = int(os.environ.get("IMPACTLAB_FUZZ_EXAMPLES", "200"))
FUZZ = settings(max_examples=N, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


def _check(test) -> None:
    assert math.isfinite(test.fs_hz) and test.fs_hz > 0
    assert test.hits, "an import with no hit"
    for h in test.hits:
        assert h.ndim == 2 and h.shape[0] == len(test.channels) and h.shape == test.hits[0].shape
        assert np.all(np.isfinite(h)), "non-finite samples passed on"
    for c in test.channels:
        s = c["sensitivity"]
        assert math.isnan(s) or (math.isfinite(s) and s != 0), f"sensitivity {s!r} passed on"


def _valid_lvm(decimal: str = ",", n: int = 6) -> str:
    lines = ["LabVIEW Measurement\t", "Writer_Version\t2", "Separator\tTab", f"Decimal_Separator\t{decimal}",
             "Multi_Headings\tYes", "X_Columns\tNo", "***End_of_Header***\t", "\t"]
    for seg in range(2):
        dx = "1.5625E-4".replace(".", decimal)
        lines += ["Channels\t2\t\t", f"Samples\t{n}\t{n}\t", "Y_Unit_Label\tNewtons\tg\t", "X_Dimension\tTime\tTime\t",
                  f"Delta_X\t{dx}\t{dx}\t", "***End_of_Header***\t\t\t", "X_Value\tForce\tAcceleration\tComment"]
        for k in range(n):
            lines.append(f"\t{k * 0.5 + seg:.4f}\t{-k * 0.25:.4f}".replace(".", decimal))
        lines.append("")
    return "\n".join(lines) + "\n"


LVM_LINES = _valid_lvm().splitlines()
TOKENS = ["\t", ",", ".", "0", "-1", "nan", "inf", "1e309", "Channels", "X_Value", "***End_of_Header***",
          "Delta_X", "Y_Unit_Label", "Separator", "Decimal_Separator", "Comma", "Space", "X_Columns", "Multi",
          "", "abc", "\u00e9"]


def _mutated_lines(draw, lines: list[str], sep: str) -> list[str]:
    """``lines`` after 1..6 random drops, duplicates, cuts, swaps or cell edits (cells split at ``sep``)."""
    lines = list(lines)
    for _ in range(draw(st.integers(1, 6))):
        if not lines:
            break
        op = draw(st.sampled_from(("drop", "dup", "edit", "cut", "swap")))
        k = draw(st.integers(0, len(lines) - 1))
        if op == "drop":
            del lines[k]
        elif op == "dup":
            lines.insert(k, lines[k])
        elif op == "cut":
            lines = lines[:k]
        elif op == "swap":
            j = draw(st.integers(0, len(lines) - 1))
            lines[k], lines[j] = lines[j], lines[k]
        else:
            cells = lines[k].split(sep) if sep else [lines[k]]
            c = draw(st.integers(0, len(cells) - 1))
            cells[c] = draw(st.sampled_from(TOKENS + ["Units:", "Hz", "Real", "Imaginary", "-1", "58", "1e400"])
                            | st.text(max_size=6))
            lines[k] = (sep or "").join(cells)
    return lines


@st.composite
def lvm_texts(draw) -> str:
    return "\n".join(_mutated_lines(draw, LVM_LINES, "\t")) + "\n"


def _write(tmp: Path, name: str, data: str | bytes) -> Path:
    p = tmp / name
    if isinstance(data, str):
        p.write_text(data, encoding="latin-1", errors="replace")
    else:
        p.write_bytes(data)
    return p


@FUZZ
@given(text=lvm_texts())
def test_lvm_mutated_text(text):
    with tempfile.TemporaryDirectory() as tmp:
        p = _write(Path(tmp), "x.lvm", text)
        try:
            _check(read_lvm(p))
        except ImportDataError as exc:
            assert str(exc)


@FUZZ
@given(raw=st.binary(max_size=400))
def test_lvm_random_bytes_after_the_magic_line(raw):
    with tempfile.TemporaryDirectory() as tmp:
        p = _write(Path(tmp), "x.lvm", b"LabVIEW Measurement\t\n" + raw)
        try:
            _check(read_lvm(p))
        except ImportDataError as exc:
            assert str(exc)


# ---------------------------------------------------------------------- numpy + description
JSONISH = st.recursive(st.none() | st.booleans() | st.integers(-3, 5) | st.floats(allow_nan=True) | st.text(max_size=5),
                       lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=4), c, max_size=3),
                       max_leaves=6)
CHANNEL = st.fixed_dictionaries({}, optional={
    "name": JSONISH | st.text(max_size=5), "unit": st.sampled_from(["N", "g", "m/s^2", "V", ""]) | JSONISH,
    "quantity": st.sampled_from(["force", "acceleration"]) | JSONISH, "point": st.text(max_size=8) | JSONISH,
    "sensitivity": st.floats(allow_nan=True) | JSONISH})
DESCRIPTION = st.fixed_dictionaries({}, optional={
    "channels": st.lists(CHANNEL | JSONISH, max_size=4) | JSONISH,
    "layout": st.sampled_from(["channels_first", "samples_first", "sideways"]) | JSONISH,
    "time_row": st.integers(-3, 4) | JSONISH,
    "sample_rate_hz": st.floats(allow_nan=True, allow_infinity=True) | st.integers(-5, 10000) | JSONISH})


@FUZZ
@given(description=DESCRIPTION,
       shapes=st.lists(st.tuples(st.integers(0, 4), st.integers(0, 6)), min_size=1, max_size=3),
       ndim=st.sampled_from([1, 2, 3]), dtype=st.sampled_from(["f8", "i2", "c16", "U3"]),
       as_file=st.booleans())
def test_numpy_with_random_descriptions(description, shapes, ndim, dtype, as_file):
    with tempfile.TemporaryDirectory() as tmp:
        paths = []
        rng = np.random.default_rng(len(paths))
        for k, (a, b) in enumerate(shapes):
            shape = {1: (a * b,), 2: (a, b), 3: (a, b, 2)}[ndim]
            arr = (rng.standard_normal(shape) * 10).astype(dtype) if dtype != "U3" else np.full(shape, "ab")
            paths.append(Path(tmp) / f"h{k}.npy")
            np.save(paths[-1], arr)
        try:
            if as_file:
                d = _write(Path(tmp), "d.json", json.dumps(description, allow_nan=True))
                description = load_description(d)
            _check(read_numpy(paths, description))
        except ImportDataError as exc:
            assert str(exc)


@FUZZ
@given(raw=st.binary(max_size=200))
def test_numpy_garbage_files_and_descriptions(raw):
    with tempfile.TemporaryDirectory() as tmp:
        p = _write(Path(tmp), "h.npy", raw)
        d = _write(Path(tmp), "d.json", raw)
        t = _write(Path(tmp), "d.toml", raw)
        for attempt in (lambda: load_description(d), lambda: load_description(t),
                        lambda: read_numpy([p], {"channels": [{"unit": "N"}], "sample_rate_hz": 100.0})):
            try:
                out = attempt()
                if hasattr(out, "hits"):
                    _check(out)
            except ImportDataError as exc:
                assert str(exc)


# ---------------------------------------------------------------------- DataPhysics-like .mat
ARRAYS = st.sampled_from(["good", "1d", "3col", "empty", "one_row", "const_t", "nan_t", "str", "bad_dt", "complex",
                          "real_complex"])


def _block(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    t = (np.arange(n) - 2) / 1000.0
    x = rng.standard_normal(n)
    return {"good": np.column_stack([t, x]), "1d": x, "3col": np.column_stack([t, x, x]), "empty": np.zeros((0, 2)),
            "one_row": np.column_stack([t, x])[:1], "const_t": np.column_stack([np.zeros(n), x]),
            "nan_t": np.column_stack([t * np.nan, x]), "str": np.array(["abc"]),
            "bad_dt": np.column_stack([-t, x]), "complex": np.column_stack([t, x + 1j * x]),
            "real_complex": np.column_stack([t, x]).astype(complex)}[kind]


@FUZZ
@given(kinds=st.lists(ARRAYS, min_size=1, max_size=3), n=st.integers(1, 12), windowed=st.booleans(),
       sens=st.sampled_from([None, "short", "ok", "str", "inf", "zero", "complex"]),
       unit=st.sampled_from([None, "ok", "num", "long"]),
       gap=st.booleans())
def test_mat_files_with_odd_blocks(kinds, n, windowed, sens, unit, gap):
    rng = np.random.default_rng(n)
    content = {}
    for k, kind in enumerate(kinds):
        content[f"X{k + 1 + (2 if gap and k else 0)}"] = _block(kind, n, rng)
        content[f"W{k + 1}"] = _block(kinds[-1 - k], n, rng)
    if sens is not None:
        content["Sensitivity"] = {"short": np.array([1.0]), "ok": np.ones(len(kinds)), "str": np.array(["x"]),
                                  "inf": np.full(len(kinds), np.inf), "zero": np.zeros(len(kinds)),
                                  "complex": np.ones(len(kinds)) * (1 + 1j)}[sens]
    if unit is not None:
        content["Unit"] = {"ok": np.array(["N"] * len(kinds)), "num": np.arange(3.0), "long": np.array(["g"] * 9)}[unit]
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "x.mat"
        scipy.io.savemat(p, content)
        try:
            _check(read_dataphysics_mat(p, windowed=windowed))
        except ImportDataError as exc:
            assert str(exc)


@FUZZ
@given(data=st.data())
def test_mat_mutated_bytes(data):
    buf = io.BytesIO()
    t = np.arange(8) / 100.0
    scipy.io.savemat(buf, {"X1": np.column_stack([t, np.sin(t)]), "X2": np.column_stack([t, np.cos(t)]),
                           "Sensitivity": np.array([2.25, 100.0]), "Unit": np.array(["N", "g"])})
    raw = bytearray(buf.getvalue())
    for _ in range(data.draw(st.integers(1, 6))):
        k = data.draw(st.integers(0, len(raw) - 1))
        raw[k] = data.draw(st.integers(0, 255))
    if data.draw(st.booleans()):
        raw = raw[:data.draw(st.integers(0, len(raw)))]
    with tempfile.TemporaryDirectory() as tmp:
        p = _write(Path(tmp), "x.mat", bytes(raw))
        try:
            _check(read_dataphysics_mat(p))
        except ImportDataError as exc:
            assert str(exc)


# ---------------------------------------------------------------------- 16-bit counts of an import
SAMPLE = (st.floats(allow_nan=False, allow_infinity=False)
          | st.sampled_from([1e308, -1e308, 1.7976931348623157e308, 5e-324, 1e-310, 0.0, 1e4, 0.1, -0.1]))


@FUZZ
@given(force=st.lists(SAMPLE, min_size=2, max_size=16), response=st.lists(SAMPLE, min_size=2, max_size=16))
def test_imported_hits_give_back_every_sample_within_half_a_step_or_refuse(force, response):
    n = min(len(force), len(response))
    data = np.array([force[:n], response[:n]])
    channels = [{"name": "f", "quantity": "force", "unit": "N", "sensitivity": math.nan, "point": "n:1:Z"},
                {"name": "a", "quantity": "acceleration", "unit": "g", "sensitivity": math.nan, "point": "n:2:Z"}]
    test = ImportedTest(1000.0, channels, [data], [], "fuzz.npy")
    try:
        (hit,) = imported_hits(test, channel_roles(test))
    except ImportDataError as exc:
        assert str(exc).startswith("fuzz.npy: hit 1, channel ")
        return
    step = np.asarray(hit.eu_per_count)[:, None]
    assert np.all(np.isfinite(hit.data)) and np.all(step > 0)
    assert np.all(np.abs(hit.data - data) <= 0.5 * step * (1 + 1e-9)), "a sample moved by more than half a step"


# ---------------------------------------------------------------------- analyser FRF exports as text
def _check_frfs(imp) -> None:
    """An import of an analyser's FRFs is consistent: one reference per set, finite values on a
    strictly increasing axis, a coherence (when there is one) within [0, 1] of the FRFs' shape."""
    assert imp.sets and len(imp.sets) == len(imp.n_averages)
    for s in imp.sets:
        assert s.n_references == 1 and s.H.shape == (s.n_outputs, 1, s.freq_hz.size)
        assert np.all(np.isfinite(s.H)) and np.all(np.diff(s.freq_hz) > 0)
        if s.coherence is not None:
            assert s.coherence.shape == s.H.shape and np.all((s.coherence >= 0) & (s.coherence <= 1))


def _ascii_lines() -> list[str]:
    from test_importers_registry import _frf, signalcalc_ascii_text

    f = np.arange(6) * 0.5
    return signalcalc_ascii_text(f, _frf(f)).split("\r\n")


def _uff_lines() -> list[str]:
    from uff58_text import Record58, record_text

    f = np.arange(5) * 0.5
    h = (1 + np.arange(5)) * (1 - 0.5j)
    return (record_text(Record58(4, (2, 3), (1, 3), 0.0, 0.5, h, ("FRF", "estimator H1 averages 3")))
            + record_text(Record58(6, (2, 3), (1, 3), 0.0, 0.5, np.linspace(0.2, 0.9, f.size)))).split("\n")


ASCII_LINES = _ascii_lines()
UFF_LINES = _uff_lines()


def _read_ascii(p: Path):
    from acquisition.frf_importers_ascii import read_signalcalc_ascii

    return read_signalcalc_ascii(p)


def _read_uff(p: Path):
    from acquisition.frf_importers import read_uff58_frfs

    return read_uff58_frfs(p)


#: the FRF-export readers fuzzed on mutated text: (file name, base lines, cell separator, line end, reader)
FRF_TEXTS = {"signalcalc-ascii": ("Hxysv00001.txt", ASCII_LINES, "\t", "\r\n", _read_ascii),
             "uff58": ("frfs.uff", UFF_LINES, "", "\n", _read_uff)}


@pytest.mark.parametrize("fmt", sorted(FRF_TEXTS))
@FUZZ
@given(data=st.data())
def test_frf_exports_mutated_text(fmt, data):
    name, lines, sep, end, read = FRF_TEXTS[fmt]
    with tempfile.TemporaryDirectory() as tmp:
        p = _write(Path(tmp), name, end.join(_mutated_lines(data.draw, lines, sep)))
        try:
            _check_frfs(read(p))
        except ImportDataError as exc:
            assert str(exc)


CSV_LINES = ['"Force","Acc","Fs",'] + [f"{math.sin(k):.6f},{math.cos(k):.6f},{'100' if k == 0 else ''},"
                                     for k in range(12)]
CSV_DESCRIPTION = {"sample_rate_hz": 100.0, "columns": ["Force", "Acc"], "excitation": "continuous",
                   "block_samples": 4, "skip_blocks": 1,
                   "channels": [{"name": "Force", "unit": "N"}, {"name": "Acc", "unit": "g"}]}


@FUZZ
@given(data=st.data(), block=st.sampled_from([None, 1, 4, 5, 40, "x"]), columns=st.sampled_from(
    [["Force", "Acc"], ["Acc"], ["Nope"], [], "Force", [1, 2]]))
def test_csv_tables_mutated_text_and_descriptions(data, block, columns):
    from acquisition.importers import read_csv_table

    text = "\n".join(_mutated_lines(data.draw, CSV_LINES, ","))
    description = {**CSV_DESCRIPTION, "block_samples": block, "columns": columns}
    with tempfile.TemporaryDirectory() as tmp:
        p = _write(Path(tmp), "x.csv", text)
        try:
            _check(read_csv_table([p], description))
        except ImportDataError as exc:
            assert str(exc)
