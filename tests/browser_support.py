"""Headless Chromium for the browser tests (the report's and the station's), and the one rule for
when it is missing: outside CI the test skips with how to install it; with ``CI=true`` it fails, so
CI cannot skip the browser tests silently."""
from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

import pytest

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
INSTALL = ("install the browser for these tests: apt-get install chromium chromium-driver, and pip install "
           "selenium (in the test extra: pip install -e '.[test,report]')")


def missing_browser() -> list[str]:
    """What the browser tests need and cannot find (empty when chromium, chromedriver and selenium are there)."""
    missing = [p for p in (CHROMIUM, CHROMEDRIVER) if not (Path(p).exists() or shutil.which(Path(p).name))]
    try:
        import selenium  # noqa: F401
    except ImportError:
        missing.append("selenium (Python package)")
    return missing


def require_browser(missing: list[str]) -> None:
    """Skip (outside CI) or fail (``CI=true``) when something the browser tests need is missing."""
    if missing:
        message = f"browser tests need {', '.join(missing)}: {INSTALL}"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail("CI=true: " + message)
        pytest.skip(message)


def headless_chrome(profile_dir: Path, window: str = "1280,1000", logs: bool = False) -> Any:
    """A headless Chromium driven by selenium (skips or fails by :func:`require_browser` when missing);
    ``logs``: keep the browser console and the network log (``get_log("browser"/"performance")``)."""
    require_browser(missing_browser())
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM if Path(CHROMIUM).exists() else shutil.which("chromium")
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                "--disable-component-update", "--no-first-run", f"--window-size={window}",
                f"--user-data-dir={profile_dir}"):
        opts.add_argument(arg)
    if logs:
        opts.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
    return webdriver.Chrome(service=Service(CHROMEDRIVER if Path(CHROMEDRIVER).exists() else shutil.which("chromedriver")),
                            options=opts)
