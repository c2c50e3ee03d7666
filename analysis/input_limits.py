"""Input files read with a bound: only regular files, never more bytes than such an input needs.

A FIFO (named pipe) or a character device such as ``/dev/zero`` given where a file is expected makes
a plain read wait for a writer or never end; a file far larger than its kind ever is fills the
memory while it is parsed. Both are refused before anything is read, with one line that names the
option or input, the file and the limit:

* :data:`DOCUMENT_LIMIT_BYTES` for the small documents an operator writes (a set-up, a channel
  description, picked poles, a simulator configuration);
* :data:`RESULT_LIMIT_BYTES` for the results the commands write and read back (fit and diagnosis JSON);
* :func:`text_data_limit_bytes` for measured data in text (LabVIEW ``.lvm``, SEP005 JSON): parsing
  takes up to :data:`TEXT_DATA_EXPANSION` bytes of memory per byte of text, so the file may be that
  fraction of the memory one computation may use (:func:`analysis.work_limits.memory_budget_bytes`).

The file is opened without blocking (a FIFO never waits for a writer) and checked on the open
descriptor, so a file swapped for a pipe between a check and the read cannot slip through; a file
that grows while read is cut off at the limit and refused too.

A JSON or TOML document nested deeper than :data:`NESTING_LIMIT` brackets and braces is refused by
its reader before it is parsed (:func:`too_deeply_nested`): Python's parsers descend one call per
level, so a file of a few kilobytes of ``[`` would otherwise exhaust the interpreter's stack.
"""
from __future__ import annotations

import os
import re
import stat
from pathlib import Path

from .work_limits import memory_budget_bytes

__all__ = ["DOCUMENT_LIMIT_BYTES", "RESULT_LIMIT_BYTES", "TEXT_DATA_EXPANSION", "text_data_limit_bytes",
           "size_text", "not_regular_kind", "read_bounded", "read_bounded_text", "check_input_file",
           "NESTING_LIMIT", "nesting_depth", "too_deeply_nested"]

#: the largest set-up, channel description, picked-poles file or simulator configuration (bytes)
DOCUMENT_LIMIT_BYTES = 4 << 20
#: the largest fit or diagnosis JSON read back (bytes)
RESULT_LIMIT_BYTES = 256 << 20
#: bytes of memory that parsing one byte of a text data file (.lvm, SEP005 JSON) may take (a 3.9 MB LabVIEW
#: file with four segments peaked at 7)
TEXT_DATA_EXPANSION = 16

#: the deepest nesting of brackets and braces accepted in a JSON or TOML input (levels); the documents
#: impactlab reads and writes nest four or five levels deep
NESTING_LIMIT = 64

# what the nesting scan stops at: a bracket or brace, or a whole string (JSON: "..." with backslash
# escapes; TOML also '...' literal strings, """...""" and '''...''' multi-line strings and # comments),
# an unterminated string running to the end of the text
_JSON_TOKENS = re.compile(r'[\[\]{}]|"[^"\\]*(?:\\.[^"\\]*)*(?:"|\\?\Z)', re.S)
_TOML_TOKENS = re.compile(r'[\[\]{}]|"""(?:\\.|[^\\])*?(?:"""|\\?\Z)|\'\'\'.*?(?:\'\'\'|\Z)'
                          r'|"[^"\\\n]*(?:\\.[^"\\\n]*)*(?:"|\\?$)|\'[^\'\n]*\'?|#[^\n]*', re.S | re.M)

_KINDS = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISDIR, "a folder"), (stat.S_ISSOCK, "a socket"))


def text_data_limit_bytes() -> int:
    """The largest text data file (bytes) whose parsing fits in the memory one computation may use now."""
    return int(memory_budget_bytes() // TEXT_DATA_EXPANSION)


def size_text(n_bytes: float) -> str:
    """A byte count for a message: ``"4 MiB"``, ``"1.5 GiB"``, ``"812 bytes"``."""
    for unit, shift in (("GiB", 30), ("MiB", 20), ("KiB", 10)):
        if n_bytes >= 1 << shift:
            return f"{n_bytes / (1 << shift):.3g} {unit}"
    return f"{int(n_bytes)} bytes"


def not_regular_kind(mode: int) -> str | None:
    """What a file of ``st_mode`` ``mode`` is when it is not a regular file ("a FIFO (named pipe)",
    "a character device", "a folder"...); None for a regular file."""
    if stat.S_ISREG(mode):
        return None
    return next((text for test, text in _KINDS if test(mode)), "not a regular file")


def _refuse_stat(st: os.stat_result, path: str, what: str, limit: int, error: type[Exception]) -> None:
    kind = not_regular_kind(st.st_mode)
    if kind is not None:
        raise error(f"{what} {path} is {kind}, not a regular file: give a regular file of at most {size_text(limit)}")
    if st.st_size > limit:
        raise error(f"{what} {path} holds {size_text(st.st_size)}, more than the {size_text(limit)} accepted: "
                    "check that it is the right file")


def check_input_file(path: str | Path, what: str, limit: int, error: type[Exception]) -> None:
    """Refuse ``path`` unless it is a regular file of at most ``limit`` bytes (for readers that open the
    file themselves: HDF5, MATLAB, ``.npy``). ``what`` names the option or input in the message ("--fit
    file"); ``error`` is raised with one line. A missing or unreadable file raises the ``OSError`` as is."""
    p = os.fspath(path)
    _refuse_stat(os.stat(p), p, what, limit, error)


def read_bounded(path: str | Path, what: str, limit: int, error: type[Exception]) -> bytes:
    """The bytes of ``path``, refused with ``error`` (one line naming ``what``, the file and ``limit``)
    when it is not a regular file or holds more than ``limit`` bytes. A missing or unreadable file
    raises the ``OSError`` as is (the caller names the file its way)."""
    p = os.fspath(path)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    fd = os.open(p, flags)  # O_NONBLOCK: opening a FIFO does not wait for a writer
    try:
        _refuse_stat(os.fstat(fd), p, what, limit, error)
        chunks: list[bytes] = []
        got = 0
        while got <= limit:
            chunk = os.read(fd, min(1 << 20, limit + 1 - got))
            if not chunk:
                break
            chunks.append(chunk)
            got += len(chunk)
    finally:
        os.close(fd)
    if got > limit:
        raise error(f"{what} {p} grew beyond the {size_text(limit)} accepted while it was read: wait until "
                    "it is written whole")
    return b"".join(chunks)


def read_bounded_text(path: str | Path, what: str, limit: int, error: type[Exception],
                      encoding: str = "utf-8") -> str:
    """:func:`read_bounded` decoded with ``encoding`` (a ``UnicodeDecodeError`` is raised as is)."""
    return read_bounded(path, what, limit, error).decode(encoding)


def nesting_depth(text: str, *, toml: bool = False, stop_above: int | None = None) -> int:
    """The deepest nesting of ``[``/``{`` in a JSON (or, with ``toml``, TOML) text, brackets and braces
    inside strings and comments not counted; one linear scan, ended as soon as the depth exceeds
    ``stop_above`` (then the depth reached, ``stop_above + 1``). A stray closing bracket counts as none."""
    depth = deepest = 0
    for match in (_TOML_TOKENS if toml else _JSON_TOKENS).finditer(text):
        c = match.group()[0]
        if c in "[{":
            depth += 1
            if depth > deepest:
                deepest = depth
                if stop_above is not None and deepest > stop_above:
                    break
        elif c in "]}" and depth:
            depth -= 1
    return deepest


def too_deeply_nested(text: str, *, toml: bool = False) -> bool:
    """Whether a JSON (TOML with ``toml``) text nests deeper than :data:`NESTING_LIMIT`: its reader
    refuses it, before parsing, with a message naming the file."""
    if text.count("[") + text.count("{") <= NESTING_LIMIT:   # cannot nest deeper: no scan
        return False
    return nesting_depth(text, toml=toml, stop_above=NESTING_LIMIT) > NESTING_LIMIT
