"""The course site's executed notebook page draws its figures from the site's own files, with no network.

The site is built as ``mkdocs build --strict`` builds it, with one notebook executed in fast mode
(``UAM_DOCS_EXECUTE=1 UAM_DOCS_EXECUTE_ONLY=02_flight_profiles``, docs/hooks.py). Chromium opens the
page from disk (``file://``) with every request outside the site's folder refused, and the pixels of each
Bokeh figure's glyph colours are counted in its plot frame (tests/drawn.py reads the frames).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from drawn import colour_count, frame_pixels

pytest.importorskip("playwright")
pytest.importorskip("mkdocs_jupyter")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs"))
from site_screenshots import refuse_outside  # noqa: E402

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
NOTEBOOK = "02_flight_profiles"

pytestmark = [pytest.mark.skipif(not Path(CHROMIUM).exists(), reason="chromium is not installed"),
              pytest.mark.slow]  # a site build and a notebook run: about 25 s

# Every laid-out Bokeh figure on the page: its title and the hex colours of its glyphs (line and fill).
JS_FIGURES = """() => { const out = [];
  for (const v of window.Bokeh.index.all_views()) { const m = v.model;
    if (m.type !== 'Figure' && m.type !== 'Plot') continue;
    const colours = new Set();
    for (const r of m.renderers) { const g = r.glyph; if (!g) continue;
      for (const k of ['line_color', 'fill_color']) { const c = g[k];
        const value = (c && typeof c === 'object' && 'value' in c) ? c.value : c;
        if (typeof value === 'string' && /^#[0-9a-fA-F]{6}$/.test(value)) colours.add(value.toLowerCase()); } }
    out.push({title: m.title && m.title.text ? m.title.text : '', colours: [...colours]});
  }
  return out; }"""


# True once BokehJS has laid out a view (``all_views`` is an iterator).
JS_ANY_VIEW = "() => window.Bokeh && window.Bokeh.index && [...window.Bokeh.index.all_views()].length > 0"


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site, built with notebook 02 executed (fast mode), in a folder of its own."""
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "UAM_DOCS_EXECUTE": "1", "UAM_DOCS_EXECUTE_ONLY": NOTEBOOK, "UAM_FAST": "1"}
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet", "--site-dir", str(out)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return out


def test_an_executed_notebook_page_draws_its_figures_offline(site, browser):
    page_file = site / "notebooks" / f"{NOTEBOOK}.html"
    html = page_file.read_text()
    assert "cdn.bokeh.org" not in html and "cdn.holoviz.org" not in html and "cdn.jsdelivr" not in html
    page = browser.new_page(viewport={"width": 1366, "height": 768})
    try:
        refused = refuse_outside(page)
        errors: list[str] = []
        page.on("pageerror", lambda err: errors.append(str(err)))
        page.goto(page_file.as_uri())
        page.wait_for_function(JS_ANY_VIEW, timeout=60_000)
        page.wait_for_timeout(1000)  # the last figures' first paint
        figures = [f for f in page.evaluate(JS_FIGURES) if f["title"] and f["colours"]]
        assert len(figures) >= 3, figures
        drawn = {}
        for fig in figures:
            img = frame_pixels(page, fig["title"])
            drawn[fig["title"]] = sum(colour_count(img, c) for c in fig["colours"])
            assert np.asarray(img).size > 0
        blank = {title: n for title, n in drawn.items() if n < 50}
        assert not blank, f"figures with fewer than 50 pixels of their glyphs' colours: {blank} (all: {drawn})"
        assert not errors, errors
    finally:
        page.close()
    assert not refused, f"requests outside the site's files: {refused[:5]}"
