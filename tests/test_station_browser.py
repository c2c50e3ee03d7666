"""A real headless Chromium drives the station page through a two-point test on sim:// with a double
hit, as an operator would (buttons and keys), then the recording is checked.

The simulated doors' ``faults=double_hit:P`` with a fixed ``fault_seed`` spoils the same strikes on
every run (the strike sequence does not depend on timing); the test reacts to what the page shows.
Skips with an install hint when chromium/chromedriver/selenium are missing; fails under CI=true."""
from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from station_support import WAIT_S, StationProcess, chrome

POINTS = ["right:6:-X", "left:9:Y"]  # the second is struck where a sensor is: its driving point
HITS = 2
DEVICE = "sim://?seed=1&faults=double_hit:0.25&fault_seed=4"  # strike 2 is a double hit


@pytest.fixture(scope="module")
def browser(tmp_path_factory) -> Iterator[Any]:
    """One Chromium for the module's tests (each starts its own station); :func:`_fresh` between them."""
    driver = chrome(tmp_path_factory.mktemp("station-browser"))
    yield driver
    driver.quit()


def _fresh(driver: Any) -> Any:
    """The browser with one blank tab and an empty console log, as a test starts it."""
    for handle in driver.window_handles[1:]:
        driver.switch_to.window(handle)
        driver.close()
    driver.switch_to.window(driver.window_handles[0])
    driver.get("about:blank")
    driver.get_log("browser")
    return driver


def test_operator_runs_a_two_point_test_in_the_browser(browser, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys
    from selenium.webdriver.support.ui import Select, WebDriverWait

    driver = _fresh(browser)
    rec = tmp_path / "rec.h5"
    s = StationProcess(["--device", DEVICE, "--out", str(rec), "--points", ",".join(POINTS), "--hits", str(HITS)],
                       tmp_path)
    try:
        wait = WebDriverWait(driver, WAIT_S, poll_frequency=0.05)
        driver.get(s.url)
        body = driver.find_element(By.TAG_NAME, "body")
        verdict = driver.find_element(By.ID, "hit-verdict")
        wait.until(lambda d: d.find_element(By.ID, "control").text == "in control"
                   and body.get_attribute("data-phase") == "setup")
        # a second tab sees the same session, read-only
        first = driver.current_window_handle
        driver.switch_to.new_window("tab")
        driver.get(s.url)
        wait.until(lambda d: d.find_element(By.TAG_NAME, "body").get_attribute("data-phase") == "setup")
        assert "read-only" in driver.find_element(By.ID, "control").text
        assert driver.find_element(By.CSS_SELECTOR, '[data-action="arm"]').get_attribute("disabled")
        assert driver.find_element(By.ID, "current-point").text == POINTS[0]
        driver.close()
        driver.switch_to.window(first)
        body = driver.find_element(By.TAG_NAME, "body")
        verdict = driver.find_element(By.ID, "hit-verdict")

        # the set-up panel: a change is checked against the analyser before it can be applied
        driver.find_element(By.CSS_SELECTOR, "#setup-panel summary").click()
        status = driver.find_element(By.ID, "setup-status")
        apply = driver.find_element(By.ID, "setup-apply")
        level = driver.find_element(By.ID, "trig-level")
        level.clear()
        level.send_keys("900")  # 2 V at the force input: beyond its 1 V range
        wait.until(lambda d: "outside the 1 V range" in status.text and not apply.is_enabled())
        level.clear()
        level.send_keys("20")
        Select(driver.find_element(By.CSS_SELECTOR, 'select[data-ch="0"]')).select_by_visible_text("2")
        wait.until(lambda d: status.text.startswith("valid") and apply.is_enabled())
        apply.click()
        wait.until(lambda d: status.text == "set-up applied")

        def click(action: str) -> None:
            button = driver.find_element(By.CSS_SELECTOR, f'button[data-action="{action}"]')
            wait.until(lambda d: button.is_enabled())
            button.click()

        seen_double = []
        rejected_by_me = 0
        for k, point in enumerate(POINTS):
            wait.until(lambda d, p=point: d.find_element(By.ID, "current-point").text == p)
            while True:
                n_before = int(driver.find_element(By.ID, "accepted-count").text)
                if n_before == HITS:
                    break
                seq = int(verdict.get_attribute("data-seq"))
                click("arm")
                wait.until(lambda d, q=seq: int(verdict.get_attribute("data-seq")) > q
                           and verdict.get_attribute("data-state") in ("decide", "rejected"))
                if verdict.get_attribute("data-state") == "rejected":
                    assert "double hit" in verdict.text
                    seen_double.append(point)
                    wait.until(lambda d: body.get_attribute("data-phase") == "ready")
                    continue
                if rejected_by_me == 0:  # the operator rejects one good-looking hit with the key
                    body.send_keys(Keys.BACKSPACE)
                    rejected_by_me += 1
                    wait.until(lambda d: verdict.get_attribute("data-state") == "rejected"
                               and body.get_attribute("data-phase") == "ready")
                    continue
                if n_before == 0:
                    click("accept")
                else:
                    body.send_keys(Keys.ENTER)
                wait.until(lambda d, n=n_before: driver.find_element(By.ID, "accepted-count").text == str(n + 1)
                           and body.get_attribute("data-phase") in ("ready", "complete"))
            wait.until(lambda d: body.get_attribute("data-phase") == "complete")
            for name in ("force", "response", "force-spectrum", "frf", "coherence", "geometry"):
                el = driver.find_element(By.CSS_SELECTOR, f'[data-plot="{name}"]')
                wait.until(lambda d, e=el: "js-plotly-plot" in e.get_attribute("class"))
            quality = driver.find_element(By.ID, "quality-lines")
            if POINTS[k] == "left:9:Y":  # a driving point: its check shows beside the hits
                wait.until(lambda d, e=quality: "driving point left:9:Y" in e.text)
            else:
                assert "driving point" not in quality.text
            if k == 0:
                driver.save_screenshot(str(tmp_path / "station-point1.png"))
            click("next-point")
        wait.until(lambda d: body.get_attribute("data-phase") == "finished")
        assert seen_double, "the seeded double hit did not show (fault seed no longer spoils strike 2?)"
        assert "finish" not in driver.execute_script("return Array.from(document.querySelectorAll("
                                                     "'button[data-action]:not([disabled])')).map(b => b.dataset.action)")
        logs = [e for e in driver.get_log("browser") if e["level"] == "SEVERE" and "favicon" not in e["message"]]
        assert not [e for e in logs if "Uncaught" in e["message"]], logs
    finally:
        try:
            _fresh(driver)   # off the station's page before it stops
        finally:
            code, _out, err = s.stop()
    assert code == 0, err

    from analysis.recording import Recording

    with Recording(rec) as r:
        hits = list(r.hits())
        frfs = r.frfsets()
        assert r.closed_cleanly
        assert r.setup["channels"][0]["range_v"] == 2.0  # the set-up applied on the page
    accepted = [h for h in hits if h.accepted]
    assert [sum(1 for h in accepted if h.point == p) for p in POINTS] == [HITS, HITS]
    reasons = [h.reasons for h in hits if not h.accepted]
    assert any(any("double hit" in x for x in rs) for rs in reasons)
    assert ["rejected by the operator"] in reasons
    assert [f.references[0] for f in frfs] == POINTS and all(f.meta["n_averages"] == HITS for f in frfs)
    import numpy as np

    assert all(np.isfinite(f.H[:, 0, 1:]).all() for f in frfs)


def test_the_page_numbers_hits_from_1_refuses_a_double_click_and_logs_no_errors(browser, tmp_path):
    """A second tab and the favicon leave no error in the browser's log; the verdict and the log give a
    hit the same number (from 1); a double click of Next point moves one point on; a done point's dot
    stays visible where an accelerometer sits (top:4 carries one)."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    driver = _fresh(browser)
    s = StationProcess(["--device", "sim://?seed=1", "--out", str(tmp_path / "rec.h5"), "--points",
                        "top:4:Z,right:6:-X", "--hits", "1"], tmp_path)
    try:
        wait = WebDriverWait(driver, WAIT_S, poll_frequency=0.05)
        driver.get(s.url)
        body = driver.find_element(By.TAG_NAME, "body")
        wait.until(lambda d: d.find_element(By.ID, "control").text == "in control"
                   and body.get_attribute("data-phase") == "setup")
        first = driver.current_window_handle
        driver.switch_to.new_window("tab")
        driver.get(s.url)
        wait.until(lambda d: "read-only" in d.find_element(By.ID, "control").text)
        second_tab_errors = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
        driver.close()
        driver.switch_to.window(first)
        body = driver.find_element(By.TAG_NAME, "body")
        verdict = driver.find_element(By.ID, "hit-verdict")

        def press(action: str) -> None:
            wait.until(lambda d: d.find_element(By.CSS_SELECTOR, f'button[data-action="{action}"]').is_enabled())
            driver.find_element(By.CSS_SELECTOR, f'button[data-action="{action}"]').click()

        press("arm")
        wait.until(lambda d: verdict.get_attribute("data-state") in ("decide", "rejected"))
        if verdict.get_attribute("data-state") == "decide":
            press("reject")
            wait.until(lambda d: verdict.get_attribute("data-state") == "rejected")
        shown = verdict.text
        assert shown.startswith("hit ") and " at top:4:Z: REJECTED" in shown, shown
        number = shown.split()[1]
        wait.until(lambda d: f"hit {number} at top:4:Z rejected" in d.find_element(By.ID, "messages").text)
        while driver.find_element(By.ID, "accepted-count").text != "1":
            wait.until(lambda d: body.get_attribute("data-phase") in ("ready", "decide"))
            if body.get_attribute("data-phase") == "ready":
                seq = int(verdict.get_attribute("data-seq"))
                press("arm")
                wait.until(lambda d, q=seq: int(verdict.get_attribute("data-seq")) > q
                           and body.get_attribute("data-phase") in ("decide", "ready"))
            else:
                press("accept")
                wait.until(lambda d: body.get_attribute("data-phase") in ("ready", "complete"))
        wait.until(lambda d: body.get_attribute("data-phase") == "complete")
        driver.execute_script("const b = document.querySelector('button[data-action=\"next-point\"]'); b.click(); b.click();")
        wait.until(lambda d: d.find_element(By.ID, "current-point").text == "right:6:-X"
                   and body.get_attribute("data-phase") == "ready")
        assert driver.find_element(By.ID, "accepted-count").text == "0"  # point 2 waits: not skipped
        traces = wait.until(lambda d: (t := d.execute_script(
            "return (document.querySelector('[data-plot=\"geometry\"]').data || []).map("
            "t => [t.name, t.marker ? t.marker.symbol : null, t.text || []])")) and any(x[0] == "done" for x in t) and t)
        names = [t[0] for t in traces]
        sensor, done = traces[names.index("accelerometers")], traces[names.index("done")]
        assert "top:4:Z" in done[2] and sensor[1] == "square-open"
        assert names.index("accelerometers") < names.index("done")  # the dots are drawn over the squares
        press("finish")
        wait.until(lambda d: body.get_attribute("data-phase") == "finished")
        errors = second_tab_errors + [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
        assert not errors, errors  # no 403 for the favicon, no 409 for the second tab's lease or a second click
    finally:
        try:
            _fresh(driver)   # off the station's page before it stops
        finally:
            code, _out, err = s.stop()
    assert code == 0, err
