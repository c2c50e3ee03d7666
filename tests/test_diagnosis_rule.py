"""The decision rule is one object that reaches every stage, and every result carries the trace of the
rules that decided (``analysis.diagnosis.rule``).

Each stage that uses a field of :class:`DecisionRule` is run twice, with the defaults and with that one
field changed, and its outcome must change: the FRF-level catalogue (``min_gain_db``, ``none_margin_db``
through :func:`diagnose`), the time-data stage (``min_gain_db``), the physical stage's significance and
adequacy (``physical_min_gain_db``, ``none_margin_db``, ``discrepancy_chi2``), its second-cause rule and its
refinements (``physical_min_gain_db``, ``quiet_chi2``), and the mode-by-mode vote (``separation_z``).
"""
from __future__ import annotations

import json
from dataclasses import fields, replace
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from analysis.diagnosis import diagnose
from analysis.diagnosis.rule import DEFAULT_RULE, RULES, DecisionRule, db, gain_db, paired_z, step, why_lines
from simulator.effects import add_frf_noise, base_model, simulate_with_effects

OUTS = ["left:9:Y", "top:4:X", "right:6:-X"]
REFS = ["right:6:-X"]
ONLY = ["stiffness_shift", "damping_change"]


@pytest.fixture(scope="module")
def stiffer():
    """A frame 2 % stiffer in frequency, 1 % noise, and its unchanged simulation."""
    base = base_model(None, OUTS, REFS, max_freq_hz=800.0)
    f = np.arange(3.0, 150.0, 0.25)
    frf = simulate_with_effects(base, OUTS, REFS, f, "accelerance", [{"effect": "stiffness_shift", "factor": 1.02}])
    return add_frf_noise(frf, np.random.default_rng(1)), base


@pytest.fixture(scope="module")
def named(stiffer):
    meas, base = stiffer
    return diagnose(meas, base, effects=ONLY)


def test_every_field_is_documented_and_checked() -> None:
    doc = DecisionRule.__doc__ or ""
    for f in fields(DecisionRule):
        assert f"{f.name} :" in doc, f.name
    with pytest.raises(ValueError, match="min_gain_db"):
        DecisionRule(min_gain_db=float("nan"))
    with pytest.raises(ValueError, match="max_stages"):
        DecisionRule(max_stages=0)
    with pytest.raises(KeyError, match="unknown rule"):
        step("no_such_rule", None, {}, "")


def test_the_helpers_are_the_rule_arithmetic() -> None:
    assert db(100.0) == pytest.approx(20.0) and db(0.0) == pytest.approx(-300.0)
    assert gain_db([2.0, 2.0], [1.0, 1.0]) == pytest.approx(10 * np.log10(2.0))
    d = np.array([1.0, 2.0, 3.0])
    assert paired_z(d, np.zeros(3)) == pytest.approx(d.mean() / (d.std(ddof=1) / np.sqrt(3)))
    assert paired_z([1.0], [0.0]) == 0.0 and paired_z([1.0, 1.0], [0.0, 0.0]) == 0.0
    assert DEFAULT_RULE.significant(0.6, 3.1) and not DEFAULT_RULE.significant(0.6, 2.9)
    assert DEFAULT_RULE.significant(3.0, 0.0) and not DEFAULT_RULE.significant(0.4, 10.0)


def test_the_frf_stage_takes_min_gain_and_the_none_margin_from_the_one_rule(stiffer, named) -> None:
    meas, base = stiffer
    assert named.verdict == "stiffness_shift"
    strict = diagnose(meas, base, effects=ONLY, rule=DecisionRule(min_gain_db=100.0))
    assert strict.verdict == "unexplained" and not any(c["significant"] for c in strict.causes)
    # the same error, judged with a wider margin of the noise, is "none"
    wide = diagnose(meas, base, effects=ONLY, rule=DecisionRule(min_gain_db=100.0, none_margin_db=30.0))
    assert wide.verdict == "none"
    assert strict.rule.min_gain_db == 100.0 and wide.to_json()["rule"]["none_margin_db"] == 30.0
    last = wide.trace[-1]
    assert last["rule"] == "none_margin" and last["values"]["none_margin_db"] == 30.0 and last["outcome"] == "verdict none"


def test_the_trace_is_ordered_in_the_result_its_json_and_the_reports(named) -> None:
    from analysis.diagnosis.report import report_text
    from analysis.report_html.page import diagnosis_html

    rules = [s["rule"] for s in named.trace]
    assert rules[0] == "same_structure"
    # each effect's significance in the order tried, then the choice of the verdict, then the further stage
    assert [s["cause"] for s in named.trace if s["rule"] == "significance"] == ONLY
    assert rules.index("largest_gain") > max(i for i, r in enumerate(rules) if r == "significance")
    assert rules[-1] == "further_stage" and named.trace[-1]["outcome"] == "explained: no further stage"
    assert all(set(s) == {"rule", "cause", "values", "outcome"} and s["rule"] in RULES for s in named.trace)
    doc = json.loads(json.dumps(named.to_json()))
    assert doc["trace"] == named.trace
    lines = why_lines(doc["trace"])
    assert lines[0].startswith("same_structure") and lines[-1].startswith("further_stage")
    assert any(line.startswith("largest_gain stiffness_shift: verdict stiffness_shift") for line in lines)
    text = report_text(named)
    assert "## Why this verdict" in text
    at = [text.index(f"{i}. {line}") for i, line in enumerate(lines, start=1)]
    assert at == sorted(at)
    html = diagnosis_html(doc, {"diagnosis": doc})
    assert "Why this verdict" in html
    at = [html.index(f"<li>{line}</li>") for line in lines]
    assert at == sorted(at)


def test_the_time_data_stage_takes_the_same_rule() -> None:
    from analysis.diagnosis.timedata_gain import diagnose_time_effects
    from simulator.time_effects import simulate_hits

    rec = simulate_hits({"effect": "input_noise", "noise_rms_n": 4.0}, n_hits=4, seed=1, n_samples=2048)

    def verdict(rule: DecisionRule) -> tuple[str, dict]:
        d = diagnose_time_effects(rec.force, rec.responses, rec.fs_hz, rec.base, (5.0, 400.0), rule=rule)
        return d["verdict"], next(c for c in d["causes"] if c["effect"] == "input_noise")

    v, c = verdict(DEFAULT_RULE)
    assert v == "input_noise" and DEFAULT_RULE.min_gain_db < c["gain_db"] < 2.0
    v, c2 = verdict(DecisionRule(min_gain_db=2.0))
    assert v == "none" and not c2["significant"] and c2["gain_db"] == c["gain_db"]


def _judge(rule: DecisionRule, stiffer):
    """The physical stage's judge of one candidate whose FRF error is 5 dB above the noise and 1 dB below the
    unchanged simulation's, its held-out modes' chi2 a tenth of the unchanged simulation's (10 dB)."""
    from analysis.diagnosis.compare import line_weights, typical_error_db
    from analysis.diagnosis.physical_verdict import _Judge

    meas, _ = stiffer
    ext = replace(meas, H=meas.H * 1.02)
    w = line_weights(meas)
    after = typical_error_db(meas, ext.H, w)
    judge = _Judge(meas, lambda changes: ext, w, np.full(4, 10.0), np.zeros(4, bool), after + 1.0, after - 5.0, rule)
    return judge.judge([("stiffness_shift", {})], np.full(4, 1.0), ())


def test_the_physical_stage_takes_significance_and_adequacy_from_the_rule(stiffer) -> None:
    c = _judge(DEFAULT_RULE, stiffer)
    assert c["gain_db"] == pytest.approx(10.0) and c["significant"] and c["modes_adequate"]
    assert not c["adequate"]                          # 5 dB above the noise, little of the excess removed
    assert _judge(DecisionRule(none_margin_db=6.0), stiffer)["adequate"]
    assert not _judge(DecisionRule(physical_min_gain_db=12.0), stiffer)["significant"]
    assert not _judge(DecisionRule(none_margin_db=6.0, discrepancy_chi2=0.5), stiffer)["adequate"]


def test_the_second_cause_rule_and_a_refinement_take_the_physical_gain_from_the_rule(monkeypatch) -> None:
    from analysis.diagnosis import physical
    from analysis.diagnosis.physical import CauseSpec, ParamSpec, PhysicalFit, _best_variant
    from analysis.diagnosis.physical_verdict import _on_top_enough

    alone, pair = np.full(10, 0.5), np.full(10, 0.2)          # 4 dB better, 3 of chi2 removed
    assert _on_top_enough(alone, pair, 0.0)[2]
    assert not _on_top_enough(alone, pair, 0.0, DecisionRule(physical_min_gain_db=5.0))[2]
    assert not _on_top_enough(alone, pair, 0.0, DecisionRule(quiet_chi2=4.0))[2]

    spec = CauseSpec("added_mass", (ParamSpec("mass_kg", 0.05, 30.0, nominal=0.0),
                                    ParamSpec("inertia_factor", 0.1, 30.0, requires="mass_kg")))
    plain = PhysicalFit(cause="added_mass", params={}, free=("mass_kg",), chi2=1.0, cv_per_mode=np.full(5, 1.0))
    refined = PhysicalFit(cause="added_mass", params={}, free=("mass_kg", "inertia_factor"), chi2=0.5,
                          cv_per_mode=np.full(5, 0.4))           # 4 dB better on held-out modes
    chi2 = {plain.free: plain.chi2, refined.free: refined.chi2}
    # fit_cause and the cross-validation stand in: each variant's fit and held-out chi2 as above
    monkeypatch.setattr(physical, "fit_cause", lambda sim, cause, free, *a, **k: ({}, chi2[tuple(free)], []))
    monkeypatch.setattr(physical, "_best_of", lambda sim, cause, mm, fmax, fits, bar, *_:
                        refined if any("inertia_factor" in f.free for f in fits) else plain)
    nothing: Any = None                                          # no simulation: the stand-ins answer
    modes: Any = SimpleNamespace(freq_hz=np.arange(5.0))
    assert _best_variant(nothing, spec, modes, 0.0) is refined
    assert _best_variant(nothing, spec, modes, 0.0, DecisionRule(physical_min_gain_db=5.0)) is plain


def test_the_mode_vote_takes_its_separation_from_the_rule() -> None:
    from analysis.diagnosis.verdict import _mass_or_stiffness

    f = np.arange(100.0)
    modes = np.array([20.0, 50.0, 80.0])
    region = np.searchsorted(np.sqrt(modes[:-1] * modes[1:]), f)
    # the two predictions differ by 100, 25 and 25 (weighted, summed) in the three modes' regions; the
    # stiffness has the smaller held-out error at the first mode, the mass at the other two
    diff = np.array([100.0, 25.0, 25.0])
    pred_b = np.sqrt(diff[region] / np.bincount(region)[region])[None, None, :]
    err_st = np.where(region == 0, 1.0, 2.0)[None, None, :]
    err_ma = np.where(region == 0, 2.0, 1.0)[None, None, :]
    ctx: Any = SimpleNamespace(measured=SimpleNamespace(freq_hz=f, H=np.zeros((1, 1, f.size))),
                          base=SimpleNamespace(freq_hz=modes), weights=np.ones((1, 1, f.size)))

    def vote(rule: DecisionRule) -> tuple[bool, list]:
        causes = [{"effect": "stiffness_shift", "gain_db": 10.0, "significant": True, "evidence": "",
                   "parameters": {"factor": 1.01}, "_held_out_after": err_st.ravel(),
                   "_extended": SimpleNamespace(H=np.zeros((1, 1, f.size)))},
                  {"effect": "mass_loading", "gain_db": 8.0, "significant": True, "evidence": "",
                   "parameters": {"mass_kg": 0.1}, "_held_out_after": err_ma.ravel(),
                   "_extended": SimpleNamespace(H=pred_b.astype(complex))}]
        trace: list = []
        _mass_or_stiffness(causes, ctx, 0.0, rule, trace)       # noise power 1 per line
        return bool(causes[0]["significant"]), trace

    kept, trace = vote(DEFAULT_RULE)                  # all three modes separate (>= 2 * 3^2): the mass wins 2 to 1
    assert not kept and trace[0]["rule"] == "mass_or_stiffness" and trace[0]["values"]["separable_modes"] == 3
    kept, trace = vote(DecisionRule(separation_z=5.0))  # only the first separates (>= 2 * 5^2): the stiffness
    assert kept and trace[0]["values"]["separable_modes"] == 1 and trace[0]["outcome"] == "kept"


def test_diagnose_hands_its_one_rule_to_the_physical_stage(stiffer, monkeypatch) -> None:
    """With an FE model the physical stage gets the very rule given to :func:`diagnose` and its trace leads
    the result's (the stage's own decisions are tested above on its judge)."""
    from analysis.diagnosis import physical_verdict as pv

    meas, base = stiffer
    seen = []

    def stage(*args, rule, **kw):
        seen.append(rule)
        return pv.PhysicalOutcome(decided=False, trace=[step("discrepancy", None, {"seen": True}, "neither differs")])

    monkeypatch.setattr(pv, "physical_verdict", stage)
    rule = DecisionRule(quiet_chi2=2.5)
    d = diagnose(meas, base, effects=ONLY, physical=SimpleNamespace(causes=lambda: []), rule=rule)
    assert seen == [rule]
    assert d.trace[0]["rule"] == "discrepancy" and d.trace[0]["values"] == {"seen": True}
