"""A teacher's path through every tab of the served app at 1366x768 and 1920x1080, one screenshot per tab
(Planner, Battery lab after picking R0, Fly in flight and after the landing with a wind change injected,
Retrain, Fleet after its first and third day, Glossary):

    python benchmarks/teacher_screenshots.py [OUT_FOLDER]      # default /tmp/uam_screenshots

Needs Debian's chromium and playwright (the test extras). It fails (AssertionError naming the figure and
the glyph) when a plot leaves a promised glyph undrawn: pixels of each legend colour are counted in the
plot frame (``tests/drawn.py``). Look at the pictures too: a count cannot see everything.
"""
import sys
import tempfile
from pathlib import Path

from playwright.sync_api import sync_playwright

from uam_studio.app.serve import ServedApp

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from drawn import (  # noqa: E402
    FLEET_DAYS,
    FLEET_PACKS,
    FLY_VOLTAGE,
    LAB_CURRENT,
    LAB_R0_VOLTAGE,
    PLANNER_VOLTAGE,
    RETRAIN_ORACLE,
    assert_drawn,
)


def main() -> None:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "/tmp/uam_screenshots")
    out.mkdir(exist_ok=True)
    home = Path(tempfile.mkdtemp())
    with ServedApp(home, timeout_s=180) as srv, sync_playwright() as p:
        b = p.chromium.launch(executable_path="/usr/bin/chromium", args=["--no-sandbox"])
        for w, h in ((1366, 768), (1920, 1080)):
            page = b.new_page(viewport={"width": w, "height": h})
            page.goto(srv.url, timeout=120_000)
            page.locator(".uam-plan-compare[data-pending='false']").wait_for(timeout=120_000)
            page.wait_for_timeout(1500)
            page.screenshot(path=str(out / f"planner_{w}.png"))
            assert_drawn(page, "Voltage: physics", PLANNER_VOLTAGE)
            page.locator(".bk-tab", has_text="Battery lab").click()
            page.locator(".uam-lab-summary").get_by_text("this setting").wait_for()
            page.locator(".bk-btn", has_text="R0").click()
            page.locator(".uam-lab-summary").get_by_text("R0 0.45 ohm").wait_for()
            page.wait_for_timeout(1500)
            assert_drawn(page, "Voltage (physics", LAB_R0_VOLTAGE)
            assert_drawn(page, "Per-cell current", LAB_CURRENT)
            page.locator(".bk-tab", has_text="Battery lab").scroll_into_view_if_needed()
            page.screenshot(path=str(out / f"battery_{w}.png"))
            page.locator(".bk-tab", has_text="Fly").click()
            page.locator(".bk-input-group", has_text="Playback speed").locator("select").select_option("100")
            page.locator("button", has_text="Fly the mission").click()
            page.locator(".uam-fly-status").get_by_text("flying:").wait_for(timeout=120_000)
            page.wait_for_timeout(3000)
            page.locator("button", has_text="Inject wind change now").click()
            page.wait_for_timeout(1500)
            page.screenshot(path=str(out / f"fly_mid_{w}.png"))
            page.locator(".bk-input-group", has_text="Playback speed").locator("select").select_option("1000")
            page.locator(".uam-fly-status").get_by_text("flown:").wait_for(timeout=120_000)
            page.wait_for_timeout(1500)
            page.screenshot(path=str(out / f"fly_{w}.png"))
            assert_drawn(page, "voltage: measured", FLY_VOLTAGE)
            page.locator(".bk-tab", has_text="Retrain").click()
            assert_drawn(page, "Destinations reached", RETRAIN_ORACLE, timeout_s=60)
            page.locator(".bk-tab", has_text="Retrain").scroll_into_view_if_needed()
            page.screenshot(path=str(out / f"retrain_{w}.png"))
            page.locator(".bk-tab", has_text="Fleet").click()
            for day in (1, 2, 3):
                page.locator(".uam-fleet-run button").click()
                page.locator(".uam-fleet-status").get_by_text(f"day {day}:").wait_for(timeout=120_000)
                page.wait_for_timeout(1500)
                if day in (1, 3):
                    page.locator(".bk-tab", has_text="Fleet").scroll_into_view_if_needed()
                    page.screenshot(path=str(out / f"fleet_day{day}_{w}.png"))
                    assert_drawn(page, "Served priority", FLEET_DAYS)
                    assert_drawn(page, "Each pack after", FLEET_PACKS)
            page.locator(".bk-tab", has_text="Glossary").click()
            page.wait_for_timeout(1000)
            page.screenshot(path=str(out / f"glossary_{w}.png"))
            page.close()
        b.close()
    print("ok", sorted(x.name for x in out.iterdir()))


if __name__ == "__main__":
    main()
