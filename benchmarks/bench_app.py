"""App benchmarks: replanning latency, page load, the planner comparison's cost, the Battery lab, and a
training session beside a planning one.

    python benchmarks/bench_app.py latency      # slider change -> updated plan and views, in process (server side)
    python benchmarks/bench_app.py pageload     # browser: page loads of a served app, to the first plan
    python benchmarks/bench_app.py replan       # browser: slider key -> the summary of that exact input
    python benchmarks/bench_app.py lab          # browser: Battery lab slider key -> its table redrawn
    python benchmarks/bench_app.py concurrency  # browser: two sessions, one retraining, the other replanning
    python benchmarks/bench_app.py flytick      # the Fly tab's playback tick, in process (server side)
    python benchmarks/bench_app.py steps        # browser: 40 slider steps of the Planner against a bare Panel page
    python benchmarks/bench_app.py fly          # browser: the Fly tab's controls alone against the bare page
    python benchmarks/bench_app.py all --append benchmarks/RESULTS.md

latency: the 8-destination single-charge mission below, the Planner's state and views built on a
Bokeh document as in a session, and the R0 slider moved ``--n`` times; each sample is the time from
the widget change to the plan and every view (summary, map, plots) updated. Reference, in the same
run: the bare library call ``plan_mission`` for the same inputs. Policies: the bundled DQN (if
``pretrained/dqn_single_charge.zip`` exists; otherwise that is reported), greedy and the oracle.
Each policy is measured with the planner comparison off and on (``--compare off,process``): on, the
agent/greedy/oracle comparison of each new plan runs in the app's comparison child process, and each
slider move waits long enough for it to start (the oracle on 8 destinations then runs for seconds
while the next plan is measured); the share of samples taken while it ran is reported.

pageload, replan, lab and concurrency serve the app with ``uam-studio serve`` in a subprocess, built
once before the first page (:class:`uam_studio.app.serve.ServedApp`), and drive Debian's chromium
(``/usr/bin/chromium``) with playwright. The page load is the time from ``goto`` to the first plan
shown in the summary, for each of ``--loads`` new pages (the median is the goal's number), with the
comparison off (``UAM_STUDIO_COMPARE=off``) and on (the default). replan: the q_max slider moved
with the keyboard (one 50 C step at a time), timed to the summary of that exact input, with a pause
between moves so that the comparison of each plan runs meanwhile (on) or not (off). lab: the Battery
lab's R0 slider moved one step, timed to the end-of-discharge table of the new value. Concurrency:
session B moves the q_max slider as in replan; first with nothing else running, then while session A
retrains a DQN agent, once with the training in a child process (the app's default) and once in a
thread of the server (for comparison).

flytick: the example mission flown in the Fly tab's state and view (built on a Bokeh document as in a
session), then ``--n`` playback ticks of 0.25 s at x10 (the tick the tab's timer runs every 250 ms);
each sample is one tick with the view's update. Reference, in the same run: the same ticks of the
state alone (its clock and status), the view's figures, sources and log not attached.
"""

from __future__ import annotations

import argparse
import datetime
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout's uam_studio, whatever the installed one points to
sys.path.insert(0, str(Path(__file__).parent))
from _timing import percentile_ms  # noqa: E402

from uam_studio.app.serve import ServedApp  # noqa: E402

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"

# An 8-destination single-charge mission within reach of a healthy cell (about 15-40 km out).
MISSION = {
    "name": "bench 8",
    "vertiport": {"x_km": 0.0, "y_km": 0.0, "wind_kts": 5.0},
    "destinations": [
        {"name": f"P{k + 1}", "x_km": round(r * np.cos(a), 1), "y_km": round(r * np.sin(a), 1),
         "priority": int(1 + k % 3), "wind_kts": float(w)}
        for k, (r, a, w) in enumerate(zip([15, 22, 30, 18, 35, 26, 40, 20],
                                          np.linspace(0.2, 2 * np.pi - 0.4, 8),
                                          [10, -5, 0, 13, -13, 5, 20, -10]))
    ],
    "scenario": "single_charge",
    "battery": {"q_max": 7600.0, "r0": 0.117215},
    "eod_v": 3.0,
}


def _stats(samples: list[float]) -> str:
    return (f"p50 {percentile_ms(samples, 50):.0f} ms, p95 {percentile_ms(samples, 95):.0f} ms, "
            f"max {1000 * max(samples):.0f} ms (n={len(samples)})")


def _load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


# ----------------------------------------------------------------------------- latency (server side)


def bench_latency(n: int, n_oracle: int, compares: list[str]) -> list[str]:
    import torch
    from bokeh.document import Document

    from uam_studio.app.planner.comparison import COMPARE_DELAY_S, comparison_runner
    from uam_studio.app.planner.state import PlannerState
    from uam_studio.app.planner.view import PlannerView
    from uam_studio.app.services import predictor
    from uam_studio.app.session import configure_server_threads
    from uam_studio.bundled import bundled_path
    from uam_studio.planning import mission_from_dict
    from uam_studio.planning.agents.dqn.rollout import bundled_agent_path
    from uam_studio.planning.planner import plan_mission

    configure_server_threads()  # as the served app: one torch thread
    mission = mission_from_dict(MISSION)
    pred = predictor()
    lines = [f"latency: 8-destination single-charge mission, torch threads {torch.get_num_threads()}, "
             f"load average before {_load()}"]
    policies = ["attention", "dqn", "greedy", "oracle"]
    if not bundled_path("attention_planner.pt").is_file():
        lines.append("  attention: no bundled pretrained/attention_planner.pt, not measured")
        policies.remove("attention")
    if not bundled_agent_path("single_charge").is_file():
        lines.append("  dqn: no bundled agent pretrained/dqn_single_charge.zip, not measured")
        policies.remove("dqn")
    if "process" in compares:
        comparison_runner("process").start()  # its imports take seconds: not inside a sample
    for policy in policies:
        count = n_oracle if policy == "oracle" else n
        bare = []
        for compare in compares:
            # every value new to the plan cache: the 4th decimal differs between the two passes
            r0s = [round(float(r), 4) + (0.0001 if compare != "off" else 0.0)
                   for r in np.linspace(0.05, 0.25, count)]
            state = PlannerState(mission=mission, background=True, policy=policy, compare=compare)
            assert state.wait_idle(600)  # (results are applied in the worker thread here: build views after)
            view = PlannerView(state)
            view.__panel__().get_root(Document())  # the views' Bokeh models, as in a session
            view.r0.value = 0.3
            assert state.wait_idle(600)  # warm (agent loaded, caches filled)
            app, overlapped = [], 0
            for r0 in r0s:
                if compare != "off":
                    time.sleep(COMPARE_DELAY_S + 0.2)  # the previous plan's comparison is running now
                    overlapped += comparison_runner(compare).busy
                t0 = time.perf_counter()
                view.r0.value = float(r0)
                assert state.wait_idle(600)
                app.append(time.perf_counter() - t0)
                assert state.plan_request.mission.battery.r0 == r0 and state.plan_error == "", state.plan_error
            note = f"; a comparison was running at {overlapped} of {len(r0s)} samples" if compare != "off" else ""
            lines.append(f"  {policy:6s} app, comparison {compare:7s}: {_stats(app)}{note}")
            state.close()
            if compare != "off":
                comparison_runner(compare).wait_idle(600)
            if not bare:
                for r0 in r0s:
                    t0 = time.perf_counter()
                    plan_mission(mission, policy, r0=float(r0), predictor=pred)
                    bare.append(time.perf_counter() - t0)
                lines.append(f"  {policy:6s} bare plan_mission: {_stats(bare)} (last route: "
                             f"{' '.join(state.plan['route'])})")
    lines.append(f"  load average after {_load()}")
    return lines


# ----------------------------------------------------------------------------- served app + browser


class Served(ServedApp):
    """:class:`uam_studio.app.serve.ServedApp` with a temporary user folder, removed afterwards."""

    def __init__(self, **env: str) -> None:
        super().__init__(tempfile.mkdtemp(prefix="uam_bench_home_"), timeout_s=300, **env)

    def __exit__(self, *exc) -> None:
        super().__exit__(*exc)
        shutil.rmtree(self.home, ignore_errors=True)


def _browser(p):
    return p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])


def _first_plan(page, timeout_ms: int = 120_000) -> None:
    page.locator(".uam-plan-summary[data-busy='false']").get_by_text("Route:").wait_for(timeout=timeout_ms)


def _settle(seconds: float = 20.0) -> None:
    """Give a just-started server's warm-up (comparison child imports, example comparison) time to end."""
    time.sleep(seconds)


def bench_pageload(n: int, compares: list[str]) -> list[str]:
    from playwright.sync_api import sync_playwright

    lines = [f"pageload: load average before {_load()}"]
    for compare in compares:
        with Served(UAM_STUDIO_COMPARE=compare) as srv, sync_playwright() as p:
            _settle()
            browser = _browser(p)
            loads, dom, table = [], [], []
            outside: list[str] = []
            for _ in range(n):
                ctx = browser.new_context(viewport={"width": 1366, "height": 768})
                page = ctx.new_page()
                page.on("request", lambda r, out=outside: out.append(r.url)
                        if not r.url.startswith(("http://127.0.0.1", "ws://127.0.0.1", "data:", "blob:")) else None)
                t0 = time.perf_counter()
                page.goto(srv.url, wait_until="load")
                dom.append(time.perf_counter() - t0)
                _first_plan(page)
                loads.append(time.perf_counter() - t0)
                if compare != "off":
                    page.locator(".uam-plan-compare[data-pending='false']").get_by_text("Oracle (exact)").wait_for(
                        timeout=120_000)
                    table.append(time.perf_counter() - t0)
                ctx.close()
            browser.close()
        lines.append(f"  comparison {compare}: server start {srv.startup_s:.1f} s; page load (goto -> first plan "
                     f"in the summary) median {statistics.median(loads):.2f} s, first {loads[0]:.2f} s, "
                     f"max {max(loads):.2f} s (n={n}; goal median <= 2.5 s)")
        lines.append(f"    document 'load' event: median {statistics.median(dom):.2f} s"
                     + (f"; comparison table complete: median {statistics.median(table):.2f} s" if table else ""))
        lines.append(f"    requests outside the server (CDN etc.): {len(outside)}")
    lines.append(f"  load average after {_load()}")
    return lines


def bench_replan(k: int, compares: list[str], pause_s: float) -> list[str]:
    from playwright.sync_api import sync_playwright

    lines = [f"replan (browser, q_max key -> summary of that input, {pause_s:g} s between moves): "
             f"load average before {_load()}"]
    for compare in compares:
        with Served(UAM_STUDIO_COMPARE=compare) as srv, sync_playwright() as p:
            _settle()
            browser = _browser(p)
            page = browser.new_page(viewport={"width": 1366, "height": 768})
            page.goto(srv.url)
            _first_plan(page)
            policy = page.locator(".uam-plan-summary").get_attribute("data-inputs").split(";")[0]
            _replan_times(page, 2)  # warm
            times, polled = _replan_times(page, k, pause_s)
            browser.close()
        lines.append(f"  comparison {compare:7s} ({policy}): key -> summary painted, in the page: {_stats(times)}"
                     "   (goal p95 <= 250 ms)")
        lines.append(f"  {'':19s}{'':{len(policy) + 3}s}as playwright's polling sees it: {_stats(polled)}")
    lines.append(f"  load average after {_load()}")
    return lines


def bench_lab(k: int) -> list[str]:
    from playwright.sync_api import sync_playwright

    lines = [f"lab (browser, Battery lab R0 key -> end-of-discharge table of the new value): load average "
             f"before {_load()}"]
    with Served() as srv, sync_playwright() as p:
        browser = _browser(p)
        page = browser.new_page(viewport={"width": 1366, "height": 768})
        page.goto(srv.url)
        _first_plan(page)
        page.locator(".bk-tab", has_text="Battery lab").click()
        table = page.locator(".uam-lab-summary")
        table.get_by_text("this setting").wait_for(timeout=120_000)
        handle = page.locator(".bk-input-group", has=page.get_by_text("R0 (ohm)")).locator(".noUi-handle")
        times = []
        for _ in range(k):
            before = table.inner_text()
            handle.focus()
            t0 = time.perf_counter()
            handle.press("PageUp")  # a big step: every curve's end changes
            page.wait_for_function("([el, old]) => el.innerText !== old", arg=[table.element_handle(), before],
                                   timeout=120_000)
            times.append(time.perf_counter() - t0)
            if "0.45" in page.locator(".bk-input-group", has=page.get_by_text("R0 (ohm)")).inner_text():
                handle.press("Home")
                page.wait_for_timeout(1500)
        browser.close()
    lines.append(f"  Battery lab change: {_stats(times)}")
    lines.append(f"  load average after {_load()}")
    return lines


_WATCH_JS = """([el, selector]) => {
  // In the page's own clock: the key's keydown, and the first frame after the summary of the new
  // input appears (its shadow root is watched, so no polling interval adds to the time).
  const root = el.getRootNode();
  window.__uamKey = null; window.__uamShown = null; window.__uamPainted = null;
  document.addEventListener('keydown', () => { if (window.__uamKey === null) window.__uamKey = performance.now(); },
                            {capture: true, once: true});
  const check = () => {
    if (window.__uamShown !== null || !root.querySelector(selector)) return false;
    window.__uamShown = performance.now();
    requestAnimationFrame(() => setTimeout(() => { window.__uamPainted = performance.now(); }, 0));
    obs.disconnect();
    return true;
  };
  const obs = new MutationObserver(check);
  obs.observe(root, {subtree: true, childList: true, attributes: true, characterData: true});
}"""


def _replan_times(page, k: int, pause_s: float = 0.0) -> tuple[list[float], list[float]]:
    """Move the q_max slider k times by one step down and time each updated plan, ``pause_s`` after
    the previous one: ``(in the page, as playwright sees it)`` (s).

    In the page: from the key's keydown to the first frame painted after the summary of that exact
    input appeared (a MutationObserver on the summary's shadow root, the page's own clock). As
    playwright sees it: from ``press`` to ``locator.wait_for`` returning; its polling (checks 0, 20,
    70, 170, 270, 770 ms after the call) rounds each time up to the next check.

    Always the same direction, so every value is new: the app caches plans by their inputs
    (``compute_plan``), and a value seen before would be answered from the cache, not planned.
    """
    handle = page.locator(".bk-input-group", has=page.get_by_text("q_max (C)")).locator(".noUi-handle")
    summary = page.locator(".uam-plan-summary")
    q = float(summary.get_attribute("data-inputs").split(";q_max=")[1].split(";")[0])
    in_page, polled = [], []
    for _ in range(k):
        page.wait_for_timeout(1000 * pause_s)
        q -= 50.0
        selector = f".uam-plan-summary[data-busy='false'][data-inputs*=';q_max={q:g};']"
        page.evaluate(_WATCH_JS, [summary.element_handle(), selector])
        handle.focus()
        t0 = time.perf_counter()
        handle.press("ArrowLeft")
        page.locator(selector).wait_for(timeout=120_000)
        polled.append(time.perf_counter() - t0)
        page.wait_for_function("() => window.__uamPainted !== null", timeout=10_000)
        in_page.append(page.evaluate("() => (window.__uamPainted - window.__uamKey) / 1000"))
    return in_page, polled


_CHANGED_JS = """([el, old, evt, last, want]) => {
  // The page's own clock: from the action (the first ``evt``, or with ``last`` the latest one) to the first
  // frame painted after the summary shows a finished result (data-busy false) for inputs other than ``old``
  // (and, with ``want``, holding that text).
  const root = el.getRootNode();
  window.__uamKey = null; window.__uamPainted = null;
  document.addEventListener(evt, () => { if (last || window.__uamKey === null) window.__uamKey = performance.now(); },
                            {capture: true, once: !last});
  const check = () => {
    const s = root.querySelector(".uam-plan-summary[data-busy='false']");
    if (!s || s.getAttribute('data-inputs') === old || (want && !s.getAttribute('data-inputs').includes(want))) return;
    obs.disconnect();
    requestAnimationFrame(() => setTimeout(() => { window.__uamPainted = performance.now(); }, 0));
  };
  const obs = new MutationObserver(check);
  obs.observe(root, {subtree: true, childList: true, attributes: true, characterData: true});
}"""


def _watch(page, evt: str = "keydown", last: bool = False, want: str = "") -> None:
    summary = page.locator(".uam-plan-summary")
    page.evaluate(_CHANGED_JS, [summary.element_handle(), summary.get_attribute("data-inputs"), evt, last, want])


def _watched(page) -> float:
    page.wait_for_function("() => window.__uamPainted !== null", timeout=120_000)
    return float(page.evaluate("() => (window.__uamPainted - window.__uamKey) / 1000"))


def _slider_steps(page, label: str, pattern: list[str]) -> list[float]:
    """Press each key of ``pattern`` on the slider labelled ``label`` and time (s, the page's clock) until
    the summary shows a finished result for the new input."""
    handle = page.locator(".bk-input-group", has=page.get_by_text(label)).locator(".noUi-handle").first
    out = []
    for key in pattern:
        _watch(page)
        handle.focus()
        handle.press(key)
        out.append(_watched(page))
    return out


_MAP_FRAME_JS = """(title) => {
  for (const v of window.Bokeh.index.all_views()) {
    const m = v.model;
    if ((m.type === 'Figure' || m.type === 'Plot') && m.title && m.title.text.startsWith(title)) {
      v.el.scrollIntoView({block: 'center'});  // a table edit may have scrolled it away
      const f = v.frame.bbox, r = v.el.getBoundingClientRect();
      return {left: r.left + f.left, top: r.top + f.top, width: f.width, height: f.height,
              x0: m.x_range.start, x1: m.x_range.end, y0: m.y_range.start, y1: m.y_range.end};
    }
  }
  return null;
}"""


def _edits(page, n: int) -> tuple[list[float], list[float], list[float]]:
    """(map clicks, wind edits of the destination each click added, quick drags) times (s): a click on an
    empty point of the map adds a destination; its wind cell is set (number editor, Enter); a quick drag is
    10 q_max key presses without waiting, timed from the last one to the plan of the last value."""
    clicks, winds, drags = [], [], []
    for k in range(n):
        fr = page.evaluate(_MAP_FRAME_JS, "Map")
        x = fr["left"] + (-70 - fr["x0"]) / (fr["x1"] - fr["x0"]) * fr["width"]  # a column of the map's west
        y = fr["top"] + (fr["y1"] - (-60 + 30 * k)) / (fr["y1"] - fr["y0"]) * fr["height"]  # with no place on it
        _watch(page, "pointerdown")
        page.mouse.click(x, y)
        clicks.append(_watched(page))
        name = f"D{k + 1}"
        row = page.locator(".tabulator-row", has=page.locator('.tabulator-cell[tabulator-field="name"]',
                                                               has_text=name))
        row.locator('.tabulator-cell[tabulator-field="wind_kts"]').click()
        editing = page.locator(".tabulator-cell.tabulator-editing input")
        editing.fill(str(-5 - k))
        _watch(page, want=f"|{name}:")
        editing.press("Enter")
        winds.append(_watched(page))
    handle = page.locator(".bk-input-group", has=page.get_by_text("q_max (C)")).locator(".noUi-handle").first
    for _ in range(n):
        q = float(page.locator(".uam-plan-summary").get_attribute("data-inputs").split(";q_max=")[1].split(";")[0])
        _watch(page, last=True, want=f";q_max={q - 500:g};")
        handle.focus()
        for _ in range(10):
            handle.press("ArrowLeft")
        drags.append(_watched(page))
    return clicks, winds, drags


_FLY_CHANGES_JS = """() => { for (const v of window.Bokeh.index.all_views()) { const m = v.model;
    if (m.type !== 'Figure' || !m.title || !m.title.text.startsWith('voltage: measured')) continue;
    for (const r of m.renderers) if (r.glyph && r.glyph.type === 'Text' && r.data_source.data.text)
      return r.data_source.data.text.length; }
  return 0; }"""

# Every text the Fly tab's status line (the Bokeh model of the pane '.uam-fly-status') takes, in order, kept in
# window.__uamTexts (a change listener: a text shown for less than a frame is kept too; the watch clears it); the
# model itself in window.__uamStatus.
_FLY_STATUS_JS = """() => { if (window.__uamStatusWatched) return true;
  for (const v of window.Bokeh.index.all_views()) { const m = v.model, c = m.css_classes;
    if (c && c.includes('uam-fly-status')) {
      window.__uamTexts = [];
      m.connect(m.properties.text.change, () => window.__uamTexts.push(String(m.text || '')));
      window.__uamStatus = m; window.__uamStatusWatched = true; return true; } }
  return false; }"""

# The Fly tab computes no flight: its status line does not say "flying..." (a click on "Fly the mission" while it
# does would not change the status, and its busy mark would not be seen). A cleared wind change flies the flight
# again, and the page can take the next click before that flight is shown.
_FLY_IDLE_JS = "() => !String(window.__uamStatus.text || '').includes('flying...')"  # after _FLY_STATUS_JS

_FRAME_WATCH_JS = """([evt, cond]) => {
  // The page's own clock: from the action (the first ``evt``) to the first frame painted after ``cond()`` held;
  // ``cond`` (JS source of a function of the page's Bokeh models) is checked at every animation frame from the
  // action on, and the time taken after that frame (a task queued from its animation-frame callback).
  window.__uamKey = null; window.__uamPainted = null; window.__uamTexts = [];
  const holds = eval(cond);
  document.addEventListener(evt, () => { if (window.__uamKey === null) window.__uamKey = performance.now(); },
                            {capture: true, once: true});
  const frame = () => {
    if (window.__uamKey !== null && holds()) {
      setTimeout(() => { window.__uamPainted = performance.now(); }, 0);
      return;
    }
    requestAnimationFrame(frame);
  };
  requestAnimationFrame(frame);
}"""


def _frame_time(page, click, cond: str) -> float:
    """Seconds on the page's clock from the pointerdown of ``click()`` to the first frame painted after ``cond``
    (JS source of a function) held."""
    page.evaluate(_FRAME_WATCH_JS, ["pointerdown", cond])
    click()
    try:
        page.wait_for_function("() => window.__uamPainted !== null", timeout=30_000)
    except Exception as err:
        raise RuntimeError(f"not seen: {cond}; texts {page.evaluate('() => window.__uamTexts')}, action at "
                           f"{page.evaluate('() => window.__uamKey')}") from err
    return float(page.evaluate("() => (window.__uamPainted - window.__uamKey) / 1000"))


def _fly_controls(page, n: int) -> dict[str, list[float]]:
    """The Fly tab's controls, each timed on the page's clock (pointerdown to the first frame painted after the
    page holds the result, as the bare page's steps are timed): 'Fly the mission' (a new world seed each round)
    until its busy mark shows
    ("flying..." in the status) and until the status says "flying:" after it (the new flight's first frame),
    'Inject wind change now' until the change is marked on the voltage figure (early in the flight, and again past
    half of it, where the flight until the change is flown again first), 'Clear wind changes' until it is gone."""
    out: dict[str, list[float]] = {"fly (until the busy mark)": [], "fly (until 'flying:', the first frame)": [],
                                   "inject a wind change": [], "clear it": [], "inject a wind change mid-flight": []}
    page.locator(".bk-tab", has_text="Fly").click()
    status = page.locator(".uam-fly-status")
    status.wait_for(state="attached", timeout=120_000)
    page.wait_for_function(_FLY_STATUS_JS, timeout=120_000)
    busy = "() => window.__uamTexts.some(t => t.includes('flying...'))"
    busy_then_flying = ("() => { const t = window.__uamTexts, i = t.findIndex(x => x.includes('flying...'));"
                        " return i >= 0 && t.slice(i + 1).some(x => x.includes('flying:')); }")

    def button(text: str):
        return lambda: page.locator("button", has_text=text).click()

    seed = page.locator(".bk-input-group", has_text="World seed").locator("input")
    speed = page.locator(".bk-input-group", has_text="Playback speed").locator("select")
    past_half = ("() => { const t = window.__uamTexts,"
                 " m = t.length ? /flying: ([0-9.]+) of ([0-9.]+)/.exec(t[t.length - 1]) : null;"
                 " return m !== null && +m[1] >= +m[2] / 2; }")
    for k in range(n):
        seed.fill(str(1000 + k))  # a new world each time: no flight is asked for twice
        seed.press("Enter")
        page.wait_for_timeout(300)
        page.wait_for_function(_FLY_IDLE_JS, timeout=120_000)
        out["fly (until 'flying:', the first frame)"].append(_frame_time(page, button("Fly the mission"),
                                                                          busy_then_flying))
        out["inject a wind change"].append(
            _frame_time(page, button("Inject wind change now"), f"() => ({_FLY_CHANGES_JS})() === 1"))
        out["clear it"].append(
            _frame_time(page, button("Clear wind changes"), f"() => ({_FLY_CHANGES_JS})() === 0"))
        page.wait_for_function(_FLY_IDLE_JS, timeout=120_000)
        out["fly (until the busy mark)"].append(_frame_time(page, button("Fly the mission"), busy))
        page.wait_for_function(busy_then_flying, timeout=120_000)
        speed.select_option("1000")  # to half the flight quickly, then a wind change there
        page.wait_for_function(past_half, timeout=120_000)
        out["inject a wind change mid-flight"].append(
            _frame_time(page, button("Inject wind change now"), f"() => ({_FLY_CHANGES_JS})() === 1"))
        speed.select_option("100")
        _frame_time(page, button("Clear wind changes"), f"() => ({_FLY_CHANGES_JS})() === 0")
    return out


def _serve_bare(port: int):
    """The bare page (benchmarks/bare_page.py) served by ``panel serve`` in a subprocess."""
    import subprocess
    import sys
    import urllib.request

    script = Path(__file__).with_name("bare_page.py")
    proc = subprocess.Popen([sys.executable, "-m", "panel", "serve", str(script), "--port", str(port),
                             "--allow-websocket-origin", f"127.0.0.1:{port}"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}/bare_page"
    for _ in range(300):
        try:
            urllib.request.urlopen(url, timeout=2).read()
            return proc, url
        except OSError:
            time.sleep(0.2)
    proc.kill()
    raise RuntimeError("the bare page did not start")


def bench_steps(per_slider: int, compare: str | None = None, flies: int = 4, planner: bool = True) -> list[str]:
    """Slider steps in the browser: the app's Planner (q_max, R0, EOD, wind home; half the steps one way, then
    back: new values first, then values seen; left out unless ``planner``) and the Fly tab's controls (``flies``
    rounds of :func:`_fly_controls`) against a bare Panel page of the same shape, in the same run.
    The first step after each page opens is included."""
    from playwright.sync_api import sync_playwright

    half = max(per_slider // 2, 1)
    pattern = ["ArrowRight"] * half + ["ArrowLeft"] * half
    sliders = ("q_max (C)", "R0 (ohm)", "EOD cut-off (V)", "Wind home (kt, - = tail)")
    lines = [f"steps (browser, key -> finished result painted; {len(pattern)} per slider; comparison "
             f"{compare or 'default'}): load average {_load()}"]
    proc, bare_url = _serve_bare(5899)
    try:
        with Served(**({"UAM_STUDIO_COMPARE": compare} if compare else {})) as srv, sync_playwright() as p:
            browser = _browser(p)
            page = browser.new_page(viewport={"width": 1366, "height": 768})
            page.goto(bare_url)
            page.locator(".uam-plan-summary").wait_for(timeout=60_000)
            bare = [t for _ in sliders for t in _slider_steps(page, "R0 (ohm)", pattern)]
            page = browser.new_page(viewport={"width": 1366, "height": 768})
            page.goto(srv.url)
            _first_plan(page)
            app: dict[str, list[float]] = {}
            if planner:
                app = {name: _slider_steps(page, name, pattern) for name in sliders}
                clicks, winds, drags = _edits(page, 5)
                page.locator("button", has_text="Reset to the example").click()  # the Fly tab flies the example
                page.locator(".uam-plan-summary[data-busy='false']:not([data-inputs*='|D1:'])").wait_for(
                    timeout=120_000)
            fly = _fly_controls(page, flies)
            browser.close()
    finally:
        proc.kill()
    def q(x: list[float], p: float) -> float:
        return float(np.percentile(np.array(x) * 1000.0, p))

    lines.append(f"  bare page: p50 {q(bare, 50):.0f} ms, p95 {q(bare, 95):.0f} ms, max {max(bare) * 1000:.0f} ms "
                 f"(n={len(bare)})")
    if planner:
        lines += _planner_lines(app, clicks, winds, drags, q(bare, 95), max(bare))
    for name, ts in fly.items():
        goal = "goal <= 2" if "first frame" in name or "inject" in name else "no goal"
        lines.append(f"  app, Fly tab, {name}: p50 {q(ts, 50):.0f} ms, p95 {q(ts, 95):.0f} ms; p95 / bare p95 "
                     f"{q(ts, 95) / q(bare, 95):.2f} ({goal}); each: {', '.join(f'{t * 1000:.0f}' for t in ts)} ms")
    return lines


def _planner_lines(app: dict[str, list[float]], clicks: list[float], winds: list[float], drags: list[float],
                   bare_p95_ms: float, bare_max: float) -> list[str]:
    """bench_steps' lines on the Planner: each slider, all its steps, map clicks, table edits, quick drags."""
    every = [t for ts in app.values() for t in ts]

    def q(x: list[float], p: float) -> float:
        return float(np.percentile(np.array(x) * 1000.0, p))

    lines = []
    for name, ts in app.items():
        lines.append(f"  app, {name}: p50 {q(ts, 50):.0f} ms, p95 {q(ts, 95):.0f} ms, max {max(ts) * 1000:.0f} ms; "
                     f"each: {', '.join(f'{t * 1000:.0f}' for t in ts)}")
    lines.append(f"  app, all {len(every)}: p50 {q(every, 50):.0f} ms, p95 {q(every, 95):.0f} ms, max "
                 f"{max(every) * 1000:.0f} ms; p95 / bare p95 {q(every, 95) / bare_p95_ms:.2f} (goal <= 2), max / "
                 f"bare max {max(every) / bare_max:.2f} (goal <= 3)")
    for name, ts in (("map click (a destination added)", clicks), ("table edit (its wind)", winds)):
        lines.append(f"  app, {name}: p50 {q(ts, 50):.0f} ms, p95 {q(ts, 95):.0f} ms, max {max(ts) * 1000:.0f} ms; "
                     f"p95 / bare p95 {q(ts, 95) / bare_p95_ms:.2f} (goal <= 3)")
    lines.append(f"  app, quick drag of 10 q_max steps, last key -> last value's plan: "
                 f"{', '.join(f'{t * 1000:.0f}' for t in drags)} ms; max / bare p95 "
                 f"{max(drags) * 1000 / bare_p95_ms:.2f} (goal <= 3)")
    return lines


def bench_concurrency(k: int, steps: int, runner: str) -> list[str]:
    from playwright.sync_api import sync_playwright

    js_len = """() => { for (const v of window.Bokeh.index.all_views()) { const m = v.model;
      if (m.title && m.title.text && m.title.text.startsWith('Destinations reached'))
        for (const r of m.renderers) if (r.glyph && r.glyph.type === 'Line') return r.data_source.get_length();
      } return -1; }"""
    lines = [f"concurrency (training in a {runner}): load average before {_load()}"]
    with Served(UAM_STUDIO_RETRAIN_RUNNER=runner) as srv, sync_playwright() as p:
        browser = _browser(p)
        a = browser.new_page(viewport={"width": 1500, "height": 1100})
        b = browser.new_page(viewport={"width": 1500, "height": 1100})
        for page in (a, b):
            page.goto(srv.url)
            _first_plan(page)
        policy = b.locator(".uam-plan-summary").get_attribute("data-inputs").split(";")[0]
        _replan_times(b, 2)  # warm
        idle = _replan_times(b, k)[0]
        a.locator(".bk-tab", has_text="Retrain").click()
        box = a.locator(".bk-input-group", has=a.get_by_text("Steps (environment transitions)")).locator("input")
        box.fill(str(steps))
        box.press("Enter")
        a.locator(".uam-train-start button").click()
        a.wait_for_function(f"() => ({js_len})() > 0", timeout=120_000)
        n0 = a.evaluate(js_len)
        busy = _replan_times(b, k)[0]
        n1 = a.evaluate(js_len)
        a.locator(".uam-train-stop button").click()
        browser.close()
    r50 = statistics.median(busy) / statistics.median(idle)
    r95 = percentile_ms(busy, 95) / percentile_ms(idle, 95)
    lines.append(f"  session B ({policy}) replan, idle:            {_stats(idle)}")
    lines.append(f"  session B ({policy}) replan, A retraining:    {_stats(busy)}; A's curve grew "
                 f"{n0} -> {n1} episodes meanwhile")
    lines.append(f"  RATIO training/idle: median {r50:.2f}x, p95 {r95:.2f}x (goal <= 2x)")
    lines.append(f"  load average after {_load()}")
    return lines


# ----------------------------------------------------------------------------- Fly playback tick


def bench_flytick(n: int) -> list[str]:
    from bokeh.document import Document

    from uam_studio.app.fly.state import FlyState
    from uam_studio.app.fly.view import TICK_MS, FlyView
    from uam_studio.app.session import configure_server_threads
    from uam_studio.planning import load_mission

    configure_server_threads()
    mission = load_mission(Path(__file__).resolve().parents[1] / "assets" / "example_mission.json")

    def ticks(with_view: bool) -> list[float]:
        state = FlyState(lambda: mission, speed=10)
        if with_view:
            FlyView(state).__panel__().get_root(Document())
        state.fly()
        state.speed = 10
        out = []
        for _ in range(n):
            t0 = time.perf_counter()
            state.tick(TICK_MS / 1000.0)
            out.append(time.perf_counter() - t0)
        return out

    view, bare = ticks(True), ticks(False)
    ratio = statistics.median(view) / max(statistics.median(bare), 1e-9)
    return ["Fly tab playback tick (example mission, x10, 0.25 s ticks)",
            f"  view + state: {_stats(view)}", f"  state alone (reference): {_stats(bare)}",
            f"  RATIO view+state/state: median {ratio:.1f}x; a tick's share of its {TICK_MS} ms period: "
            f"median {100 * statistics.median(view) / (TICK_MS / 1000.0):.1f}%"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("what", choices=["latency", "pageload", "replan", "lab", "concurrency", "flytick", "steps", "fly",
                                    "all"],
                    nargs="?", default="all")
    ap.add_argument("--n", type=int, default=40, help="slider changes per policy (latency)")
    ap.add_argument("--flies", type=int, default=4, help="rounds of the Fly tab's controls (steps, fly)")
    ap.add_argument("--n-oracle", type=int, default=8, help="slider changes for the oracle (seconds each)")
    ap.add_argument("--loads", type=int, default=5, help="page loads (pageload)")
    ap.add_argument("--k", type=int, default=15, help="replans per phase (replan, concurrency) or changes (lab)")
    ap.add_argument("--compare", default="off,process",
                    help="planner comparison modes to measure with (latency, pageload, replan)")
    ap.add_argument("--pause", type=float, default=1.0, help="seconds between slider moves (replan)")
    ap.add_argument("--steps", type=int, default=200_000, help="training steps of session A (concurrency)")
    ap.add_argument("--runners", default="process,thread",
                    help="where session A trains: the app's default child process, and/or a thread (concurrency)")
    ap.add_argument("--append", default=None, metavar="FILE", help="append the results as a section to FILE")
    args = ap.parse_args()
    lines: list[str] = []
    compares = args.compare.split(",")
    if args.what in ("latency", "all"):
        lines += bench_latency(args.n, args.n_oracle, compares)
    if args.what == "steps":
        for compare in (None, *compares):
            lines += bench_steps(10, compare, args.flies)
    elif args.what == "fly":
        lines += bench_steps(10, flies=args.flies, planner=False)
    elif args.what == "all":
        lines += bench_steps(10)
    if args.what in ("pageload", "all"):
        lines += bench_pageload(args.loads, compares)
    if args.what in ("replan", "all"):
        lines += bench_replan(args.k, compares, args.pause)
    if args.what in ("lab", "all"):
        lines += bench_lab(args.k)
    if args.what in ("concurrency", "all"):
        for runner in args.runners.split(","):
            lines += bench_concurrency(args.k, args.steps, runner)
    if args.what in ("flytick", "all"):
        lines += bench_flytick(args.n)
    print("\n".join(lines))
    if args.append:
        cmd = "python benchmarks/bench_app.py " + " ".join(sys.argv[1:])
        day = datetime.date.today().isoformat()
        block = "\n".join("    " + s for s in lines)
        with open(args.append, "a") as f:
            f.write(f"\n## App (`{cmd}`)\n\nMeasured {day}, {os.cpu_count()} CPU cores:\n\n{block}\n")


if __name__ == "__main__":
    main()
