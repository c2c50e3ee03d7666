"""The layer rule of docs/architecture.md, enforced on every import statement of the three packages
(module level and inside functions alike).

    analysis      imports neither acquisition nor simulator (containers, numerics, file formats)
    acquisition   imports analysis, never simulator (the simulated doors come through entry points)
    simulator     imports analysis and acquisition's interface modules only (wire formats, errors,
                  the transport interface, the URL grammar)
    faces         modules named cli_*.py and __main__.py wire the packages together; they may import
                  anything, and no library module imports them
"""
from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
from import_graph import PACKAGES, ROOT, import_statements

#: what a library (non-face) module of each package may import from the other two
ALLOWED: dict[str, dict[str, frozenset[str] | None]] = {
    "analysis": {},
    "acquisition": {"analysis": None},  # None: any module of that package
    "simulator": {"analysis": None,
                  "acquisition": frozenset({"protocol", "errors", "transport", "urls"})},
}


def is_face(module: str) -> bool:
    """A wiring module: the command lines (``cli_*``) and the ``python -m`` entry points."""
    last = module.rsplit(".", 1)[-1]
    return last.startswith("cli_") or last == "__main__"


def violations(root: Path) -> list[str]:
    """Every import in ``root``'s packages that breaks the rule, as ``file:line: what``."""
    found = []
    for module, path, node, names in import_statements(root):
        package = module.split(".")[0]
        if is_face(module):
            continue
        where = f"{path.relative_to(root)}:{node.lineno}"
        for name in names:
            top = name.split(".")[0]
            if top in PACKAGES and is_face(name):
                found.append(f"{where}: library module {module} imports the face {name}")
            if top not in PACKAGES or top == package:
                continue
            if top not in ALLOWED[package]:
                found.append(f"{where}: {package} may not import {top} ({name})")
                continue
            allowed = ALLOWED[package][top]
            parts = name.split(".")
            if allowed is not None and len(parts) > 1 and parts[1] not in allowed:
                found.append(f"{where}: {package} may import only {sorted(allowed)} of {top}, not {name}")
            elif allowed is not None and len(parts) == 1:
                bad = [a.name for a in getattr(node, "names", []) if a.name not in allowed]
                if bad:
                    found.append(f"{where}: {package} may import only {sorted(allowed)} of {top}, not {bad}")
    return found


def test_the_packages_keep_the_layer_rule() -> None:
    found = violations(ROOT)
    assert not found, "layer rule broken (docs/architecture.md):\n" + "\n".join(found)


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        p = tmp_path / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(textwrap.dedent(text))
    for package in PACKAGES:
        (tmp_path / package).mkdir(exist_ok=True)
        (tmp_path / package / "__init__.py").touch()
    return tmp_path


@pytest.mark.parametrize("rel,text,expect", [
    ("analysis/fit.py", "def f():\n    from acquisition import driver\n", "analysis may not import acquisition"),
    ("analysis/fit.py", "import simulator.fem\n", "analysis may not import simulator"),
    ("acquisition/urls.py", "def door():\n    from simulator.usb_backend import SimUsbBackend\n",
     "acquisition may not import simulator"),
    ("simulator/stand.py", "from acquisition.session import CaptureSession\n", "may import only"),
    ("simulator/stand.py", "from acquisition import driver\n", "may import only"),
    ("analysis/diagnosis/x.py", "from ...acquisition import session\n", "analysis may not import acquisition"),
    ("acquisition/session.py", "from .cli_capture import main\n", "imports the face"),
])
def test_the_checker_catches_a_violation(tmp_path: Path, rel: str, text: str, expect: str) -> None:
    root = _tree(tmp_path, {rel: text})
    found = violations(root)
    assert len(found) >= 1 and expect in found[0], found


def test_the_checker_allows_the_faces_and_the_interfaces(tmp_path: Path) -> None:
    root = _tree(tmp_path, {
        "analysis/cli_diagnose.py": "import simulator.fem\nfrom acquisition import session\n",
        "acquisition/__main__.py": "import simulator\n",
        "acquisition/session.py": "from analysis.recording import RecordingWriter\n",
        "simulator/firmware.py": "from acquisition import protocol as P\nfrom acquisition.errors import SetupError\n",
    })
    assert violations(root) == []
