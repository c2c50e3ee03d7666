"""No import circles: the modules of the three packages form a directed acyclic graph.

Every import statement counts, at module level and inside functions (a deferred import hides a
circle from Python, not from the reader); only ``if TYPE_CHECKING:`` blocks are left out (read by
type checkers only). A package's ``__init__`` is a node like any module.
"""
from __future__ import annotations

import textwrap
from pathlib import Path

from import_graph import PACKAGES, ROOT, import_statements, source_files


def import_graph(root: Path) -> dict[str, set[str]]:
    """module -> the project modules it imports (a name that is not a module counts as its module)."""
    modules = {name for name, _ in source_files(root)}
    edges: dict[str, set[str]] = {m: set() for m in modules}
    for module, _path, _node, names in import_statements(root, runtime_only=True):
        for name in names:
            while name and name not in modules:
                name = name.rpartition(".")[0]
            if name and name != module:
                edges[module].add(name)
    return edges


def circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for start in sorted(edges):
        if start in index:
            continue
        work = [(start, iter(sorted(edges[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    m = stack.pop()
                    on_stack.discard(m)
                    component.append(m)
                    if m == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_the_packages_have_no_import_circles() -> None:
    found = circles(import_graph(ROOT))
    assert not found, "import circles (break them by moving the shared part down):\n" + "\n".join(
        " <-> ".join(c) for c in found)


def test_the_checker_finds_a_circle_through_a_deferred_import(tmp_path: Path) -> None:
    files = {
        "analysis/a.py": "from .b import x\n",
        "analysis/b.py": "def f():\n    from analysis import c\n",
        "analysis/c.py": "import analysis.a\n",
        "analysis/d.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .a import y\n",
        "analysis/e.py": "from .d import z\n",
    }
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(textwrap.dedent(text))
    for package in PACKAGES:
        (tmp_path / package).mkdir(exist_ok=True)
        (tmp_path / package / "__init__.py").touch()
    assert circles(import_graph(tmp_path)) == [["analysis.a", "analysis.b", "analysis.c"]]
