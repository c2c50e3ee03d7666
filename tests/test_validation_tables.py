"""The tables of docs/validation.md that the real-data studies print are on the page as printed: the automatic
band (benchmarks/studies/default_band_realdata.py, kept in the discussion run_all fills in) and the analyst's
key (benchmarks/studies/realdata_key.py --markdown writes its section, run_all puts it at the page's end).
Without the data the page is checked against its sources; with it the bolted beam's rows are re-run."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.accuracy.validation.datasets import DATASETS  # noqa: E402
from benchmarks.studies import default_band_realdata as band_study  # noqa: E402
from benchmarks.studies import realdata_key as key_study  # noqa: E402

PAGE = ROOT / "docs" / "validation.md"
DISCUSSION = ROOT / "benchmarks" / "accuracy" / "validation" / "discussion.md"
BAND_HEAD = "## The automatic band on real data"


def _band_section(text: str) -> str:
    start = text.index(BAND_HEAD)
    end = text.find("\n## ", start + len(BAND_HEAD))
    return text[start:end if end >= 0 else len(text)].strip()


def _band_rows(text: str) -> dict[str, list[str]]:
    """The automatic-band table's rows by dataset label, as cells."""
    rows = [line for line in _band_section(text).splitlines() if line.startswith("| ") and "---" not in line]
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in rows]
    return {c[0]: c for c in cells[1:]}


def test_the_page_shows_the_automatic_band_section_of_the_discussion_whole():
    """The section (its table the study's output) is in docs/validation.md as discussion.md has it: a hand
    edit of either page shows."""
    section = _band_section(DISCUSSION.read_text(encoding="utf-8"))
    assert "{" not in section               # no figure to fill in: run_all copies it as it is
    assert section in PAGE.read_text(encoding="utf-8")
    rows = _band_rows(section)
    assert list(rows) == [d.label for d in DATASETS]
    assert all(len(c) == len(band_study.COLUMNS) for c in rows.values())


def test_the_page_ends_with_the_key_section_the_key_study_wrote():
    section = key_study.KEY_SECTION.read_text(encoding="utf-8").strip()
    assert section.startswith("## The automatic fit against an analyst's key")
    assert PAGE.read_text(encoding="utf-8").rstrip().endswith(section)
    lines = [line for line in section.splitlines() if line.startswith("| ") and "---" not in line]
    assert [line.split("|")[1].strip() for line in lines[1:]] == [d.key for d in DATASETS]


def _scored(key: str, poles: list[float], success: bool) -> dict:
    from benchmarks.accuracy.validation.key import KEYS, score

    s = score(KEYS[key], poles, success)
    s.update(key=key, poles=poles, zeta_percent=[0.5] * len(poles), zeta_std_percent=[0.05] * len(poles))
    return s


def test_the_key_section_is_made_from_the_scored_rows():
    """No data: two scored rows give the heading, the table (one line per row, missed and spurious poles
    named) and the text with the bolted beam's 54 Hz pole as scored."""
    from benchmarks.accuracy.validation.key import KEYS

    pyuff = [a.freq_hz for a in KEYS["pyuff_3frf"].accepted]
    unesp = [a.freq_hz for a in KEYS["unesp_boltedbeam"].accepted]
    rows = [_scored("pyuff_3frf", pyuff[1:] + [300.0], True), _scored("unesp_boltedbeam", unesp, True)]
    rows[1]["zeta_percent"][[round(f) for f in unesp].index(54)] = 0.119
    text = key_study.markdown_section(rows)
    assert text.startswith("## The automatic fit against an analyst's key\n")
    assert "| pyuff_3frf | 5 / 6 | 51.52 | 300 | True | False |" in text.splitlines()
    assert f"| unesp_boltedbeam | {len(unesp)} / {len(unesp)} | - | - | True | True |" in text.splitlines()
    assert "(0.12 +- 0.05 %)" in text and "{" not in text


def test_the_whole_table_only_goes_to_the_page():
    with pytest.raises(SystemExit) as exc:
        key_study.main(["--markdown", "--only", "pyuff_3frf"])
    assert exc.value.code == 2


@pytest.mark.realdata
def test_the_bolted_beam_rows_on_the_page_are_the_studies_output(shared_data):
    """The bolted beam fitted as the two studies fit it: its automatic-band row (every cell but the fit
    time) and its key row are on the page as printed."""
    d = next(d for d in DATASETS if d.key == "unesp_boltedbeam")
    cells, inside = band_study.band_row(d, shared_data)
    assert inside
    assert _band_rows(PAGE.read_text(encoding="utf-8"))[d.label][:-1] == cells[:-1]
    row = key_study.section_row(key_study.key_row(d, shared_data))
    assert row in key_study.KEY_SECTION.read_text(encoding="utf-8").splitlines()
