"""A session's document is built once, also when ``uam-studio serve --num-procs`` runs several processes
behind its front (uam_studio/app/front.py).

Each first load does what a browser does to the server (benchmarks/bench_classroom.py's client: GET the
page, open its websocket with the page's token, pull the document), or is a real page in Chromium. A hook
loaded into the server's processes (tests/server_hooks/sitecustomize.py) logs every document the app
builds with its process and session id.
"""

from __future__ import annotations

import asyncio
import collections
import shutil
import sys
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from uam_studio.app.front import AppProcesses, session_of_token
from uam_studio.app.serve import ServedApp

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "benchmarks"))
from bench_classroom import first_load  # noqa: E402

LOADS = 4


def _built(log: Path, skip: int) -> dict[str, list[str]]:
    """Session id -> the processes that built its document, from the hook's log after its first ``skip`` lines."""
    built = collections.defaultdict(list)
    for line in log.read_text().splitlines()[skip:]:
        pid, session = line.split()
        built[session].append(pid)
    return dict(built)


def _serve(home: Path, num_procs: int) -> ServedApp:
    """``uam-studio serve --num-procs N`` with the build-logging hook; its log is ``home / "builds.log"``."""
    return ServedApp(home, args=["--num-procs", str(num_procs)], PYTHONPATH=str(HERE / "server_hooks"),
                     UAM_TEST_BUILD_LOG=str(home / "builds.log"))


def _lines(log: Path) -> int:
    return len(log.read_text().splitlines()) if log.exists() else 0


@pytest.fixture(scope="module")
def two_procs(tmp_path_factory) -> Iterator[ServedApp]:
    """One ``--num-procs 2`` server for this module's tests of it, in file order: first loads, pages in
    Chromium, then one app process killed (the last, as it ends a process). Each reads the log past the
    lines written before it."""
    with _serve(tmp_path_factory.mktemp("two_procs"), 2) as app:
        yield app


def _builds(app: ServedApp) -> dict[str, list[str]]:
    """Session id -> the processes that built its document, over :data:`LOADS` first loads of ``app``."""
    log = app.home / "builds.log"
    warm = _lines(log)  # the liveness checks' builds, and the earlier tests' on a shared server

    async def loads() -> None:
        with ThreadPoolExecutor(2) as pool:
            for _ in range(LOADS):
                _, conn = await first_load(app.url, pool)
                conn.close()

    with ThreadPoolExecutor(1) as runner:  # its own event loop: another test may leave one running here
        runner.submit(asyncio.run, loads()).result()
    return _built(log, warm)


def test_each_session_is_built_once_by_one_process(tmp_path):
    with _serve(tmp_path, 1) as app:
        built = _builds(app)
    assert len(built) == LOADS, built
    assert all(len(pids) == 1 for pids in built.values()), built


def test_each_session_is_built_once_behind_the_front(two_procs):
    built = _builds(two_procs)
    assert len(built) == LOADS, built
    assert all(len(pids) == 1 for pids in built.values()), built
    # behind the front, the pages go to the app processes in turn
    assert len({pids[0] for pids in built.values()}) == 2, built


def test_the_front_remembers_which_process_built_a_session_and_skips_an_ended_one():
    procs = AppProcesses([7001, 7002, 7003])
    assert [procs.next() for _ in range(4)] == [0, 1, 2, 0]
    # files have a turn of their own: a page's files never decide where the next page goes
    assert [procs.next("file") for _ in range(2)] == [0, 1] and procs.next() == 1
    procs.remember("abc", 2)
    assert procs.of_session("abc") == 2 and procs.of_session("xyz") is None and procs.of_session(None) is None
    procs.alive[1] = False
    assert [procs.next() for _ in range(4)] == [2, 0, 2, 0]
    assert procs.sessions_per_process() == [0, 0, 1]
    with pytest.raises(ValueError):
        AppProcesses([])


def test_a_session_token_names_its_session_and_anything_else_names_none():
    from bokeh.util.token import generate_jwt_token

    token = generate_jwt_token("session-123", signed=False)
    assert session_of_token(token) == "session-123" and session_of_token(token.encode()) == "session-123"
    for junk in (None, "", "not a token", "e30", b"\xff\xfe"):
        assert session_of_token(junk) is None


CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"


@pytest.mark.skipif(not Path(CHROMIUM).exists(), reason="chromium is not installed")
def test_pages_behind_a_two_process_front_are_built_once_and_draw_styled(two_procs):
    """Three pages in Chromium through ``--num-procs 2``: each session is built once, in the process the front
    sent its page to (both processes serve pages), every request stays on the server, and each page draws its
    plan, its destinations table and its voltage figure."""
    pytest.importorskip("playwright")
    from drawn import PLANNER_VOLTAGE, assert_drawn
    from playwright.sync_api import sync_playwright

    def pages(url: str) -> None:  # Playwright's sync API in a thread of its own: no event loop running there
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=CHROMIUM)
            try:
                for _ in range(3):
                    page = browser.new_page(viewport={"width": 1500, "height": 1100})
                    page.set_default_timeout(60_000)
                    outside: list[str] = []
                    page.on("request", lambda r, out=outside: out.append(r.url) if not r.url.startswith(
                        ("http://127.0.0.1", "ws://127.0.0.1", "data:", "blob:")) else None)
                    failed: list[str] = []
                    page.on("requestfailed", lambda r, out=failed: out.append(f"{r.url}: {r.failure}"))
                    page.goto(url)
                    page.locator(".uam-plan-summary").get_by_text("Route:").wait_for()
                    page.locator(".tabulator-row").first.wait_for()
                    assert_drawn(page, "Voltage: physics", PLANNER_VOLTAGE)
                    assert not outside and not failed, (outside, failed)
                    page.close()
            finally:
                browser.close()

    log = two_procs.home / "builds.log"
    warm = _lines(log)
    with ThreadPoolExecutor(1) as runner:
        runner.submit(pages, two_procs.url).result()
    built = _built(log, warm)
    assert len(built) == 3 and all(len(pids) == 1 for pids in built.values()), built
    assert len({pids[0] for pids in built.values()}) == 2, built


def test_the_front_keeps_serving_when_an_app_process_ends(two_procs):
    """One of two app processes is killed: the front notices within its check (1 s), logs it, and sends
    every new page to the process left; the front itself keeps running."""
    import os
    import signal
    import time

    from uam_studio.app.serve import child_pids

    def cmdline(pid: int) -> str:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()

    app = two_procs
    children = child_pids(app.proc.pid)
    workers = [pid for pid in children if "uam_studio.cli" in cmdline(pid)]
    assert len(workers) == 2, workers
    # the app processes share the front's one comparison worker and start no comparison process of
    # their own (each did before, at its warm-up)
    assert sum("multiprocessing.spawn" in cmdline(pid) for pid in children) == 1, children
    time.sleep(3.0)
    assert [pid for w in workers for pid in child_pids(w)] == []
    os.kill(workers[0], signal.SIGKILL)
    deadline = time.monotonic() + 10.0  # the front checks its processes every second
    while f"(pid {workers[0]}) ended" not in app.log_path.read_text() and time.monotonic() < deadline:
        time.sleep(0.1)

    async def loads() -> list[float]:
        out = []
        with ThreadPoolExecutor(2) as pool:
            for _ in range(3):
                seconds, conn = await first_load(app.url, pool)
                conn.close()
                out.append(seconds)
        return out

    with ThreadPoolExecutor(1) as runner:
        times = runner.submit(asyncio.run, loads()).result()
    assert app.proc.poll() is None
    assert len(times) == 3
    log = app.log_path.read_text()
    assert f"(pid {workers[0]}) ended" in log and "gets no new pages" in log, log[-2000:]
