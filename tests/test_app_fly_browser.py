"""Browser test of the Fly tab (pytest-playwright, Debian's chromium): fly, play back, inject a wind change.

Its own ``uam-studio serve`` subprocess (``app_url`` in tests/conftest.py); the screenshot goes to ``assets/screenshots/fly_tab.png``
when ``UAM_SCREENSHOTS=1``.
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import pytest

pytest.importorskip("playwright")

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
TIMEOUT_MS = 120_000

pytestmark = pytest.mark.skipif(not Path(CHROMIUM).exists(), reason="chromium is not installed")


def test_fly_tab_flies_plays_and_takes_a_wind_change(browser, app_url):
    page = browser.new_page(viewport={"width": 1366, "height": 768})
    outside = []
    page.on("request", lambda r: outside.append(r.url) if not r.url.startswith(
        ("http://127.0.0.1", "http://localhost", "ws://127.0.0.1", "ws://localhost", "data:", "blob:"))
        else None)
    page.goto(app_url, timeout=TIMEOUT_MS)
    page.locator(".bk-tab", has_text="Fly").click(timeout=TIMEOUT_MS)
    page.locator("button", has_text="Fly the mission").click(timeout=TIMEOUT_MS)
    status = page.locator(".uam-fly-status")
    status.get_by_text("hindsight oracle").wait_for(timeout=TIMEOUT_MS)
    status.get_by_text("flown:").wait_for(timeout=TIMEOUT_MS)
    # playback moves the clock and fills the decision log
    log = page.locator(".uam-fly-log")
    log.get_by_text("vertiport").first.wait_for(timeout=TIMEOUT_MS)
    page.locator("button", has_text="Inject wind change now").click(timeout=TIMEOUT_MS)
    status.get_by_text("hindsight oracle").wait_for(timeout=TIMEOUT_MS)
    # the playback goes on from the injection: the next arrival's re-plan appears in the log
    log.get_by_text(re.compile(r"plan (changed|unchanged)")).first.wait_for(timeout=TIMEOUT_MS)
    if os.environ.get("UAM_SCREENSHOTS") == "1":
        page.screenshot(path=str(ROOT / "assets" / "screenshots" / "fly_tab.png"))
    width = page.evaluate("() => document.documentElement.scrollWidth")
    assert width <= 1366 + 1, width
    assert not outside, outside[:5]
    page.close()
