"""Each benchmark's results file is written by the benchmark itself (benchmarks/results.py): every .md and
.json under benchmarks/ is named by a script as its output (``RESULTS = Path(__file__).with_name(...)``,
written through ``recorded`` with ``--write``), or is a hold-out case list with its results beside it
(``CASE_LISTS`` and ``results_of_cases``), or is one of the few inputs listed here with their reader."""
from __future__ import annotations

import fnmatch
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks"
sys.path.insert(0, str(ROOT))

from benchmarks.results import RESULTS_SUFFIX, recorded, results_of_cases  # noqa: E402

#: files under benchmarks/ that a script reads rather than writes -> (the script, why)
INPUTS = {"accuracy/validation/discussion.md": ("accuracy/validation/run_all.py",
                                                "the discussion text run_all fills in with its figures for docs/validation.md"),
          "accuracy/validation/commands.md": ("accuracy/validation/run_all.py",
                                              "the commands section run_all inserts into docs/validation.md"),
          "accuracy/validation/key_section.md": ("accuracy/validation/run_all.py",
                                                 "the analyst's key section (studies/realdata_key.py --markdown "
                                                 "writes it) run_all puts at the end of docs/validation.md")}

RESULTS_DECL = re.compile(r'^RESULTS = Path\(__file__\)\.with_name\("([^"]+)"\)', re.M)
CASES_DECL = re.compile(r'^CASE_LISTS = "([^"]+)"', re.M)


def _scripts() -> dict[Path, str]:
    return {p: p.read_text(encoding="utf-8") for p in sorted(BENCH.rglob("*.py"))}


def _data_files() -> list[Path]:
    return sorted(p for ext in ("*.md", "*.json") for p in BENCH.rglob(ext))


#: the studies' shared command lines: a hold-out study's ``run`` sub-command from ``add_run`` has ``--write``
STUDY_ARGS = BENCH / "studies" / "study_args.py"


def _has_write_option(text: str, scripts: dict[Path, str]) -> bool:
    """A script with a ``--write`` option: its own, or the ``run`` sub-command of :mod:`study_args`."""
    return '"--write"' in text or ("add_run(" in text and '"--write"' in scripts.get(STUDY_ARGS, ""))


def _case_list_owner(path: Path, scripts: dict[Path, str]) -> Path | None:
    """The script beside ``path`` whose CASE_LISTS pattern it matches and that writes results_of_cases."""
    for script, text in scripts.items():
        m = CASES_DECL.search(text)
        if script.parent == path.parent and m and any(fnmatch.fnmatch(path.name, pat) for pat in m.group(1).split()) \
                and "results_of_cases(" in text and _has_write_option(text, scripts) and "write_text_atomic(" in text:
            return script
    return None


def test_every_results_file_has_a_script_that_writes_it() -> None:
    scripts = _scripts()
    files = _data_files()
    assert files, "no results files found: the test looks in the wrong place"
    orphans = []
    for f in files:
        rel = f.relative_to(BENCH).as_posix()
        if rel in INPUTS:
            reader = BENCH / INPUTS[rel][0]
            assert f'"{f.name}"' in scripts[reader], f"{reader} does not read {rel}"
            continue
        if f.name.endswith(RESULTS_SUFFIX):
            stem = f.name.removesuffix(RESULTS_SUFFIX)
            # CASES.results.json (the first run) or CASES.LABEL.results.json (a family's run, a later run)
            heads = [(stem, None)] + ([(stem.rsplit(".", 1)[0], stem.rsplit(".", 1)[1])] if "." in stem else [])
            if any((f.parent / f"{h}.json").is_file() and results_of_cases(f.parent / f"{h}.json", label) == f
                   and _case_list_owner(f.parent / f"{h}.json", scripts) for h, label in heads):
                continue
        elif f.suffix == ".json" and _case_list_owner(f, scripts) is not None:
            continue   # a hold-out case list: an input, drawn by its script, results beside it
        writers = [s for s, text in scripts.items() if s.parent == f.parent and f.name in RESULTS_DECL.findall(text)
                   and "recorded(RESULTS, " in text and "add_write_option(" in text]
        if not writers:
            orphans.append(rel)
    assert not orphans, f"results files no script writes (declare RESULTS and record with --write): {orphans}"


def test_a_script_that_declares_results_writes_them_through_the_atomic_helper() -> None:
    for script, text in _scripts().items():
        for name in RESULTS_DECL.findall(text):
            assert "from benchmarks.results import" in text and "recorded(RESULTS, " in text, script
            assert (script.parent / name).is_file(), f"{script} names {name}, which is not beside it"


def test_recorded_replaces_the_file_only_after_a_whole_run(tmp_path, monkeypatch, capsys) -> None:
    target = tmp_path / "bench_x.md"
    target.write_text("the previous figures\n")
    monkeypatch.setattr(sys, "argv", [str(BENCH / "speed" / "bench_x.py"), "--n", "3", "--write"])
    with pytest.raises(RuntimeError), recorded(target, True):
        print("half a table")
        raise RuntimeError("interrupted")
    assert target.read_text() == "the previous figures\n"          # a failed run leaves the previous results
    with recorded(target, False):
        print("not recorded")
    assert target.read_text() == "the previous figures\n"
    with recorded(target, True):
        print("| a | b |")
    text = target.read_text()
    assert text.startswith("# Results of `benchmarks/speed/bench_x.py`")
    assert "    python benchmarks/speed/bench_x.py --n 3 --write" in text and "| a | b |" in text
    assert "the previous figures" not in text and "half a table" not in text
    assert [p.name for p in tmp_path.iterdir()] == ["bench_x.md"]   # no temporary left beside it
    assert "| a | b |" in capsys.readouterr().out              # the terminal still shows the run


def test_results_of_a_case_list_sit_beside_it() -> None:
    assert results_of_cases(Path("x/diag_holdout_seed3.json")) == Path("x/diag_holdout_seed3.results.json")
