"""Fuzzing the UFF 58 reader (``analysis.uff.read_uff58``) with damaged files.

Base files are real impactlab UFF exports (binary and ASCII dataset 58); hypothesis replaces,
inserts and deletes bytes and lines. The reader either returns a valid :class:`FRFSet` or raises
:class:`UFFError` with a message. Cases per test: ``IMPACTLAB_FUZZ_EXAMPLES`` (default 200).
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from analysis.frf import FRFSet
from analysis.uff import UFFError, _frf_set_dicts, _write_sets, read_uff58

N = int(os.environ.get("IMPACTLAB_FUZZ_EXAMPLES", "200"))
FUZZ = settings(max_examples=N, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow])


def _base_files() -> dict[str, bytes]:
    f = np.arange(0, 20.0, 2.5)
    rng = np.random.default_rng(0)
    H = rng.normal(size=(2, 1, f.size)) + 1j * rng.normal(size=(2, 1, f.size))
    s = FRFSet(f, H, "accelerance", ("left:9:Y", "top:4:X"), ("right:6:-X",), "(m/s^2)/N",
               rng.uniform(size=H.shape), None, {})
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for binary in (1, 0):
            sets = _frf_set_dicts(s, ("fuzz", "", ""))
            for d in sets:
                d["binary"] = binary
            p = Path(tmp) / f"b{binary}.uff"
            _write_sets(p, sets)
            out["binary" if binary else "ascii"] = p.read_bytes()
    return out


BASES = _base_files()


def _read(raw: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "x.uff"
        p.write_bytes(raw)
        try:
            frf = read_uff58(p)
        except UFFError as exc:
            assert str(exc)
            return
    assert isinstance(frf, FRFSet) and frf.H.shape[2] == frf.freq_hz.size
    assert np.all(np.isfinite(frf.freq_hz))
    measured = ~np.all(np.isnan(frf.H), axis=2)  # combinations the file does not hold are all-NaN markers
    assert np.all(np.isfinite(frf.H[measured])), "non-finite FRF values passed on"


def test_bases_read_back():
    for raw in BASES.values():
        with tempfile.TemporaryDirectory() as tmp:
            p = Path(tmp) / "x.uff"
            p.write_bytes(raw)
            assert read_uff58(p).H.shape == (2, 1, 8)


@FUZZ
@given(kind=st.sampled_from(sorted(BASES)), data=st.data())
def test_mutated_bytes(kind, data):
    raw = bytearray(BASES[kind])
    for _ in range(data.draw(st.integers(1, 6))):
        k = data.draw(st.integers(0, len(raw) - 1))
        op = data.draw(st.sampled_from(("set", "digit", "insert", "delete")))
        if op == "set":
            raw[k] = data.draw(st.integers(0, 255))
        elif op == "digit":
            raw[k] = ord(data.draw(st.sampled_from("0123456789-+.eE ")))
        elif op == "insert":
            raw[k:k] = data.draw(st.binary(min_size=1, max_size=4))
        else:
            del raw[k:k + data.draw(st.integers(1, 40))]
    _read(bytes(raw))


@FUZZ
@given(kind=st.sampled_from(sorted(BASES)), data=st.data())
def test_mutated_lines(kind, data):
    lines = BASES[kind].split(b"\n")
    for _ in range(data.draw(st.integers(1, 4))):
        k = data.draw(st.integers(0, len(lines) - 1))
        op = data.draw(st.sampled_from(("drop", "dup", "cut", "blank", "field")))
        if op == "drop":
            del lines[k]
        elif op == "dup":
            lines.insert(k, lines[k])
        elif op == "cut":
            lines = lines[:max(k, 1)]
        elif op == "blank":
            lines[k] = b""
        else:
            lines[k] = data.draw(st.sampled_from([b"    -1", b"    58", b"  58b     1     1", b"1 2 3",
                                                  b"nan nan", b"99999999999999999999", b"    4     0     0"]))
        if not lines:
            break
    _read(b"\n".join(lines))


@FUZZ
@given(raw=st.binary(max_size=300))
def test_random_bytes(raw):
    _read(raw)
