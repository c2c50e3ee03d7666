"""The packages' public names: each name in ``__all__`` resolves, and importing a package imports
none of its modules (no side effects, cheap start-up)."""
from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

PACKAGES = ("analysis", "acquisition", "simulator")


@pytest.mark.parametrize("package", PACKAGES)
def test_every_exported_name_resolves_to_its_module(package: str) -> None:
    pkg = importlib.import_module(package)
    assert pkg.__all__, f"{package} exports nothing"
    for name in pkg.__all__:
        obj = getattr(pkg, name)
        home = getattr(obj, "__module__", None)
        if home is not None:  # classes and functions say where they live: inside the package
            assert home.split(".")[0] in PACKAGES, (name, home)
    assert sorted(dir(pkg)) == sorted(pkg.__all__)
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        pkg.not_a_name  # noqa: B018


def test_importing_a_package_loads_none_of_its_modules() -> None:
    code = ("import sys, analysis, acquisition, simulator\n"
            "mods = [m for m in sys.modules if m.split('.')[0] in ('analysis', 'acquisition', 'simulator')]\n"
            "print(sorted(mods))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "['acquisition', 'analysis', 'analysis._lazy', 'simulator']"
