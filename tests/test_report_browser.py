"""The HTML test report in a real headless Chromium (selenium + Debian's chromium/chromium-driver):
no console errors, the mode table's rows equal the fitted modes, every ``data-plot`` element has
drawn content, the mode-shape animation advances, no request leaves ``file://``.

Outside CI the tests skip (with how to install the browser) when chromium, chromedriver or selenium
is missing; with ``CI=true`` they fail instead, so CI cannot skip them silently.
"""
from __future__ import annotations

import io
import json
import sys
import time
from pathlib import Path

import numpy as np
import pytest

# benchmarks/ is not an installed package: make the project root importable under plain `pytest` too
_ROOT = str(Path(__file__).resolve().parents[1])
if _ROOT not in sys.path:
    sys.path.insert(0, _ROOT)

from browser_support import headless_chrome, require_browser  # noqa: E402

from benchmarks.accuracy.validation.datasets import DATASETS  # noqa: E402

PLOTS = ("frf", "coherence", "force-spectrum", "force-time", "response-time", "stabilization", "cmif", "synthesis",
         "automac", "mode-shapes", "diagnosis", "diagnosis-bands")
LOAD_TIMEOUT_S = 60


def test_missing_browser_skips_outside_ci_and_fails_under_ci(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="apt-get install chromium chromium-driver"):
        require_browser(["/usr/bin/chromium"])
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="CI=true: browser tests need /usr/bin/chromedriver"):
        require_browser(["/usr/bin/chromedriver"])
    require_browser([])  # all there: no skip, no failure


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    driver = headless_chrome(tmp_path_factory.mktemp("chromium-profile"), logs=True)
    driver.set_page_load_timeout(LOAD_TIMEOUT_S)
    yield driver
    driver.quit()


@pytest.fixture(scope="module")
def loaded(browser, report_case):
    """The report (with a diagnosis) loaded and drawn; the browser log and network log of the load."""
    from selenium.webdriver.support.ui import WebDriverWait

    browser.get_log("browser")
    browser.get_log("performance")
    browser.get(report_case["report"].resolve().as_uri())
    WebDriverWait(browser, LOAD_TIMEOUT_S).until(lambda d: d.execute_script("return document.body.dataset.ready"))
    return {"driver": browser, "ready": browser.execute_script("return document.body.dataset.ready"),
            "console": browser.get_log("browser"), "network": browser.get_log("performance")}


def test_no_console_errors(loaded):
    assert loaded["ready"] == "1"
    errors = [e for e in loaded["console"] if e["level"] in ("SEVERE", "ERROR")]
    assert not errors, f"console errors: {errors}"


def test_mode_table_rows_equal_the_fitted_modes(loaded, report_case):
    n = loaded["driver"].execute_script("return document.querySelectorAll('table#modes tbody tr').length")
    assert n == report_case["n_modes"] > 0


def test_every_plot_has_drawn_content(loaded):
    script = """
    const out = {};
    for (const el of document.querySelectorAll('[data-plot]')) {
      const name = el.dataset.plot;
      if (el.tagName === 'CANVAS') {
        const px = el.getContext('2d').getImageData(0, 0, el.width, el.height).data;
        let ink = 0;
        for (let i = 0; i < px.length; i += 4) { if (px[i] < 200 || px[i + 1] < 200 || px[i + 2] < 200) ink++; }
        out[name] = {traces: 1, marks: ink};
      } else {
        const traces = (el._fullData || []).filter(t => t.visible === true).length;
        const marks = el.querySelectorAll('.cartesianlayer .trace path, .heatmaplayer image, .barlayer path, '
                                          + '.cartesianlayer .point').length;
        out[name] = {traces: traces, marks: marks};
      }
    }
    return out;"""
    drawn = loaded["driver"].execute_script(script)
    for name in PLOTS:
        assert name in drawn, f"no data-plot={name!r} element"
        assert drawn[name]["traces"] > 0 and drawn[name]["marks"] > 0, f"{name} is empty: {drawn[name]}"
    assert drawn["mode-shapes"]["marks"] > 1000  # the wireframe and its nodes, not a few stray pixels


def _canvas_png(driver) -> np.ndarray:
    from PIL import Image

    el = driver.find_element("css selector", "[data-plot='mode-shapes']")
    return np.asarray(Image.open(io.BytesIO(el.screenshot_as_png)).convert("L"), dtype=int)


def test_animation_advances_and_pauses(loaded):
    from selenium.webdriver.support.ui import WebDriverWait

    d = loaded["driver"]
    d.execute_script("document.querySelector('[data-plot=\"mode-shapes\"]').scrollIntoView()")
    first = _canvas_png(d)
    # poll (no fixed sleep): the picture must change while playing
    WebDriverWait(d, 20, poll_frequency=0.2).until(lambda drv: np.count_nonzero(_canvas_png(drv) != first) > 200)
    d.find_element("id", "play").click()  # pause
    assert d.find_element("id", "play").text == "play"
    frames = d.execute_script("return Number(document.querySelector('[data-plot=\"mode-shapes\"]').dataset.frames)")
    a = _canvas_png(d)
    WebDriverWait(d, 5).until(lambda drv: drv.execute_script("return 1"))
    b = _canvas_png(d)
    assert np.array_equal(a, b), "the picture changes while paused"
    assert frames == d.execute_script("return Number(document.querySelector('[data-plot=\"mode-shapes\"]').dataset.frames)")
    # another mode, larger amplitude: the picture changes although paused
    d.execute_script("const s = document.getElementById('mode-select'); s.value = '1';"
                     "s.dispatchEvent(new Event('change'));")
    WebDriverWait(d, 5, poll_frequency=0.1).until(lambda drv: np.count_nonzero(_canvas_png(drv) != b) > 200)
    # the interpolation of unmeasured nodes moves the rest of the wireframe
    c = _canvas_png(d)
    d.find_element("id", "interpolate").click()
    WebDriverWait(d, 5, poll_frequency=0.1).until(lambda drv: np.count_nonzero(_canvas_png(drv) != c) > 200)
    d.find_element("id", "interpolate").click()
    d.find_element("id", "play").click()  # play again
    assert d.find_element("id", "play").text == "pause"


def test_no_request_leaves_file_urls(loaded):
    urls = []
    for entry in loaded["network"]:
        msg = json.loads(entry["message"])["message"]
        # requests made by the report's documents (the browser's own new-tab page is not ours)
        if msg.get("method") == "Network.requestWillBeSent" and \
                str(msg["params"].get("documentURL", "")).startswith("file://"):
            urls.append(msg["params"]["request"]["url"])
    assert any(u.endswith("plotly.min.js") for u in urls), f"the network log saw no page assets: {urls}"
    outside = [u for u in urls if not u.startswith(("file://", "data:", "blob:"))]
    assert not outside, f"requests outside file://: {outside}"
    resources = loaded["driver"].execute_script(
        "return performance.getEntriesByType('resource').map(e => e.name)")
    assert all(u.startswith(("file://", "data:", "blob:")) for u in resources), resources


def test_legend_click_hides_the_coherence_too(loaded):
    from selenium.webdriver.support.ui import WebDriverWait

    d = loaded["driver"]
    hidden = d.execute_script("""
      const frf = document.querySelector('[data-plot="frf"]');
      const coh = document.querySelector('[data-plot="coherence"]');
      return Plotly.restyle(frf, {visible: 'legendonly'}, [0, 1]).then(() => coh._fullData[0].visible);""")
    assert hidden == "legendonly"
    WebDriverWait(d, 10, poll_frequency=0.1).until(lambda drv: drv.execute_script(
        "return document.querySelector('[data-plot=coherence]')._fullData[0].visible") == "legendonly")


def test_frf_picker_shows_an_frf_and_its_coherence(loaded):
    from selenium.webdriver.support.ui import WebDriverWait

    d = loaded["driver"]
    get = """const frf = document.querySelector('[data-plot="frf"]');
             const coh = document.querySelector('[data-plot="coherence"]');
             return [frf._fullData[10].visible, frf._fullData[11].visible, coh._fullData[5].visible];"""
    assert d.execute_script(get) == ["legendonly"] * 3
    d.execute_script("const p = document.getElementById('frf-picker'); p.value = '5';"
                     "p.dispatchEvent(new Event('change'));")
    WebDriverWait(d, 10, poll_frequency=0.1).until(lambda drv: drv.execute_script(get) == [True, True, True])


def _open_report(driver, index: Path) -> str:
    """Load ``index`` and wait until its plots are drawn; returns ``dataset.ready``."""
    from selenium.webdriver.support.ui import WebDriverWait

    driver.get_log("browser")
    driver.get(index.resolve().as_uri())
    WebDriverWait(driver, LOAD_TIMEOUT_S).until(lambda d: d.execute_script("return document.body.dataset.ready"))
    return driver.execute_script("return document.body.dataset.ready")


@pytest.mark.realdata
def test_report_of_an_imported_real_recording_opens(browser, shared_data, tmp_path):
    """The README's import of the LADISK beam (a real LabVIEW file: no sensitivities, no input ranges)
    gives a report that draws every plot in Chromium without a console error."""
    from acquisition import cli_import
    from analysis import cli_report

    rec = tmp_path / "beam.h5"
    assert cli_import.main([str(shared_data / "ladisk_beam_impact" / "acceleration.lvm"), "--out", str(rec)]) == 0
    assert cli_report.main([str(rec), "--out", str(tmp_path / "rb")]) == 0
    assert _open_report(browser, tmp_path / "rb" / "index.html") == "1"
    errors = [e for e in browser.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
    assert not errors, f"console errors: {errors}"
    n = browser.execute_script("return document.querySelectorAll('table#modes tbody tr').length")
    assert n >= 1


#: the stability class whose markers the picking test clicks (stable frequency, damping and vector)
STABLE = "freq+damp+mac"


def _click_pole(driver, freq_hz: float) -> dict:
    """Click the stable-class marker nearest ``freq_hz`` at the highest model order (a real mouse click
    at the marker's place); returns the marker's {freq_hz, order, damping}, or None when no marker of
    that class lies within 0.5 % of ``freq_hz``."""
    from selenium.webdriver.common.action_chains import ActionChains

    found = driver.execute_script("""
      const div = document.querySelector('[data-plot="stabilization"]');
      const t = div._fullData.findIndex(d => d.meta === 'poles' && d.name.endsWith('vector'));
      const tr = div._fullData[t];
      const dist = tr.x.map(f => Math.abs(f - arguments[0]));
      const near = Math.min(...dist);
      if (near > 5e-3 * arguments[0]) return null;
      let best = -1;  // the nearest column, its highest order
      tr.x.forEach((f, i) => { if (dist[i] <= near + 1e-3 * f && (best < 0 || tr.y[i] > tr.y[best])) best = i; });
      const xa = div._fullLayout.xaxis, ya = div._fullLayout.yaxis, box = div.getBoundingClientRect();
      const px = div._fullLayout._size.l + xa.l2p(tr.x[best]), py = div._fullLayout._size.t + ya.l2p(tr.y[best]);
      return {freq_hz: tr.x[best], order: tr.y[best], damping: tr.customdata[best],
              dx: px - box.width / 2, dy: py - box.height / 2};""", freq_hz)
    if found is None:
        return None
    div = driver.find_element("css selector", "[data-plot='stabilization']")
    # two clicks within plotly's double-click interval (0.3 s) would be a double click (zoom reset): the click
    # waits until 0.45 s have passed since the previous one (the wait for its pick often took that already)
    pause = max(0.0, _CLICK_GAP_S - (time.monotonic() - _last_click[0]))
    ActionChains(driver).pause(pause).move_to_element_with_offset(div, round(found["dx"]), round(found["dy"])) \
        .click().perform()
    _last_click[0] = time.monotonic()
    return found


#: the least time between two clicks on the stabilization diagram (s), and when the last one was made
_CLICK_GAP_S = 0.45
_last_click = [0.0]


def _wait_picks(driver, n: int) -> None:
    """Wait until the diagram counts ``n`` picks."""
    from selenium.webdriver.support.ui import WebDriverWait

    WebDriverWait(driver, 10, poll_frequency=0.1).until(lambda d: d.execute_script(
        "return document.querySelector('[data-plot=\"stabilization\"]').dataset.picks") == str(n))


def test_picked_poles_are_saved_and_fitted(browser, report_case, tmp_path):
    """Click pole markers on the report's stabilization diagram, unpick one, save the picks with the
    page's button (a real download), fit with ``--poles poles.json``: the fit's poles are the picked ones."""
    from selenium.webdriver.support.ui import WebDriverWait

    from analysis import cli_fit

    downloads = tmp_path / "downloads"
    downloads.mkdir()
    browser.execute_cdp_cmd("Browser.setDownloadBehavior", {"behavior": "allow", "downloadPath": str(downloads)})
    assert _open_report(browser, report_case["report"]) == "1"
    browser.execute_script("document.querySelector('[data-plot=\"stabilization\"]').scrollIntoView()")
    picked: list[dict] = []
    for f in (p["freq_hz"] for p in report_case["fit_doc"]["poles"]):
        if any(abs(q["freq_hz"] - f) < 5e-3 * f for q in picked):
            continue  # a close pair drawn as one column: picked once
        q = _click_pole(browser, f)
        if q is None:
            continue
        picked.append(q)
        _wait_picks(browser, len(picked))
    wanted = [q["freq_hz"] for q in picked]
    assert len(wanted) >= 4
    # a second click unpicks, a third picks again
    _click_pole(browser, wanted[0])
    WebDriverWait(browser, 10, poll_frequency=0.1).until(lambda d: d.find_elements(
        "css selector", "#pick-list li").__len__() == len(wanted) - 1)
    _click_pole(browser, wanted[0])
    WebDriverWait(browser, 10, poll_frequency=0.1).until(lambda d: d.find_elements(
        "css selector", "#pick-list li").__len__() == len(wanted))
    assert [round(q["freq_hz"], 4) for q in picked] == sorted(round(q["freq_hz"], 4) for q in picked)
    browser.find_element("id", "save-picks").click()
    saved = downloads / "poles.json"
    WebDriverWait(browser, 10, poll_frequency=0.1).until(lambda d: saved.is_file() and saved.stat().st_size > 0)
    doc = json.loads(saved.read_text())
    assert doc["schema"] == "impactlab.poles/1" and len(doc["poles"]) == len(wanted)
    assert [q["freq_hz"] for q in doc["poles"]] == pytest.approx(sorted(q["freq_hz"] for q in picked))
    out = tmp_path / "fit.json"
    assert cli_fit.main([str(report_case["recording"]), "--poles", str(saved), "--json", str(out), "-q"]) == 0
    fitted = sorted(p["freq_hz"] for p in json.loads(out.read_text())["poles"])
    assert len(fitted) == len(picked)
    assert fitted == pytest.approx(sorted(q["freq_hz"] for q in picked), rel=5e-3)


def test_response_histories_differ_in_colour(loaded):
    """The responses of one point are told apart by colour, not only by dash style."""
    colours = loaded["driver"].execute_script("""
      const div = document.querySelector('[data-plot="response-time"]');
      return div._fullData.filter(t => t.visible === true).map(t => t.line.color);""")
    assert len(colours) >= 2 and len(set(colours)) == len(colours)


@pytest.mark.long
@pytest.mark.realdata
@pytest.mark.parametrize("d", DATASETS, ids=lambda d: d.key)
def test_report_of_every_validation_dataset_opens(browser, shared_data, tmp_path, d):
    """The report of each real dataset of docs/validation.md (its FRFs, fitted in its band) draws every plot in
    Chromium without a console error."""
    from analysis.report_html import build_document, run_fit, write_report

    name = d.key
    frf = d.load(shared_data)
    doc = build_document(frf, run_fit(frf, band=d.fit_band()), input_name=name)
    index = write_report(tmp_path / name, doc)
    assert _open_report(browser, index) == "1", name
    errors = [e for e in browser.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
    assert not errors, f"{name}: console errors: {errors}"
