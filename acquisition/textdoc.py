"""Reading the small JSON/TOML documents operators write (set-up files, channel descriptions)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from analysis.input_limits import DOCUMENT_LIMIT_BYTES, NESTING_LIMIT, read_bounded_text, too_deeply_nested

__all__ = ["read_document"]


def read_document(path: str | Path, what: str, error: type[Exception]) -> Any:
    """Parse ``path`` as TOML (``.toml``) or JSON (anything else).

    ``what`` names the document and its option in messages ("set-up file (--setup)"); every failure
    (unreadable, not UTF-8, malformed, not a regular file, larger than
    :data:`analysis.input_limits.DOCUMENT_LIMIT_BYTES`, nested deeper than
    :data:`analysis.input_limits.NESTING_LIMIT`) raises ``error`` with a message naming the file and the
    problem.
    """
    p = Path(path)
    try:
        text = read_bounded_text(p, what, DOCUMENT_LIMIT_BYTES, error)
    except OSError as exc:
        raise error(f"cannot read {what} {p}: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise error(f"{what} {p} is not UTF-8 text ({exc})") from None
    toml = p.suffix.lower() == ".toml"
    if too_deeply_nested(text, toml=toml):
        raise error(f"{what} {p} is not valid {p.suffix.lstrip('.') or 'JSON'}: nested deeper than {NESTING_LIMIT} "
                    "levels")
    try:
        if toml:
            import tomllib

            return tomllib.loads(text)
        return json.loads(text)
    except ValueError as exc:
        raise error(f"{what} {p} is not valid {p.suffix.lstrip('.') or 'JSON'}: {exc}") from None
