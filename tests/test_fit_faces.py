"""What the fit shows besides its poles: the mode indicator in the fit JSON and the plots, the picked-poles
file of the report (``analysis fit --poles FILE``), label placement and log-frequency axes."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_cli_fit import F_TRUE, _write_uff58_with_pyuff

from analysis import cli_fit, cli_stabilization
from analysis.frf import FRFSet
from analysis.inputs import InputError
from analysis.mif import cmif, indicator_summary
from analysis.modal import ModalModel, pole_from_fz, synthesize
from analysis.picks import PICKS_SCHEMA, read_picks
from analysis.plots import fit_figure, label_levels


@pytest.fixture(scope="module")
def uff_file(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("faces") / "frame.uff"
    _write_uff58_with_pyuff(p)
    return p


def _two_reference_frf(f_hz=(40.0, 41.0, 90.0), n_out=4, seed=3) -> FRFSet:
    """Accelerance FRFs of three modes seen from two references (a close pair at 40/41 Hz)."""
    rng = np.random.default_rng(seed)
    poles = pole_from_fz(np.asarray(f_hz), np.full(len(f_hz), 0.01))
    phi = rng.standard_normal((n_out, poles.size))
    part = rng.standard_normal((2, poles.size))
    R = phi[:, None, :] * part[None, :, :] * poles.imag / 2j
    model = ModalModel(poles, R, quantity="accelerance", residual_form="none",
                       outputs=[f"n:{k + 1}:Z" for k in range(n_out)], references=["n:10:Z", "n:11:Z"])
    return synthesize(model, np.linspace(1.0, 150.0, 3000))


def test_indicator_summary_is_small_and_keeps_the_peaks():
    frf = _two_reference_frf()
    full = cmif(frf)
    doc = indicator_summary(frf, (20.0, 120.0), max_points=200)
    assert len(doc["freq_hz"]) == 200 and len(doc["cmif_db"]) == 2 and doc["mif"] is None
    band = (frf.freq_hz >= 20) & (frf.freq_hz <= 120)
    assert doc["lines"] == int(band.sum())
    # the peak of the first curve survives the reduction exactly (its bin is represented by it)
    k = int(np.argmax(full[band, 0]))
    assert max(doc["cmif_db"][0]) == pytest.approx(round(20 * np.log10(full[band, 0][k]), 2))
    assert doc["freq_hz"][int(np.argmax(doc["cmif_db"][0]))] == pytest.approx(frf.freq_hz[band][k], abs=1e-4)
    json.dumps(doc, allow_nan=False)
    with pytest.raises(ValueError, match="max_points"):
        indicator_summary(frf, max_points=1)


def test_fit_json_holds_the_mode_indicator_and_plot_has_its_panel(uff_file, tmp_path):
    out, png = tmp_path / "fit.json", tmp_path / "fit.png"
    assert cli_fit.main([str(uff_file), "--json", str(out), "--plot", str(png), "--log-freq", "-q"]) == 0
    doc = json.loads(out.read_text())
    ind = doc["mode_indicator"]
    assert len(ind["freq_hz"]) <= 256 and len(ind["cmif_db"]) == 1 and len(ind["mif"]) == len(ind["freq_hz"])
    lo, hi = doc["band"]
    assert lo <= ind["freq_hz"][0] and ind["freq_hz"][-1] <= hi
    # one reference: the MIF dips at each mode in the band, well below its level between modes
    f, m = np.asarray(ind["freq_hz"]), np.asarray(ind["mif"], float)
    assert np.nanmedian(m) > 0.7
    for fr in F_TRUE[(F_TRUE > lo) & (F_TRUE < hi)]:
        near = np.abs(f - fr) < 0.02 * fr
        assert np.nanmin(m[near]) < 0.4
    assert png.stat().st_size > 10_000
    assert len(out.read_bytes()) < 60_000  # compact: the indicator does not swamp the fit's JSON


def test_stabilization_plot_legend_above_and_cmif_below(tmp_path):
    from analysis.stabilization import stabilization

    frf = _two_reference_frf()
    st = stabilization(frf, 8, band=(20.0, 120.0))
    from analysis.plots import plot_stabilization

    for log in (False, True):
        out = plot_stabilization(st, frf, tmp_path / f"stab{log}.png", log_freq=log)
        assert out.stat().st_size > 10_000
    assert cli_stabilization.main([_uff(tmp_path), "--png", str(tmp_path / "s.png"), "--log-freq"]) == 0


def _uff(tmp_path: Path) -> str:
    p = tmp_path / "frame.uff"
    _write_uff58_with_pyuff(p)
    return str(p)


def test_label_levels_keep_close_numbers_apart():
    rows = label_levels([0.10, 0.105, 0.11, 0.5, 0.505], width=0.02)
    assert rows == [0, 1, 2, 0, 1]
    # every pair of labels on one row is at least a label's width apart
    x = np.sort(np.random.default_rng(0).uniform(0, 1, 30))
    rows = label_levels(x, width=0.02, levels=30)
    for r in set(rows):
        on = x[np.asarray(rows) == r]
        assert np.all(np.diff(on) >= 0.02)


def test_fit_figure_labels_do_not_overlap_on_log_axes():
    """Modes from 5 Hz to 1.2 kHz: on a log axis every number has its own place (no two overlap)."""
    fz = np.array([5.0, 5.3, 12.9, 13.5, 35.0, 50.0, 81.0, 128.0, 160.0, 161.0, 199.0, 283.0, 616.0, 623.0, 1100.0])
    poles = pole_from_fz(fz, np.full(fz.size, 0.01))
    model = ModalModel(poles, (np.ones((2, 1, fz.size)) * poles.imag / 2j), quantity="accelerance",
                       residual_form="none", outputs=["n:1:Z", "n:2:Z"], references=["n:3:Z"])
    frf = synthesize(model, np.linspace(1.0, 1200.0, 6000))
    for log in (False, True):
        fig = fit_figure(frf, model, band=(4.0, 1150.0), log_freq=log, indicator=True)
        fig.canvas.draw()
        boxes = [t.get_window_extent() for t in fig.axes[0].texts]
        assert len(boxes) == fz.size
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                assert not boxes[i].overlaps(boxes[j]), (fig.axes[0].texts[i].get_text(), fig.axes[0].texts[j].get_text())
    assert fig.axes[-1].get_xscale() == "log" and fig.axes[-1].get_ylabel() == "MIF [-]"


def _picks(tmp_path: Path, poles: list, band=(20.0, 200.0)) -> Path:
    p = tmp_path / "poles.json"
    p.write_text(json.dumps({"schema": PICKS_SCHEMA, "input": "frame.uff", "band_hz": list(band), "poles": poles}))
    return p


def test_read_picks_gives_poles_or_frequencies(tmp_path):
    picks = read_picks(_picks(tmp_path, [{"freq_hz": 62.0, "damping": 0.01, "order": 9},
                                         {"freq_hz": 30.0, "damping": 0.008, "order": 7}]))
    assert picks.band_hz == (20.0, 200.0) and picks.input == "frame.uff"
    p = picks.initial()
    assert np.iscomplexobj(p) and np.allclose(p, pole_from_fz(np.array([62.0, 30.0]), np.array([0.01, 0.008])))
    no_damping = read_picks(_picks(tmp_path, [{"freq_hz": 62.0}, {"freq_hz": 30.0, "damping": 0.01}]))
    assert no_damping.damping is None and list(no_damping.initial()) == [62.0, 30.0]
    text = tmp_path / "poles.txt"
    text.write_text("30.0\n62.0, 64.5\n")
    assert list(read_picks(text).initial()) == [30.0, 62.0, 64.5]


@pytest.mark.parametrize("content, message", [
    ("{not json", "not valid JSON"),
    (json.dumps({"poles": [{"freq_hz": 30.0}]}), "not a picked-poles file"),
    (json.dumps({"schema": PICKS_SCHEMA, "poles": []}), "holds no picked poles"),
    (json.dumps({"schema": PICKS_SCHEMA, "poles": [{"damping": 0.01}]}), "pole 1 has no \"freq_hz\""),
    (json.dumps({"schema": PICKS_SCHEMA, "poles": [{"freq_hz": "30"}]}), "is not a number"),
    (json.dumps({"schema": PICKS_SCHEMA, "poles": [{"freq_hz": -3.0}]}), "must be > 0 Hz"),
    (json.dumps({"schema": PICKS_SCHEMA, "poles": [{"freq_hz": 30.0, "damping": 0.8}, {"freq_hz": 3, "damping": 1.5}]}),
     "pole 2: damping 1.5 must be a ratio"),
    ("30, sixty", "neither a picked-poles JSON file nor a list of frequencies"),
])
def test_malformed_picks_files_say_what_is_wrong(tmp_path, content, message):
    p = tmp_path / "bad.json"
    p.write_text(content)
    with pytest.raises(InputError, match=message):
        read_picks(p)


def test_fit_with_a_picks_file_fits_exactly_the_picks_in_their_band(uff_file, tmp_path, capsys):
    picks = _picks(tmp_path, [{"freq_hz": 30.1, "damping": 0.009, "order": 5},
                              {"freq_hz": 119.5, "damping": 0.011, "order": 5}], band=(20.0, 150.0))
    out = tmp_path / "fit.json"
    assert cli_fit.main([str(uff_file), "--poles", str(picks), "--json", str(out), "-q"]) == 0
    doc = json.loads(out.read_text())
    assert doc["band"][0] == pytest.approx(20.0, abs=0.3) and doc["band"][1] == pytest.approx(150.0, abs=0.3)
    fitted = [p["freq_hz"] for p in doc["poles"]]
    assert fitted == pytest.approx([30.0, 120.0], rel=1e-3)  # the picks, refined; nothing added
    capsys.readouterr()
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"schema": PICKS_SCHEMA, "poles": []}))
    assert cli_fit.main([str(uff_file), "--poles", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "holds no picked poles" in err and "Traceback" not in err
    assert cli_fit.main([str(uff_file), "--poles", str(tmp_path / "missing.json")]) == 2
    assert "not found" in capsys.readouterr().err


def test_stabilization_legend_sits_above_the_pole_columns(tmp_path, monkeypatch):
    """The legend is drawn outside the diagram's axes, so no pole column is hidden behind it."""
    import analysis.plots as plots
    from analysis.stabilization import stabilization

    frf = _two_reference_frf()
    st = stabilization(frf, 8, band=(20.0, 120.0))
    figures = []
    real_save = plots._save
    monkeypatch.setattr(plots, "_save", lambda fig, path: (figures.append(fig), real_save(fig, path))[1])
    plots.plot_stabilization(st, frf, tmp_path / "stab.png")
    fig = figures[0]
    fig.canvas.draw()
    ax = fig.axes[0]
    legend = ax.get_legend().get_window_extent()
    assert legend.y0 >= ax.get_window_extent().y1 - 1  # above the plotting area
    assert fig.axes[-1].get_ylabel().startswith("CMIF")  # two references: the CMIF beneath


def test_fleet_png_names_the_flagged_units(tmp_path, monkeypatch):
    """fleet.png ties its points to units: every flagged unit is named in both panels."""
    import matplotlib.figure
    from test_batch_fleet_stats import _fleet

    from analysis.batch.fleet import assess_fleet
    from analysis.batch.outputs import plot_fleet

    units = _fleet(24, {3: {2: 0.03}, 17: {5: -0.04}})
    names = [f"unit{k:02d}" for k in range(24)]
    res = assess_fleet(units, names, [n + ".h5" for n in names])
    flagged = {u.name for u in res.units if u.flagged}
    assert flagged == {"unit03", "unit17"}
    saved = []
    real = matplotlib.figure.Figure.savefig
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", lambda self, *a, **k: (saved.append(self), real(self, *a, **k))[1])
    plot_fleet(tmp_path / "fleet.png", res)
    fig = saved[0]
    for ax in fig.axes[:2]:
        assert {t.get_text() for t in ax.texts} == flagged
    assert (tmp_path / "fleet.png").stat().st_size > 10_000


def test_terminal_table_gives_the_units_of_the_standard_deviations():
    from analysis.report import format_table

    frf = _two_reference_frf()
    from analysis.pipeline import fit_auto

    fit = fit_auto(frf, band=(20.0, 120.0))
    head = format_table(fit.lsfd, frf, initial=fit.selected_poles, initial_label="LSCF").splitlines()[1]
    assert "f std [Hz]" in head and "zeta std [%]" in head and "LSCF f [Hz]" in head and "LSCF zeta [%]" in head


def test_terminal_table_removes_the_windows_decay_from_the_initial_poles_as_from_the_fit():
    from dataclasses import replace

    from analysis.modal import damping_ratio
    from analysis.pipeline import fit_auto
    from analysis.report import format_table

    frf = replace(_two_reference_frf(), exp_window_tau_s=5.0)   # the data as if an exponential window had damped them
    fit = fit_auto(frf, band=(20.0, 120.0))
    shift = fit.lsfd.model.meta["exp_window_shift_rad_s"]
    assert shift == pytest.approx(0.2)
    rows = [r.split("|") for r in format_table(fit.lsfd, frf, initial=fit.selected_poles,
                                                initial_label="LSCF").splitlines()[3:]]
    shown = [float(r[2]) for r in rows if len(r) > 4 and r[0].strip().startswith("pole") and r[2].strip() != "-"]
    structural = sorted(100 * damping_ratio(fit.selected_poles + shift))
    raw = sorted(100 * damping_ratio(fit.selected_poles))
    assert shown and sorted(shown) == pytest.approx(structural[:len(shown)], abs=1e-3)
    assert sorted(shown) != pytest.approx(raw[:len(shown)], abs=1e-3)
