"""Take the site's screenshots of the Planner, Battery lab, Retrain, Fleet and Glossary tabs at 1366x768 (a
classroom laptop; playwright + Debian's chromium).

    python assets/screenshots/make_screenshots.py [--width 1920 --height 1080 --out DIR]

Serves the app with ``panel serve`` on a free port (user folder in a temporary directory), adds a
destination on the map and waits for the planner comparison, switches to the Battery lab (varying
R0), runs a short DQN retraining and a short attention-planner retraining, flies three fleet days and opens
the Glossary, and writes ``planner.png``, ``battery_lab.png``, ``retrain.png``, ``retrain_attention.png``,
``fleet_tab.png`` and ``glossary.png`` in ``--out`` (default: next to this file). (The Fly tab's screenshots
come from its browser tests, with ``UAM_SCREENSHOTS=1``.)
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
JS_FRAME = """(title) => {
  for (const v of window.Bokeh.index.all_views()) {
    const m = v.model;
    if (m.title && m.title.text && m.title.text.startsWith(title)) {
      const f = v.frame.bbox, r = v.el.getBoundingClientRect();
      return {left: r.left + f.left, top: r.top + f.top, width: f.width, height: f.height,
              x0: m.x_range.start, x1: m.x_range.end, y0: m.y_range.start, y1: m.y_range.end};
    }
  }
  return null;
}"""


def main() -> None:
    import argparse

    from playwright.sync_api import sync_playwright

    ap = argparse.ArgumentParser(description="the README's screenshots")
    ap.add_argument("--width", type=int, default=1366)
    ap.add_argument("--height", type=int, default=768)
    ap.add_argument("--out", type=Path, default=HERE)
    args = ap.parse_args()
    out = args.out
    out.mkdir(parents=True, exist_ok=True)

    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    home = tempfile.mkdtemp(prefix="uam_shots_")
    proc = subprocess.Popen(
        [sys.executable, "-m", "panel", "serve", "uam_studio/app/main.py", "--port", str(port), "--address",
         "127.0.0.1", "--allow-websocket-origin", f"127.0.0.1:{port}", "--warm", "--liveness"],
        cwd=ROOT, env={**os.environ, "UAM_STUDIO_HOME": home}, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        for _ in range(600):
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/liveness", timeout=10):
                    break
            except OSError:
                time.sleep(0.5)
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
            page = browser.new_page(viewport={"width": args.width, "height": args.height})
            page.set_default_timeout(120_000)
            page.goto(f"http://127.0.0.1:{port}/main")
            page.locator(".uam-plan-summary[data-busy='false']").get_by_text("Route:").wait_for()
            fr = page.evaluate(JS_FRAME, "Map")
            page.mouse.click(fr["left"] + (-22 - fr["x0"]) / (fr["x1"] - fr["x0"]) * fr["width"],
                             fr["top"] + (fr["y1"] - 18) / (fr["y1"] - fr["y0"]) * fr["height"])
            page.locator(".uam-plan-summary[data-busy='false'][data-inputs*='|D1:']").wait_for()
            page.locator(".uam-plan-compare[data-pending='false'][data-inputs*='|D1:']").wait_for()
            page.locator(".uam-plan-summary").click()  # the map loses its focus outline
            page.mouse.move(5, args.height - 8)  # no hover tooltip in the picture
            page.wait_for_function("() => [...window.Bokeh.index.all_views()].filter("
                                   "v => v.model.type === 'Figure').length >= 4")  # plots load after the page
            time.sleep(2)
            page.screenshot(path=str(out / "planner.png"))

            page.locator(".bk-tab", has_text="Battery lab").click()
            page.locator(".bk-btn", has_text="R0").first.click()
            page.locator(".uam-lab-summary").get_by_text("R0 0.45 ohm").wait_for()
            time.sleep(2)
            page.screenshot(path=str(out / "battery_lab.png"))

            page.locator(".bk-tab", has_text="Retrain").click()
            box = page.locator(".bk-input-group", has=page.get_by_text("Steps (environment transitions)"))
            box.locator("input").fill("3000")
            box.locator("input").press("Enter")
            page.locator(".uam-train-start button").click()
            page.locator(".uam-train-status").get_by_text("done:").wait_for(timeout=900_000)
            time.sleep(1.5)
            page.screenshot(path=str(out / "retrain.png"))

            page.locator(".uam-train-model button", has_text="Attention").click()
            for css, value in ((".uam-train-missions", "60"), (".uam-train-epochs", "12")):
                page.locator(css).locator("input").fill(value)
                page.locator(css).locator("input").press("Tab")
            page.locator(".uam-train-start button").click()
            page.locator(".uam-train-status").get_by_text("done: 12 epochs").wait_for(timeout=900_000)
            time.sleep(1.5)
            page.screenshot(path=str(out / "retrain_attention.png"))

            page.locator(".bk-tab", has_text="Fleet").click()
            for day in (1, 2, 3):
                page.locator(".uam-fleet-run button").click()
                page.locator(".uam-fleet-status").get_by_text(f"day {day}:").wait_for(timeout=300_000)
            time.sleep(2)
            page.screenshot(path=str(out / "fleet_tab.png"))

            page.locator(".bk-tab", has_text="Glossary").click()
            time.sleep(2)
            page.screenshot(path=str(out / "glossary.png"))
            browser.close()
    finally:
        proc.terminate()
        proc.wait(20)
        shutil.rmtree(home, ignore_errors=True)
    for name in ("planner.png", "battery_lab.png", "retrain.png", "retrain_attention.png", "fleet_tab.png",
                 "glossary.png"):
        print(f"{name}: {(out / name).stat().st_size / 1024:.0f} KB")


if __name__ == "__main__":
    main()
