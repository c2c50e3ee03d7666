"""The shared CLI helper: error-to-exit-code rules, output folder checks, the BrokenPipe guard."""
from __future__ import annotations

import subprocess
import sys

import pytest

from analysis.command_line import UsageError, check_out_dir, cli_entry, exit_on


@cli_entry
def _main(exc: BaseException | None) -> int:
    with exit_on("prog", (KeyError, 2), (LookupError, 1, "lookup: "), (ValueError, 3)):
        if exc is not None:
            raise exc
    return 0


def test_first_matching_rule_gives_the_code_and_the_message(capsys):
    assert _main(None) == 0
    assert _main(KeyError("k")) == 2 and capsys.readouterr().err == "prog: 'k'\n"
    assert _main(IndexError("i")) == 1 and capsys.readouterr().err == "prog: lookup: i\n"
    assert _main(ValueError("v")) == 3 and capsys.readouterr().err == "prog: v\n"
    with pytest.raises(TypeError):  # no rule: not swallowed
        _main(TypeError("t"))


def test_check_out_dir_names_the_missing_folder(tmp_path):
    check_out_dir(None)
    check_out_dir(tmp_path / "a.json")
    with pytest.raises(UsageError, match=r"cannot write the JSON .*a.json: folder .*nowhere does not exist"):
        check_out_dir(tmp_path / "nowhere" / "a.json", "JSON")
    with pytest.raises(KeyError, match="its folder"):
        check_out_dir(tmp_path / "nowhere" / "a.json", error=KeyError, message="cannot write {label}: its folder")


def test_a_closed_stdout_pipe_ends_quietly():
    code = ("import sys\nfrom analysis.command_line import cli_entry\n"
            "@cli_entry\ndef main():\n    for i in range(200000):\n        print('line', i)\n    return 0\n"
            "sys.exit(main())\n")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None
    proc.stdout.readline()
    proc.stdout.close()  # the reader stops, as `| head -1` does
    assert proc.stderr is not None
    with proc.stderr:
        err = proc.stderr.read().decode()
    assert proc.wait() == 0 and "Traceback" not in err


def test_repair_and_replay_share_the_recording_in_out_parser(capsys):
    """repair and replay read one recording (never modified) and write another: the same parser
    (recording_in_out) gives both the positional recording, a required --out and --overwrite."""
    from acquisition import cli_repair, cli_replay
    from analysis.command_line import recording_in_out

    p = recording_in_out("python -m x", "x: one line.\n\nMore.", "the output")
    args = p.parse_args(["in.h5", "--out", "out.h5", "--overwrite"])
    assert (args.recording, args.out, args.overwrite) == ("in.h5", "out.h5", True)
    assert p.description == "x: one line." and p.prog == "python -m x"
    for main in (cli_repair.main, cli_replay.main):
        with pytest.raises(SystemExit) as usage:     # --out is required: a usage error
            main(["in.h5"])
        assert usage.value.code == 2 and "--out" in capsys.readouterr().err
        with pytest.raises(SystemExit):
            main(["--help"])
        text = capsys.readouterr().out
        assert "recording" in text and "--overwrite" in text and "never modified" in text
