"""The import statements of the three packages, read from their source (no module is imported):
one parser for the layer rule, the no-circles rule and the module map."""
from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("analysis", "acquisition", "simulator")


def module_name(root: Path, path: Path) -> str:
    """Dotted module name of a source file below ``root`` (a package's ``__init__`` is the package)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def imported(module: str, is_package: bool, node: ast.AST) -> list[str]:
    """Absolute names an import statement reads: the module and, for ``from m import a``, ``m.a``
    (``a`` may be a submodule)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    assert isinstance(node, ast.ImportFrom)
    if node.level == 0:
        base = node.module or ""
    else:
        pkg = module.split(".") if is_package else module.split(".")[:-1]
        pkg = pkg[: len(pkg) - (node.level - 1)]
        base = ".".join(pkg + ([node.module] if node.module else []))
    return [base] + [f"{base}.{a.name}" for a in node.names if a.name != "*"]


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    """ids of the statements inside ``if TYPE_CHECKING:`` blocks (read by type checkers only)."""
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If):
            test = node.test
            name = test.id if isinstance(test, ast.Name) else test.attr if isinstance(test, ast.Attribute) else ""
            if name == "TYPE_CHECKING":
                skip.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    return skip


def source_files(root: Path) -> Iterator[tuple[str, Path]]:
    """(module name, path) of every source file of the three packages."""
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            yield module_name(root, path), path


def import_statements(root: Path, *, runtime_only: bool = False) -> Iterator[tuple[str, Path, ast.stmt, list[str]]]:
    """Every import statement of the packages (module level and inside functions) as
    (importing module, its path, the statement, the names it reads). ``runtime_only`` leaves out
    the ``if TYPE_CHECKING:`` blocks."""
    for module, path in source_files(root):
        tree = ast.parse(path.read_text(), filename=str(path))
        skip = _type_checking_nodes(tree) if runtime_only else set()
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)) and id(node) not in skip:
                yield module, path, node, imported(module, path.name == "__init__.py", node)
