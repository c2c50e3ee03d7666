"""One error root: every exception class of the three packages derives from
:class:`analysis.errors.ImpactlabError`, and the errors are defined in the errors modules.

Read from the source (no module is imported). Private classes (a leading underscore) used for
control flow inside one module, and ``CliExit`` (the command lines' exit signal, not an error), are
left out, and so are warnings.
"""
from __future__ import annotations

import ast
import builtins

from import_graph import ROOT, source_files

#: where errors are defined: one module per package, plus the session's and the station's own
ERROR_MODULES = {"analysis.errors", "acquisition.errors", "simulator.errors", "acquisition.session_errors",
                 "acquisition.station.engine"}
NOT_ERRORS = {"CliExit"}
BUILTIN_EXCEPTIONS = {n for n, v in vars(builtins).items() if isinstance(v, type) and issubclass(v, BaseException)}


def exception_classes() -> dict[str, tuple[str, list[str]]]:
    """class name -> (module, base names) for every class of the packages."""
    classes: dict[str, tuple[str, list[str]]] = {}
    for module, path in source_files(ROOT):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                bases = [b.id if isinstance(b, ast.Name) else b.attr if isinstance(b, ast.Attribute) else ""
                         for b in node.bases]
                classes[node.name] = (module, bases)
    return classes


def _reaches(name: str, target: str, classes: dict[str, tuple[str, list[str]]], seen: frozenset = frozenset()) -> bool:
    if name == target:
        return True
    if name in BUILTIN_EXCEPTIONS and target in BUILTIN_EXCEPTIONS:
        return issubclass(getattr(builtins, name), getattr(builtins, target))
    if name in seen or name not in classes:
        return False
    return any(_reaches(b, target, classes, seen | {name}) for b in classes[name][1])


def _is_exception(name: str, classes: dict[str, tuple[str, list[str]]], seen: frozenset = frozenset()) -> bool:
    if name in BUILTIN_EXCEPTIONS:
        return True
    if name in seen or name not in classes:
        return False
    return any(_is_exception(b, classes, seen | {name}) for b in classes[name][1])


def test_every_error_derives_from_the_root_and_lives_in_an_errors_module() -> None:
    classes = exception_classes()
    errors = {n: m for n, (m, _) in classes.items()
              if _is_exception(n, classes) and not _reaches(n, "Warning", classes)
              and not n.startswith("_") and n not in NOT_ERRORS}
    assert "ChildCrashed" in errors and "UFFError" in errors  # the check sees the packages' errors
    outside_root = sorted(n for n in errors if not _reaches(n, "ImpactlabError", classes))
    assert not outside_root, f"errors not under ImpactlabError: {outside_root}"
    scattered = sorted(f"{m}.{n}" for n, m in errors.items() if m not in ERROR_MODULES)
    assert not scattered, f"errors defined outside the errors modules {sorted(ERROR_MODULES)}: {scattered}"
