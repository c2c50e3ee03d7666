"""The fitter's stops and verdicts have their status and message in one table (analysis.fit_messages):
every row formats, every solver status has a row, and the fitting modules write no message of their own."""
from __future__ import annotations

import ast
import re
import string
from pathlib import Path

import pytest

from analysis._lsfd_kernels import Status
from analysis.fit_messages import STOPS, VERDICTS, stop, verdict_message

ROOT = Path(__file__).resolve().parents[1]
#: the modules whose return points used to write their own messages
FITTER = ("analysis/_gn.py", "analysis/_lm.py", "analysis/lsfd.py", "analysis/fit_result.py", "analysis/pipeline.py",
          "analysis/compressed_fit.py")


def _fields(template: str) -> list[str]:
    return [f for _, f, _, _ in string.Formatter().parse(template) if f]


@pytest.mark.parametrize("name", sorted(STOPS))
def test_every_stop_formats_with_its_figures(name: str) -> None:
    status, template = STOPS[name]
    values = {f: 1.5 if f not in ("method", "reason", "inner") else "x" for f in _fields(template)}
    got = stop(name, **values)
    assert got[0] == status and "{" not in got[1] and got[1]
    assert (status > 0) == got[1].startswith(("converged", "initial fit already", "poles given", "poles from"))


def test_every_status_code_has_a_row_and_every_verdict_a_message() -> None:
    codes = {v for k, v in vars(Status).items() if k.isupper()}
    assert {s for s, _ in STOPS.values()} == codes
    assert verdict_message("not converged", lsfd="GN reached max_iter=3") == "the LSFD did not converge: GN reached max_iter=3"
    assert set(VERDICTS) == {"converged", "not converged", "implausible"}


def test_the_fitting_modules_write_no_stop_message_of_their_own() -> None:
    """No string literal of the fitter reads like a row of the table (the words each row starts with)."""
    starts = {re.split(r"[ :({]", t, maxsplit=1)[0] for _, t in STOPS.values()} | {"converged", "LSFD"}
    pattern = re.compile(r"^(converged: |GN stopped|LM stopped|GN reached|LM reached|GN step increased|"
                         r"LM could not|initial poles give|initial fit already|the poles' basis|poles would collapse|"
                         r"the LSFD did not converge|the fit converged but|LSFD \(|poles from the principal)")
    assert starts
    found = []
    for rel in FITTER:
        tree = ast.parse((ROOT / rel).read_text())
        for node in ast.walk(tree):
            texts = []
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                texts = [node.value]
            elif isinstance(node, ast.JoinedStr):
                texts = ["".join(v.value for v in node.values if isinstance(v, ast.Constant) and isinstance(v.value, str))]
            found += [f"{rel}:{node.lineno}: {t[:60]}" for t in texts if pattern.match(t)]
    assert not found, found


def test_a_fit_reports_the_tables_message() -> None:
    import numpy as np

    from analysis import ModalModel, fit_lsfd, synthesize
    from analysis.lsfd import LSFDConvergenceWarning
    from analysis.modal import pole_from_fz

    frf = synthesize(ModalModel(pole_from_fz([40.0], [0.01]), [[[20j]]], quantity="receptance"),
                     np.arange(1.0, 100.0, 0.5))
    with pytest.warns(LSFDConvergenceWarning) as caught:
        res = fit_lsfd(frf, pole_from_fz([40.5], [0.02]), method="gn", max_iter=1, ftol=0.0, xtol=0.0)
    assert str(caught[0].message).startswith("LSFD (gn) stopped at max_iter=1 before converging")
    assert (res.status, res.message) == stop("max_iter", method="GN", max_iter=1)
