"""Reading the small JSON/TOML documents operators write (set-up files, channel descriptions)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from analysis.input_limits import DOCUMENT_LIMIT_BYTES, read_bounded_text

__all__ = ["read_document"]


def read_document(path: str | Path, what: str, error: type[Exception]) -> Any:
    """Parse ``path`` as TOML (``.toml``) or JSON (anything else).

    ``what`` names the document and its option in messages ("set-up file (--setup)"); every failure
    (unreadable, not UTF-8, malformed, not a regular file, larger than
    :data:`analysis.input_limits.DOCUMENT_LIMIT_BYTES`) raises ``error`` with a message naming the file and the
    problem.
    """
    p = Path(path)
    try:
        text = read_bounded_text(p, what, DOCUMENT_LIMIT_BYTES, error)
    except OSError as exc:
        raise error(f"cannot read {what} {p}: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise error(f"{what} {p} is not UTF-8 text ({exc})") from None
    try:
        if p.suffix.lower() == ".toml":
            import tomllib

            return tomllib.loads(text)
        return json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise error(f"{what} {p} is not valid {p.suffix.lstrip('.') or 'JSON'}: {exc}") from None
