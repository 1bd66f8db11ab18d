"""What a first load costs the server before any of the app's own work: two reference pages beside the app.

    OMP_NUM_THREADS=1 python benchmarks/bench_classroom_floor.py [--sessions 1 30]

Three servers, one after another, each loaded by :func:`bench_classroom.full_load` (the page GET, the
websocket, the whole document, then the browser's ``document_ready`` and everything the page defers), N
clients at once:

- ``bare``: ``panel serve`` of a page with one Markdown pane and one slider (Panel's own floor);
- ``figures``: ``panel serve`` of four Bokeh figures of five 100-point lines each with the usual six
  tools, and one slider (about the model count of the Planner's four plots);
- ``app``: ``uam-studio serve`` (:class:`uam_studio.app.serve.ServedApp`), the app as a class opens it.

Printed per server and N: p50 / p95 of the first page's load times (s), p95 of the complete loads (the
last deferred part or update received), and the server's CPU seconds per session (``/proc/PID/stat``,
user + system, of the server and its child processes, from the first GET until the server is idle again:
every deferred part built and sent). With every
page built on one event loop, p95 at N concurrent loads is about N x the CPU per session: a p95 of 5 s for 30
sessions needs <= ~0.17 s each.
"""

from __future__ import annotations

import argparse
import asyncio
import subprocess
import sys
import tempfile
import time
import urllib.request
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_classroom import Load, full_load, settle, tree_cpu_s  # noqa: E402

from uam_studio.app.serve import ServedApp  # noqa: E402

BARE = """import panel as pn
pn.Column(pn.pane.Markdown("# A page"),
          pn.widgets.FloatSlider(name="q_max (C)", start=5000, end=8000, value=7600)).servable()
"""
FIGURES = """import numpy as np, panel as pn
from bokeh.plotting import figure
def fig(i):
    f = figure(height=250, width=400, title=f"figure {i}", tools="pan,wheel_zoom,box_zoom,reset,save,hover")
    for k in range(5):
        f.line(np.arange(100), np.random.default_rng(k).random(100), legend_label=f"line {k}")
    return f
pn.Column(*[pn.pane.Bokeh(fig(i)) for i in range(4)], pn.widgets.FloatSlider(name="q", start=0, end=1)).servable()
"""


async def _loads(url: str, n: int, pid: int) -> tuple[list[Load], float]:
    """N loads at once; (the loads, the server's CPU seconds once it is idle again)."""
    with ThreadPoolExecutor(max_workers=n) as pool:
        loads = await asyncio.gather(*(full_load(url, pool) for _ in range(n)))
    cpu = await settle(pid)
    for load in loads:
        load.conn.close()
    await asyncio.gather(*(load.reader for load in loads if load.reader is not None))
    return loads, cpu


def measure(name: str, url: str, pid: int, sessions: list[int]) -> None:
    """Print one line per N for the server ``pid`` answering at ``url``."""
    for n in sessions:
        before = tree_cpu_s(pid)
        loads, cpu = asyncio.run(_loads(url, n, pid))
        times = np.array([ld.page_s for ld in loads])
        complete = np.array([ld.complete_s for ld in loads])
        per = (cpu - before) / n
        print(f"{name:8s} {n:3d} sessions: first page p50 {np.percentile(times, 50):6.2f} s, "
              f"p95 {np.percentile(times, 95):6.2f} s; complete p95 {np.percentile(complete, 95):6.2f} s; "
              f"server CPU {per:5.3f} s/session", flush=True)
        time.sleep(2.0)


def _panel_serve(script: Path, port: int) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-m", "panel", "serve", str(script), "--port", str(port)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://localhost:{port}/{script.stem}"
    deadline = time.monotonic() + 120
    while True:
        try:
            urllib.request.urlopen(url, timeout=30).read()
            return proc
        except OSError:
            if time.monotonic() > deadline or proc.poll() is not None:
                proc.kill()
                raise RuntimeError(f"panel serve {script.name} did not start") from None
            time.sleep(0.5)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sessions", type=int, nargs="+", default=[1, 30])
    ap.add_argument("--port", type=int, default=5391, help="first of the two ports the reference pages use")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for i, (name, source) in enumerate((("bare", BARE), ("figures", FIGURES))):
            script = Path(tmp) / f"{name}.py"
            script.write_text(source)
            proc = _panel_serve(script, args.port + i)
            try:
                measure(name, f"http://localhost:{args.port + i}/{name}", proc.pid, args.sessions)
            finally:
                proc.terminate()
                proc.wait(30)
        with ServedApp(Path(tmp) / "home") as app:
            time.sleep(5.0)  # the warm-up's plans and comparisons
            measure("app", app.url, app.proc.pid, args.sessions)


if __name__ == "__main__":
    main()
