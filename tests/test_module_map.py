"""Every module of the three packages is named in the module map of docs/architecture.md.

A module counts as named when its package's section (``### analysis/`` ...) holds it in backticks
as ``name``, ``name.Thing``, ``name(...)`` or its path below the package (``diagnosis/physical``);
a module of a sub-package also needs the sub-package named in that section. ``__init__`` and
``__main__`` need no entry.
"""
from __future__ import annotations

import re
from pathlib import Path

from import_graph import PACKAGES, ROOT, source_files


def package_sections(text: str) -> dict[str, str]:
    """The text of each package's section below ``## Module map``."""
    if "## Module map" not in text:
        return {}
    body = text.split("## Module map", 1)[1].split("\n## ", 1)[0]
    parts = re.split(r"^### +(\w+)/.*$", body, flags=re.M)
    return {parts[i]: parts[i + 1] for i in range(1, len(parts) - 1, 2)}


def unmapped(root: Path) -> list[str]:
    """Modules missing from the map, as dotted names."""
    sections = package_sections((root / "docs" / "architecture.md").read_text())
    tokens = {pkg: set(re.findall(r"`([^`]+)`", text)) for pkg, text in sections.items()}
    missing = []
    for module, path in source_files(root):
        if path.stem in ("__init__", "__main__"):
            continue
        package, *sub, name = module.split(".")
        named = set()
        for token in tokens.get(package, ()):
            for piece in re.split(r"[\s,;+]+", token):
                piece = piece.strip("()").removeprefix(f"{package}/").removeprefix(f"{package}.")
                named.add(re.split(r"[.(\[ ]", piece.removesuffix(".py"), maxsplit=1)[0])
                named.update(p for p in re.split(r"[/.(\[ ]", piece.removesuffix(".py")) if p)
        ok = name in named or "/".join([*sub, name]) in named
        ok = ok and all(s in named for s in sub)
        if not ok:
            missing.append(module)
    return missing


def test_every_module_is_in_the_module_map() -> None:
    missing = unmapped(ROOT)
    assert not missing, "modules missing from docs/architecture.md's module map:\n" + "\n".join(missing)


def test_the_check_sees_a_missing_module(tmp_path: Path) -> None:
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "architecture.md").write_text(
        "# x\n## Module map\n### analysis/ (bottom)\n- `frf.FRFSet`, `diagnosis/` (`physical`)\n"
        "### acquisition/\n- `driver`\n### simulator/\n\n## Conventions\n- `fem`\n")
    for rel in ("analysis/frf.py", "analysis/lsfd.py", "analysis/diagnosis/physical.py",
                "acquisition/driver.py", "simulator/fem.py"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).touch()
    for package in PACKAGES:
        (tmp_path / package / "__init__.py").touch()
    assert unmapped(tmp_path) == ["analysis.lsfd", "simulator.fem"]
