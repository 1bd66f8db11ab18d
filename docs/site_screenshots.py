"""Screenshots of the built course site at 1366x768 in Chromium, opened from disk with no network.

    python docs/site_screenshots.py SITE_DIR OUT_DIR

Takes the front page, notebook 02's page scrolled to its first figure (build it executed first:
``UAM_DOCS_EXECUTE=1 UAM_DOCS_EXECUTE_ONLY=02_flight_profiles UAM_FAST=1 mkdocs build --strict``), an API
page (the battery layer) and the Results landing page, one PNG each. A request outside the site's folder is
refused and named.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

PAGES = {
    "site_front.png": ("index.html", None),
    "site_notebook_02.png": ("notebooks/02_flight_profiles.html", ".bk-Figure, .bk-Column, .bk-Row"),
    "site_api_battery.png": ("library/battery.html", None),
    "site_results.png": ("results/index.html", None),
}


def refuse_outside(page) -> list[str]:
    """Route every request of the Playwright ``page``: a ``file://`` one goes on, any other is refused and
    its URL added to the list returned (filled as the page loads)."""
    refused: list[str] = []

    def only_local(route) -> None:
        if route.request.url.startswith("file://"):
            route.continue_()
        else:
            refused.append(route.request.url)
            route.abort()

    page.route("**/*", only_local)
    return refused


def main(site: Path, out: Path) -> list[str]:
    """Write one PNG per page of :data:`PAGES` into ``out``; return the refused requests (empty when none)."""
    from playwright.sync_api import sync_playwright

    out.mkdir(parents=True, exist_ok=True)
    refused: list[str] = []
    chromium = shutil.which("chromium") or "/usr/bin/chromium"
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, args=["--no-sandbox"])
        try:
            for name, (path, scroll_to) in PAGES.items():
                page = browser.new_page(viewport={"width": 1366, "height": 768})
                page_refused = refuse_outside(page)
                page.goto((site / path).resolve().as_uri())
                page.wait_for_timeout(1500)
                if scroll_to:
                    if not page.locator(scroll_to).count():
                        raise SystemExit(f"{site / path}: no figure drawn (build the site with the notebook "
                                         "executed: see this script's docstring)")
                    page.locator(scroll_to).first.scroll_into_view_if_needed()
                    page.wait_for_timeout(1000)
                page.screenshot(path=str(out / name))
                refused += page_refused
                page.close()
        finally:
            browser.close()
    return refused


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    bad = main(Path(sys.argv[1]), Path(sys.argv[2]))
    print(f"{len(PAGES)} screenshots in {sys.argv[2]}; requests refused: {bad or 'none'}")
    sys.exit(1 if bad else 0)
