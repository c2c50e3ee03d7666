"""Shared data of the report tests: one small simulated test (the demo's roving-hammer session on the
simulated frame, two accepted hits per point), its fit, a diagnosis document and the report folder.
Made once per session (a few seconds) by the ``report_case`` fixture of tests/conftest.py."""
from __future__ import annotations

import json
from pathlib import Path

#: a diagnosis document in the schema of ``python -m analysis diagnose --json`` (verdict.to_json)
DIAGNOSIS = {
    "verdict": "support_flexibility",
    "causes": [
        {"effect": "support_flexibility", "parameters": {"scale": 0.4}, "gain_db": 25.7, "evidence": "modes 1-2 shift",
         "error_before_db": -3.0, "error_after_db": -28.7, "z": 9.1, "significant": True},
        {"effect": "sensor_mass", "parameters": {"kg": 0.006}, "gain_db": 0.4, "evidence": "small",
         "error_before_db": -3.0, "error_after_db": -3.4, "z": 0.5, "significant": False},
    ],
    "error_before_db": -3.0, "error_after_db": -28.7, "noise_db": {"difference": -42.5, "coherence": -40.9},
    "unexplained": False, "skipped": [], "time_data_verdict": "none",
    "combined": None,
    "comparison": {"bands": [{"lo_hz": 4.0, "hi_hz": 60.0, "error_db": -2.5}, {"lo_hz": 60.0, "hi_hz": 215.0,
                                                                                 "error_db": -9.0}],
                   "modes": {"pairs": [{"measured_hz": 12.9, "simulated_hz": 11.2, "df_percent": -13.2,
                                        "measured_damping": 0.0086, "simulated_damping": 0.006, "amplitude_db": 3.1,
                                        "phase_deg": 4.0, "mac": 0.97}],
                             "only_measured": [], "only_simulated": []}},
}


def make_report_case(out: Path) -> None:
    """Write the case in the folder ``out``; its file ``done`` is written last."""
    from acquisition import cli_demo
    from analysis import cli_report

    assert cli_demo.main(["--out", str(out), "--hits", "2"]) == 0
    diag = out / "diag.json"
    diag.write_text(json.dumps(DIAGNOSIS))
    code = cli_report.main([str(out / "demo.h5"), "--out", str(out / "full"), "--fit", str(out / "fit.json"),
                            "--diagnosis", str(diag), "--geometry", "frame"])
    assert code == 0
    (out / "done").write_text("")


def report_case_in(out: Path) -> dict:
    """The case made by :func:`make_report_case` in ``out``: {"dir", "recording", "uff", "fit", "diagnosis",
    "report" (index.html with the diagnosis), "demo_report", "n_modes", "fit_doc"}."""
    fit = json.loads((out / "fit.json").read_text())
    return {"dir": out, "recording": out / "demo.h5", "uff": out / "demo.uff", "fit": out / "fit.json",
            "diagnosis": out / "diag.json", "report": out / "full" / "index.html",
            "demo_report": out / "report" / "index.html", "n_modes": len(fit["poles"]), "fit_doc": fit}


def page_root(index: Path) -> Path:
    return Path(index).parent
