"""Deeply nested JSON/TOML inputs are refused by measuring their nesting before parsing.

The readers never hand such a text to a parser (whose recursion would reach the interpreter's limit):
each test below replaces the parser with one that fails the test if it is called.
"""
from __future__ import annotations

import json

import pytest

from analysis.input_limits import NESTING_LIMIT, nesting_depth, too_deeply_nested

DEEP = "[" * 50000 + "]" * 50000


@pytest.mark.parametrize("text, depth", [
    ('[1, [2, {"a": [3]}]]', 4),
    ('["[[[[", {"{{": "]]"}]', 2),                      # brackets inside strings do not count
    (r'["a\"[[[[", [[1]]]', 3),                          # an escaped quote does not end the string
    (r'["a\\", [[1]]]', 3),                              # an escaped backslash does: the brackets count
    (r'[{"k\\\"[": "\u005b"}]', 2),
    ('"an unterminated [[[[ string', 0),
    ("]]][[", 2),                                        # stray closing brackets count as none
    ("", 0),
])
def test_json_nesting_depth(text, depth):
    assert nesting_depth(text) == depth


def test_toml_nesting_depth_skips_strings_and_comments():
    text = ('title = "a [[[ b"  # [[[[ a comment\n'
            "path = '[[[\\'\n"                              # a literal string: the backslash escapes nothing
            'multi = """\n[[[ "quoted" \\""" ]\n"""\n'
            "lit = '''\n{{{{\n'''\n"
            "[[parts]]\n"
            'x = [[1, 2], {a = ["]"]}]\n')
    assert nesting_depth(text, toml=True) == 3
    assert nesting_depth("a = '[[[' \nb = [[1]]", toml=True) == 2
    assert nesting_depth("a = '[[[' \nb = [[1]]") == 5                # in JSON a single quote opens nothing


def test_the_scan_stops_above_the_limit_and_the_limit_is_exact():
    assert nesting_depth("[" * 10 ** 6, stop_above=NESTING_LIMIT) == NESTING_LIMIT + 1
    assert not too_deeply_nested("[" * NESTING_LIMIT + "]" * NESTING_LIMIT)
    assert too_deeply_nested("[" * (NESTING_LIMIT + 1) + "]" * (NESTING_LIMIT + 1))
    assert too_deeply_nested("a = " + "[" * (NESTING_LIMIT + 1), toml=True)
    assert not too_deeply_nested(json.dumps(["[" * 1000, "{" * 1000]))       # in strings: depth 1


def _never(*args, **kwargs):
    raise AssertionError("a text nested beyond the limit reached the parser")


@pytest.mark.parametrize("depth", [NESTING_LIMIT + 1, 50000])
def test_sep005_refuses_deep_json_before_parsing(tmp_path, monkeypatch, depth):
    from analysis.sep005 import SEP005Error, read_sep005

    p = tmp_path / "deep.json"
    p.write_text("[" * depth + "]" * depth)
    monkeypatch.setattr(json, "loads", _never)
    with pytest.raises(SEP005Error, match=f"is not a JSON SEP005 file \\(nested deeper than {NESTING_LIMIT} levels"):
        read_sep005(p)


@pytest.mark.parametrize("suffix, text", [(".json", DEEP), (".toml", "a = " + DEEP + "\n")])
def test_operator_documents_refuse_deep_input_before_parsing(tmp_path, monkeypatch, suffix, text):
    import tomllib

    from acquisition.errors import SetupError
    from acquisition.textdoc import read_document

    p = tmp_path / f"setup{suffix}"
    p.write_text(text)
    monkeypatch.setattr(json, "loads", _never)
    monkeypatch.setattr(tomllib, "loads", _never)
    with pytest.raises(SetupError, match=f"set-up file .* is not valid {suffix[1:]}: nested deeper than"):
        read_document(p, "set-up file (--setup)", SetupError)


def test_simulator_config_refuses_deep_toml_before_parsing(tmp_path, monkeypatch):
    from simulator import config
    from simulator.config import ConfigError, FrameConfig

    p = tmp_path / "c.toml"
    p.write_text("a = " + DEEP + "\n")
    monkeypatch.setattr(config._toml, "loads", _never)
    with pytest.raises(ConfigError, match="nested too deeply to be a frame configuration"):
        FrameConfig.load(p)


def test_report_fit_file_refuses_deep_json_before_parsing(tmp_path, monkeypatch):
    from analysis.report_html.sources import ReportInputError, load_fit_json

    p = tmp_path / "fit.json"
    p.write_text(DEEP)
    monkeypatch.setattr(json, "loads", _never)
    with pytest.raises(ReportInputError, match="nested too deeply to be a fit file"):
        load_fit_json(p, None)  # refused before the FRF set is looked at
