"""Fuzzing the readers of numbers users hand in: the importers fed NaN and infinities, the SEP005
reader, the fit JSON reader, the simulator's TOML configuration and the station's JSON API.

Each case ends in a valid result holding only finite numbers, or in the reader's documented error
with a message; never another exception, never a non-finite value passed on. The station must
answer every request with a status below 500 and write no traceback. Cases per test:
``IMPACTLAB_FUZZ_EXAMPLES`` (default 200; the station API a quarter of it).
"""
from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from acquisition.importers import ImportDataError, read_lvm, read_numpy, read_sep005_test
from analysis.frf import FRFSet
from analysis.report_html.sources import ReportInputError, load_fit_json
from analysis.sep005 import SEP005Error, read_sep005

N = int(os.environ.get("IMPACTLAB_FUZZ_EXAMPLES", "200"))
FUZZ = settings(max_examples=N, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

ODD_FLOATS = st.sampled_from([float("nan"), float("inf"), -float("inf"), 1e308, -1e308, 5e-324, 0.0, -0.0])
NUMBER = st.floats(allow_nan=True, allow_infinity=True) | ODD_FLOATS | st.integers(-10**6, 10**6)
JSONISH = st.recursive(st.none() | st.booleans() | NUMBER | st.text(max_size=6),
                       lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=5), c, max_size=3),
                       max_leaves=8)


def _import_checked(read, *args) -> None:
    """``read(*args)`` gives a test holding only finite samples and a finite rate, or ImportDataError."""
    try:
        test = read(*args)
    except ImportDataError as exc:
        assert str(exc)
        return
    assert math.isfinite(test.fs_hz) and test.fs_hz > 0
    for h in test.hits:
        assert np.all(np.isfinite(h)), "non-finite samples passed on"


# ---------------------------------------------------------------------- importers with bad numbers
@FUZZ
@given(values=st.lists(st.lists(NUMBER, min_size=2, max_size=2), min_size=2, max_size=12),
       dx=NUMBER | st.sampled_from(["1e-4", "1e-300", "", "x"]))
def test_lvm_with_non_finite_and_extreme_values(values, dx):
    text = ("LabVIEW Measurement\t\nSeparator\tTab\nDecimal_Separator\t.\n***End_of_Header***\t\n\t\nChannels\t2\t\n"
            f"Samples\t{len(values)}\t{len(values)}\nY_Unit_Label\tN\tg\nDelta_X\t{dx}\t{dx}\n***End_of_Header***\t\n"
            "X_Value\tforce\tacc\tComment\n" + "".join(f"\t{a}\t{b}\n" for a, b in values))
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "x.lvm"
        p.write_text(text)
        _import_checked(read_lvm, p)


@FUZZ
@given(values=st.lists(NUMBER, min_size=4, max_size=24), fs=NUMBER)
def test_numpy_with_non_finite_values(values, fs):
    arr = np.array(values[: len(values) // 2 * 2], dtype=float).reshape(2, -1)
    desc = {"sample_rate_hz": fs, "channels": [{"name": "f", "unit": "N"}, {"name": "a", "unit": "g"}]}
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "h.npy"
        np.save(p, arr)
        _import_checked(read_numpy, [p], desc)


# ---------------------------------------------------------------------- SEP005
CHANNEL = st.fixed_dictionaries(
    {"name": st.text(max_size=5) | JSONISH, "unit_str": st.sampled_from(["N", "g", "m/s^2"]) | JSONISH,
     "data": st.lists(NUMBER, max_size=8) | JSONISH},
    optional={"fs": NUMBER | JSONISH, "time": st.lists(NUMBER, max_size=8) | JSONISH,
              "quantity": st.sampled_from(["f", "a", "v", "x"]) | JSONISH, "group": st.sampled_from(["hit-1", "hit-2"]),
              "trigger_index": st.integers(-3, 10) | JSONISH, "point": st.text(max_size=8) | JSONISH})


@FUZZ
@given(doc=st.lists(CHANNEL | JSONISH, max_size=4) | JSONISH | st.fixed_dictionaries({"channels": st.lists(CHANNEL)}),
       deep=st.integers(0, 3))
def test_sep005_documents(doc, deep):
    text = json.dumps(doc, allow_nan=True)
    if deep == 3:
        text = "[" * 20000 + text + "]" * 20000
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "s.json"
        p.write_text(text)
        try:
            channels = read_sep005(p)
        except SEP005Error as exc:
            assert str(exc)
        else:
            for ch in channels:
                assert np.all(np.isfinite(ch["data"])) and math.isfinite(ch["fs"]) and ch["fs"] > 0
        _import_checked(read_sep005_test, p)


# ---------------------------------------------------------------------- fit JSON
def _frf() -> FRFSet:
    f = np.linspace(1.0, 40.0, 40)
    return FRFSet(f, np.ones((1, 1, f.size), complex), "accelerance", ("a:1:X",), ("b:1:X",), "(m/s^2)/N",
                  None, None, {})


FRF = _frf()
PAIR = st.lists(NUMBER, min_size=2, max_size=2) | JSONISH
POLE = st.fixed_dictionaries({"pole": PAIR}, optional={"freq_hz_std": NUMBER | JSONISH, "damping_std": NUMBER | JSONISH})
FIT = st.fixed_dictionaries(
    {"poles": st.lists(POLE, min_size=1, max_size=3) | JSONISH,
     "residues": st.lists(st.fixed_dictionaries({"output": st.sampled_from(["a:1:X", "x"]) | JSONISH,
                                                 "reference": st.sampled_from(["b:1:X"]) | JSONISH,
                                                 "values": st.lists(PAIR, max_size=3) | JSONISH}), max_size=2) | JSONISH,
     "band": st.lists(NUMBER, min_size=2, max_size=2) | JSONISH},
    optional={"quantity": st.sampled_from(["accelerance", "mobility", "x"]) | JSONISH,
              "residual_form": st.sampled_from(["physical", "none", "odd"]) | JSONISH,
              "upper_residual": JSONISH, "warnings": JSONISH})


@FUZZ
@given(doc=FIT | JSONISH)
def test_fit_json_documents(doc):
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "fit.json"
        p.write_text(json.dumps(doc, allow_nan=True))
        try:
            fit = load_fit_json(p, FRF)
        except ReportInputError as exc:
            assert str(exc) and "\n" not in str(exc)
            return
    poles = np.asarray(fit.model.poles)
    assert np.all(np.isfinite(poles)) and np.all(poles.real < 0)
    assert np.all(np.isfinite(fit.model.residues)) and all(math.isfinite(b) for b in fit.band)


# ---------------------------------------------------------------------- simulator TOML configuration
def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, (int,)):
        return str(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return json.dumps(str(v))


KEYS = [("material", "youngs_modulus_pa"), ("material", "density_kg_m3"), ("material", "poisson_ratio"),
        ("components.left", "n_elements"), ("components.top", "end_m"), ("sections.column", "width_m"),
        ("sensors.accelerometer", "mass_kg"), ("damping", "zeta"), ("damping", "zeta_default"),
        ("modes", "max_freq_hz"), ("hammer", "tip"), ("supports", "stiffness"), ("sampling", "sample_rate_hz"),
        ("noise", "seed"), ("damage", "cracked_elements")]
TOML_VALUE = (NUMBER | st.booleans() | st.text(max_size=4) | st.lists(NUMBER, max_size=7)
              | st.integers(10**5, 10**12))


@FUZZ
@given(changes=st.lists(st.tuples(st.sampled_from(KEYS), TOML_VALUE), max_size=4), junk=st.text(max_size=30))
def test_simulator_config_files(changes, junk):
    from simulator.config import ConfigError, FrameConfig

    tables: dict = {}
    for (table, key), value in changes:
        tables.setdefault(table, {})[key] = value
    text = "".join(f"[{t}]\n" + "".join(f"{k} = {_toml_value(v)}\n" for k, v in kv.items()) for t, kv in tables.items())
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "c.toml"
        p.write_text(text + (junk if len(changes) % 2 else ""))
        try:
            cfg = FrameConfig.load(p)
        except ConfigError as exc:
            assert str(exc)
            return
    from simulator.config import _first_bad_number

    assert _first_bad_number(cfg.raw) is None  # every accepted number finite and within the bound


# ---------------------------------------------------------------------- the station's JSON API
@pytest.fixture(scope="module")
def station(tmp_path_factory):
    import signal
    import threading

    from station_support import StationProcess

    d = tmp_path_factory.mktemp("station_fuzz")
    s = StationProcess(["--device", "sim://?seed=9", "--out", str(d / "rec.h5"), "--points", "left:9:Y,top:4:X",
                        "--hits", "2"], cwd=d)
    logged: dict[str, list[str]] = {"out": [], "err": []}
    readers = [threading.Thread(target=lambda f=f, k=k: logged[k].extend(f), daemon=True)  # drain: one log line
               for f, k in ((s.proc.stdout, "out"), (s.proc.stderr, "err"))]    # per bad request fills a pipe
    for t in readers:
        t.start()
    yield s
    s.proc.send_signal(signal.SIGTERM)
    s.proc.wait(timeout=120)
    for t in readers:
        t.join(timeout=30)
    for pipe in (s.proc.stdout, s.proc.stderr):
        if pipe is not None:
            pipe.close()
    err = "".join(logged["err"])
    assert "Traceback" not in err, err[-3000:]


ACTIONS = st.sampled_from(["setup", "auto", "pause", "resume", "remeasure", "skip", "explode", "undo"]) | JSONISH
SETUP_LIKE = st.fixed_dictionaries({}, optional={
    "sample_rate_hz": NUMBER | JSONISH, "block_size": NUMBER | JSONISH,
    "channels": st.lists(st.fixed_dictionaries({}, optional={"name": JSONISH, "range_v": NUMBER | JSONISH,
                                                             "coupling": JSONISH}), max_size=3) | JSONISH,
    "trigger": JSONISH})


@settings(max_examples=max(10, N // 4), derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                 HealthCheck.data_too_large])
@given(path=st.sampled_from(["/api/setup/check", "/api/action", "/api/lease"]),
       body=st.fixed_dictionaries({}, optional={"client": st.just("fuzz") | JSONISH, "action": ACTIONS,
                                                "setup": SETUP_LIKE | JSONISH,
                                                "windows": st.fixed_dictionaries({}, optional={"force": JSONISH,
                                                                                               "exp": JSONISH}) | JSONISH,
                                                "take": JSONISH, "on": JSONISH, "point": JSONISH}) | JSONISH,
       raw_nan=st.booleans())
def test_station_json_api(station, path, body, raw_nan):
    from station_support import Api

    api = Api(station, "fuzz")
    data = json.dumps(body, allow_nan=True).encode() if raw_nan else json.dumps(body, allow_nan=True).replace(
        "NaN", "null").replace("Infinity", "1e308").encode()
    status, answer = api.request("POST", path, raw=data)
    assert status < 500, (status, answer)
    if status >= 400:
        assert isinstance(answer, dict) and answer.get("error")
