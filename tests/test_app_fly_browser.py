"""Browser test of the Fly tab (pytest-playwright, Debian's chromium): fly, play back, inject a wind change.

Its own ``uam-studio serve`` subprocess (``app_url`` in tests/conftest.py); the screenshot goes to
``assets/screenshots/fly_tab.png`` when ``UAM_SCREENSHOTS=1``.
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import pytest
from drawn import FLEET_DAYS, FLEET_PACKS, FLY_VOLTAGE, MANY_RATES, MANY_SERVED, assert_drawn

pytest.importorskip("playwright")

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
TIMEOUT_MS = 120_000

pytestmark = pytest.mark.skipif(not Path(CHROMIUM).exists(), reason="chromium is not installed")


# The Fly voltage figure: the playback time (min), the latest time any curve reaches, the latest decision
# marker, and the wind-change labels.
JS_VOLTAGE = """() => { const out = {now_min: null, curve_max_min: 0, last_decision_min: 0, changes: []};
  for (const v of window.Bokeh.index.all_views()) { const m = v.model;
    if (m.type !== 'Figure' || !m.title || !m.title.text.startsWith('voltage: measured')) continue;
    for (const r of m.renderers) { if (!r.glyph || !r.data_source) continue; const d = r.data_source.data;
      const t = d.time_min ? [...d.time_min] : [];
      if (r.glyph.type === 'Line' && t.length) out.curve_max_min = Math.max(out.curve_max_min, ...t);
      if (r.glyph.type === 'Scatter' && t.length) out.last_decision_min = Math.max(...t);
      if (r.glyph.type === 'Text' && d.text) out.changes = [...d.text];
    }
    for (const c of [...m.renderers, ...m.center])
      if (c.type === 'Span' && c.dimension === 'height') out.now_min = c.location;
  }
  return out; }"""


# The injected change's time (min) on the voltage figure, and the Fly log's "leg wind vs forecast" column.
JS_CHANGE_MIN = """() => { for (const v of window.Bokeh.index.all_views()) { const m = v.model;
    if (m.type !== 'Figure' || !m.title || !m.title.text.startsWith('voltage: measured')) continue;
    for (const r of m.renderers) if (r.glyph && r.glyph.type === 'Text' && r.data_source.data.text.length)
      return r.data_source.data.x[0]; }
  return null; }"""
LEG_WINDS = '.uam-fly-log .tabulator-row .tabulator-cell[tabulator-field="leg wind vs forecast (kt)"]'


def _speed(page, value: str) -> None:
    page.locator(".bk-input-group", has_text="Playback speed").locator("select").select_option(value)


def test_fly_tab_flies_plays_and_takes_a_wind_change(browser, app_url):
    page = browser.new_page(viewport={"width": 1366, "height": 768})
    outside = []
    page.on("request", lambda r: outside.append(r.url) if not r.url.startswith(
        ("http://127.0.0.1", "http://localhost", "ws://127.0.0.1", "ws://localhost", "data:", "blob:"))
        else None)
    page.goto(app_url, timeout=TIMEOUT_MS)
    page.locator(".bk-tab", has_text="Fly").click(timeout=TIMEOUT_MS)
    _speed(page, "10")
    # the README's demo flies the teaching world (the pack its model), chosen as a class would
    page.locator(".bk-input-group", has_text="The world").locator("select").select_option(
        "its model (teaching)")
    page.locator("button", has_text="Fly the mission").click(timeout=TIMEOUT_MS)
    status = page.locator(".uam-fly-status")
    status.get_by_text("flying:").wait_for(timeout=TIMEOUT_MS)
    # playback moves the clock and fills the decision log
    log = page.locator(".uam-fly-log")
    try:  # any shown match: the first in the page's order may be one the table keeps hidden
        log.get_by_text("vertiport").filter(visible=True).first.wait_for(timeout=TIMEOUT_MS)
    except Exception as err:  # say how far the playback got (the first decision is 20 s into the flight)
        shown = status.get_by_text(re.compile("flying|flown")).first.inner_text(timeout=5_000)
        matches = log.get_by_text("vertiport").count()
        raise AssertionError(f"no decision shown in the log; status: {shown!r}; {matches} hidden matches; "
                             f"log text: {log.first.inner_text(timeout=5_000)[:300]!r}") from err
    # while it plays, nothing from its future: no result, no curve or decision after the playback time
    text = status.get_by_text("flying:").inner_text()  # the status line (inside the pane's shadow root)
    assert text.startswith("flying:") and "hindsight" not in text and "flown:" not in text, text
    facts = page.evaluate(JS_VOLTAGE)
    assert facts["now_min"] is not None and facts["curve_max_min"] <= facts["now_min"] + 0.1, facts
    assert facts["last_decision_min"] <= facts["now_min"] + 0.1, facts
    page.locator("button", has_text="Inject wind change now").click(timeout=TIMEOUT_MS)
    page.wait_for_function(f"() => ({JS_VOLTAGE})().changes.length === 1", timeout=TIMEOUT_MS)
    # the change, marked where it was injected
    assert page.evaluate(JS_VOLTAGE)["changes"][0] == "wind +25 kt from the next take-off"
    inject_s = round(60 * page.evaluate(JS_CHANGE_MIN))
    _speed(page, "1000")  # on to the landing: then the result and the references show
    status.get_by_text("hindsight oracle (best known plan)").wait_for(timeout=TIMEOUT_MS)
    status.get_by_text("flown:").wait_for(timeout=TIMEOUT_MS)
    assert "first leg's lowest voltage: believed" in status.get_by_text("flown:").inner_text()
    assert_drawn(page, "voltage: measured", FLY_VOLTAGE)
    # the playback went on from the injection: the next arrival's re-plan is in the log
    log.get_by_text(re.compile(r"plan (changed|unchanged)")).first.wait_for(timeout=TIMEOUT_MS)
    # The operator noticed the change: the log shows what each leg measured against the forecast, the
    # same as the library's flight with the event, and at least one leg after the change flew over 20 kt
    # more headwind against the forecast than the same flight without it.
    from uam_studio.app.planner.state import PlannerState
    from uam_studio.planning.operations import WindEvent, fly_mission

    mission = PlannerState().mission
    flown = fly_mission(mission, seed=0, events=[WindEvent(inject_s, 25.0)], world="model")
    calm = fly_mission(mission, seed=0, world="model")
    cells = page.locator(LEG_WINDS)
    cells.nth(len(flown.events) - 1).wait_for(timeout=TIMEOUT_MS)
    shown = [t.strip() for t in cells.all_inner_texts()]
    assert shown == [d.leg_wind_text for d in reversed(flown.events)], (shown, inject_s)
    after = [d.leg_wind_vs_forecast_kts for d in flown.events[1:]]
    before = [d.leg_wind_vs_forecast_kts for d in calm.events[1:]]
    assert max(a - b for a, b in zip(after, before)) > 20.0, (after, before)
    # The README's demo: the flight lands safe (the weather reserve covers +25 kt), and the log says what
    # the operator believes about the change: its probability at each decision, higher by the landing
    # than without the change, and its words where it has some ("perhaps a change of about ...").
    assert not flown.breached and "BREACHED" not in status.get_by_text("flown:").inner_text(), flown.breach_cause
    p_cells = page.locator('.uam-fly-log .tabulator-row .tabulator-cell[tabulator-field="wind changed (p)"]')
    assert [t.strip() for t in p_cells.all_inner_texts()] == [f"{d.wind_change_p:.2f}" for d in reversed(flown.events)]
    assert flown.events[-1].wind_change_p > calm.events[-1].wind_change_p, (flown.events[-1], calm.events[-1])
    said = [d.wind_change for d in flown.events if d.wind_change]
    assert said, [d.reason for d in flown.events]
    log.get_by_text(said[-1]).first.wait_for(timeout=TIMEOUT_MS)
    if os.environ.get("UAM_SCREENSHOTS") == "1":
        page.screenshot(path=str(ROOT / "assets" / "screenshots" / "fly_tab.png"))
    width = page.evaluate("() => document.documentElement.scrollWidth")
    assert width <= 1366 + 1, width
    assert not outside, outside[:5]
    page.close()


def test_fleet_tab_runs_a_day_for_the_three_dispatchers(browser, app_url):
    """The Fleet tab at 1366x768: one click flies a day for the three dispatchers; the status names each,
    the three figures are there and draw their glyphs (pixels of each colour) after one day and after
    three, nothing overflows sideways (screenshot with UAM_SCREENSHOTS=1)."""
    page = browser.new_page(viewport={"width": 1366, "height": 768})
    page.goto(app_url, timeout=TIMEOUT_MS)
    page.locator(".bk-tab", has_text="Fleet").click(timeout=TIMEOUT_MS)
    page.locator(".uam-fleet-run button").click(timeout=TIMEOUT_MS)
    status = page.locator(".uam-fleet-status")
    line = status.get_by_text("day 1:")
    line.wait_for(timeout=TIMEOUT_MS)
    text = line.inner_text()
    assert all(word in text for word in ("health-aware", "health-blind", "hindsight")), text
    assert re.search(r"hindsight \d+ stars, .*\(at most \d+ possible\)", text), text  # the day's bound
    titles = page.evaluate("() => [...window.Bokeh.index.all_views()].filter(v => v.model.type === 'Figure' && "
                           "v.model.title && v.model.title.text).map(v => v.model.title.text)")
    for start in ("Served priority", "Last day, health-aware", "Each pack after"):
        assert any(t.startswith(start) for t in titles), titles
    assert_drawn(page, "Served priority", FLEET_DAYS)  # one day: its markers
    assert_drawn(page, "Each pack after", FLEET_PACKS)
    for day in (2, 3):
        page.locator(".uam-fleet-run button").click(timeout=TIMEOUT_MS)
        status.get_by_text(f"day {day}:").wait_for(timeout=TIMEOUT_MS)
    assert_drawn(page, "Served priority", FLEET_DAYS)
    assert_drawn(page, "Each pack after", FLEET_PACKS)
    if os.environ.get("UAM_SCREENSHOTS") == "1":
        page.screenshot(path=str(ROOT / "assets" / "screenshots" / "fleet_tab.png"))
    assert page.evaluate("() => document.documentElement.scrollWidth") <= 1366 + 1
    page.close()


def test_fly_tab_flies_a_pack_with_its_logbook(browser, app_url, tmp_path):
    """The student picks a pack whose logbook holds 3 flights: the log's first decision says where its belief came
    from and prints q_max +- std in full, the same numbers as the library's flight of that pack."""
    page = browser.new_page(viewport={"width": 1366, "height": 768})
    page.goto(app_url, timeout=TIMEOUT_MS)
    page.locator(".bk-tab", has_text="Fly").click(timeout=TIMEOUT_MS)
    page.locator(".uam-fly-pack select").select_option("its logbook: 3 flights")
    _speed(page, "1000")
    page.locator("button", has_text="Fly the mission").click(timeout=TIMEOUT_MS)
    page.locator(".uam-fly-status").get_by_text("flown:").wait_for(timeout=TIMEOUT_MS)
    from uam_studio.app.planner.state import PlannerState
    from uam_studio.planning.operations import fly_mission
    from uam_studio.planning.operations.pack_history import simulate_logbook

    mission = PlannerState().mission
    rec = fly_mission(mission, seed=0, logbook=simulate_logbook(mission, 3, 0))
    first = rec.events[0]
    cell = '.uam-fly-log .tabulator-row .tabulator-cell[tabulator-field="{}"]'
    sources = page.locator(cell.format("belief from"))
    sources.nth(len(rec.events) - 1).wait_for(timeout=TIMEOUT_MS)
    assert sources.all_inner_texts()[-1].strip() == "logbook (3 flights)"
    q_cells = page.locator(cell.format("q_max (C)"))
    shown = q_cells.all_inner_texts()[-1].strip()
    assert shown == f"{first.q_max_c:.0f} ± {first.q_max_sd_c:.0f}", shown
    # shown whole: the cell's text is not cut by its column
    fits = page.evaluate(f"() => [...document.querySelectorAll('{cell.format('q_max (C)')}')]"
                         ".every(c => c.scrollWidth <= c.clientWidth)")
    assert fits
    page.screenshot(path=str(tmp_path / "fly_logbook.png"))
    if os.environ.get("UAM_SCREENSHOTS") == "1":
        page.screenshot(path=str(ROOT / "assets" / "screenshots" / "fly_tab_logbook.png"))
    assert page.evaluate("() => document.documentElement.scrollWidth") <= 1366 + 1
    page.close()


def test_fly_tab_flies_many_flights_and_draws_the_price_of_safety(browser, app_url):
    """The "many flights" card: two flights per declared risk (the slider one step left), flown and drawn: the breach
    rates against the line rate = risk, the priority served, and one table row per risk."""
    page = browser.new_page(viewport={"width": 1366, "height": 900})
    page.goto(app_url, timeout=TIMEOUT_MS)
    page.locator(".bk-tab", has_text="Fly").click(timeout=TIMEOUT_MS)
    page.get_by_text("Many flights: the price of safety").click(timeout=TIMEOUT_MS)
    card = page.locator(".uam-many")
    card.locator(".noUi-handle").first.press("ArrowLeft", timeout=TIMEOUT_MS)  # 4 -> 2 flights per risk
    card.get_by_text("Flights per declared risk: 2").wait_for(timeout=TIMEOUT_MS)
    page.locator("button", has_text="Fly many flights").click(timeout=TIMEOUT_MS)
    rows = page.locator(".uam-many-table .tabulator-row")
    rows.nth(3).wait_for(timeout=TIMEOUT_MS)
    risks = [t.strip() for t in page.locator(
        '.uam-many-table .tabulator-row .tabulator-cell[tabulator-field="declared risk"]').all_inner_texts()]
    assert risks == ["0.01", "0.05", "0.1", "0.2"], risks
    page.get_by_text("2 flights per declared risk").wait_for(timeout=TIMEOUT_MS)
    card.scroll_into_view_if_needed()
    assert_drawn(page, "breach rate against the declared risk", MANY_RATES)
    assert_drawn(page, "priority served / hindsight", MANY_SERVED)
    if os.environ.get("UAM_SCREENSHOTS") == "1":
        card.screenshot(path=str(ROOT / "assets" / "screenshots" / "fly_many.png"))
    page.close()
