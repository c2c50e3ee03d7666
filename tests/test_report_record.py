"""The report's test record: what an imported file did not know (sensitivity, input range: NaN in the
recording) is shown as unknown and the page's data stay standard JSON; the record reads like the
terminal (labels, units, hits numbered from 1)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_importers import synthetic_hits, write_lvm

BEAM_LVM = Path("ladisk_beam_impact/acceleration.lvm")


def _strict_report_data(folder: Path) -> dict:
    """``report-data.js`` parsed as strict JSON (NaN / Infinity are not JSON: they fail here)."""
    text = (folder / "report-data.js").read_text()
    assert text.startswith("window.REPORT_DATA = ")

    def reject(token):
        raise AssertionError(f"non-standard JSON constant {token} in report-data.js")

    return json.loads(text[len("window.REPORT_DATA = "):].rstrip().rstrip(";"), parse_constant=reject)


def _import(lvm: Path, out: Path) -> Path:
    from acquisition import cli_import

    assert cli_import.main([str(lvm), "--out", str(out)]) == 0
    return out


def test_unknown_channel_values_of_an_import_are_none_in_the_report(tmp_path):
    """An imported .lvm has no sensitivity or input range: the recording holds NaN for them, the
    report's channel table None ("unknown"), and the written page data are strict JSON."""
    from analysis.recording import Recording
    from analysis.report_html import read_test_record
    from analysis.report_html.collect import test_section

    lvm = tmp_path / "hits.lvm"
    write_lvm(lvm, synthetic_hits(3)[0])
    rec_path = _import(lvm, tmp_path / "rec.h5")
    with Recording(rec_path) as r:  # the root cause: the recording's "unknown" is NaN
        assert all(c["sensitivity"] != c["sensitivity"] for c in r.channels)
    record = read_test_record(rec_path)
    assert [c["sensitivity"] for c in record.channels] == [None, None]
    assert [c["range_v"] for c in record.channels] == [None, None]
    section = json.loads(json.dumps(test_section(record), allow_nan=False, default=float))
    assert section["channels"][0]["sensitivity"] is None


@pytest.mark.realdata
def test_report_of_the_imported_ladisk_beam(shared_data, tmp_path):
    """The README's import of the LADISK beam gives a complete report folder with standard JSON."""
    from analysis import cli_report

    rec = _import(shared_data / BEAM_LVM, tmp_path / "beam.h5")
    assert cli_report.main([str(rec), "--out", str(tmp_path / "rb")]) == 0
    assert (tmp_path / "rb" / "index.html").is_file()
    doc = _strict_report_data(tmp_path / "rb")
    assert len(doc["modal"]["modes"]) >= 1


def _text(html_part: str) -> str:
    import html
    import re

    return html.unescape(re.sub(r"<[^>]+>", " | ", html_part))


def test_record_of_a_capture_without_points_reads_like_the_terminal(tmp_path, capsys):
    """A capture made without --points: the points row names the struck point, no "None", the trigger
    level has its unit, no raw keys, hits numbered from 1 (in the recording and at their point) as the
    terminal numbers them."""
    from acquisition import cli_capture
    from analysis.report_html import make_report

    rec = tmp_path / "cap.h5"
    assert cli_capture.main(["--device", "sim://?seed=1", "--out", str(rec), "--auto", "--hits", "2"]) == 0
    terminal = capsys.readouterr().out
    page = make_report(rec, tmp_path / "report").read_text()
    test = _text(page[page.index("<section id='test'>"):page.index("<section id='points'>")])
    assert "None" not in test and "pretrigger" not in test and "_" not in test.replace("sim://?seed=1", "")
    assert "| points |  | right:6:-X |" in test
    assert "level 20 N" in test and "128 samples (20 ms) kept before the trigger" in test
    assert "hits per point 2" in test and "roving hammer" in test
    # "hit 1" and "hit 2" at right:6:-X in the terminal; rows 1 and 2 (hit at the point 1 and 2) in the report
    assert "right:6:-X  hit 1:" in terminal and "right:6:-X  hit 2:" in terminal
    hits = test[test.index("| reason |"):]
    cells = [c.strip() for c in hits.split("|") if c.strip()]
    assert cells[1:5] == ["1", "right:6:-X", "1", "accepted"] and cells[7:11] == ["2", "right:6:-X", "2", "accepted"]


def test_shapes_of_points_labelled_by_another_tool():
    """Labels that are not component:node:direction (e.g. 'view0:acc:Z') still get a node, an axis and a sign."""
    from analysis.report_html.collect import _axis_sign

    assert _axis_sign("right:4:-Z") == (2, -1) and _axis_sign("left:9:Y") == (1, 1)
    assert _axis_sign("view0:acc:Z") == (2, 1) and _axis_sign("view0:acc:-x") == (0, -1)
    assert _axis_sign("sensor 3") == (2, 1)
