"""The ``>>>`` examples of the public API (``fit_auto``, ``fit_lsfd``, ``diagnose``, ``Recording``,
``Analyser``) and of the fitter's message table run as written, as SciPy's docstrings do."""
from __future__ import annotations

import doctest
import importlib

import pytest

#: (module, name) of every object whose docstring examples the suite runs; name None: the module's own
DOCUMENTED = [("analysis.pipeline", "fit_auto"), ("analysis.lsfd", "fit_lsfd"), ("analysis.diagnosis.entry", "diagnose"),
              ("analysis.recording", "Recording"), ("acquisition.driver", "Analyser"), ("analysis.fit_messages", None)]


@pytest.mark.parametrize(("module", "name"), DOCUMENTED, ids=[n or m for m, n in DOCUMENTED])
def test_the_docstring_examples_run_as_written(module: str, name: str | None) -> None:
    mod = importlib.import_module(module)
    obj = getattr(mod, name) if name else mod
    tests = doctest.DocTestFinder(recurse=False).find(obj, name or module, module=mod, globs={})
    examples = sum(len(t.examples) for t in tests)
    assert examples >= 2, f"{module}.{name}: no examples in its docstring"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    for t in tests:
        runner.run(t)
    result = runner.summarize(verbose=False)
    assert result.failed == 0 and result.attempted == examples, f"{result.failed} of {examples} examples failed"
