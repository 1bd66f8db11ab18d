"""A class opening the app together (issue 40): N concurrent first loads of ``uam-studio serve``.

    OMP_NUM_THREADS=1 python benchmarks/bench_classroom.py [--sessions 1 30 60] [--hold 5] [--num-procs N]

One server (:class:`uam_studio.app.serve.ServedApp`: ``uam-studio serve --no-show`` in a subprocess, as a
teacher starts it). For each N, N clients start at once; each does what a browser's first load does to
the server: GET the page (the server builds the session's document), open the ``/ws`` websocket with
the page's token, wait for the server's ACK, ask for the document (PULL-DOC-REQ) and read the whole
reply, then tell the server the document is drawn (``document_ready``, as BokehJS does) and read what the
server sends after it: the parts the page defers (the Planner's table and lower plots) and later updates.
A first page's time runs from its GET to the reply's last frame; a complete load's to the last message
received before the server is idle again. Then, with all N connected (and ``--hold`` s after), the
server's memory is read (RSS, MB, summed over its processes; and PSS, in which a page the processes share
after the fork counts once), then they disconnect. Printed per N: p50 and p95 of the first pages' times
(s), the slowest, p95 of the complete loads, errors, RSS, PSS, the server's CPU seconds per session (all
its processes, from the first GET until idle) and the server log's Bokeh warnings per session. The
reference in the same run: N = 1, one load alone. Goals (issue 59, 2 cores): 30 sessions p95 <= 8 s, 60
sessions all served with p95 <= 16 s, RSS <= 1.5 GB with 30 open, no per-session warning.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import re
import tempfile
import time
import urllib.request
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tornado.httpclient import HTTPRequest
from tornado.websocket import websocket_connect

from uam_studio.app.serve import ServedApp, child_pids

TOKEN = re.compile(r'"token":\s*"([^"]+)"')


async def _read_message(conn) -> dict:
    """One Bokeh protocol message: header, metadata, content, then a header and a payload per buffer."""
    header = json.loads(await conn.read_message())
    await conn.read_message()  # metadata
    await conn.read_message()  # content
    for _ in range(2 * int(header.get("num_buffers", 0))):
        await conn.read_message()
    return header


async def first_load(url: str, pool: ThreadPoolExecutor, t0: float | None = None) -> tuple[float, object]:
    """(seconds, the open websocket) of one first load (module docstring); the GET runs in ``pool``;
    the seconds run from ``t0`` (``time.perf_counter()``; default: now)."""
    t0 = time.perf_counter() if t0 is None else t0
    loop = asyncio.get_running_loop()
    html = await loop.run_in_executor(pool, lambda: urllib.request.urlopen(url, timeout=600).read().decode())
    token = TOKEN.search(html)
    if token is None:
        raise RuntimeError("no session token in the page")
    ws_url = url.replace("http://", "ws://").rstrip("/") + "/ws"
    conn = await websocket_connect(HTTPRequest(ws_url, headers={"Origin": url.rstrip("/")}, connect_timeout=600,
                                               request_timeout=600),
                                   subprotocols=["bokeh", token.group(1)], max_message_size=1 << 30)
    ack = await _read_message(conn)
    if ack.get("msgtype") != "ACK":
        raise RuntimeError(f"expected ACK, got {ack.get('msgtype')}")
    await conn.write_message(json.dumps({"msgid": "1", "msgtype": "PULL-DOC-REQ"}))
    await conn.write_message("{}")
    await conn.write_message("{}")
    while True:
        reply = await _read_message(conn)
        if reply.get("msgtype") == "PULL-DOC-REPLY":
            break
    return time.perf_counter() - t0, conn


@dataclass
class Load:
    """One browser's load: its first page (:func:`first_load`), then what the page asks for once it is drawn.

    A browser tells the server its document is drawn (Bokeh's ``document_ready`` event); the server then
    builds what the page defers (Panel's ``defer_load``: the Planner's table and lower plots) and sends it,
    with any later update (the planners' comparison), as PATCH-DOC messages. :attr:`later` collects their
    arrival times (``time.perf_counter()``) until the websocket closes.
    """

    t0: float
    page_s: float
    conn: Any
    later: list[float] = field(default_factory=list)
    reader: asyncio.Task | None = None

    @property
    def complete_s(self) -> float:
        """Seconds from the GET to the last message the server sent (the page itself if none came after)."""
        return (max(self.later) - self.t0) if self.later else self.page_s


DOCUMENT_READY = json.dumps({"events": [{"kind": "MessageSent", "msg_type": "bokeh_event",
                                         "msg_data": {"type": "event", "name": "document_ready", "values": {}}}]})


async def _collect(load: Load) -> None:
    with contextlib.suppress(Exception):  # the websocket closed
        while True:
            header = await _read_message(load.conn)
            if header.get("msgtype") is None:
                return
            load.later.append(time.perf_counter())


async def full_load(url: str, pool: ThreadPoolExecutor) -> Load:
    """A browser's load (:class:`Load`): the first page, then ``document_ready``, and a task that reads
    everything the server sends after it."""
    t0 = time.perf_counter()
    page_s, conn = await first_load(url, pool, t0)
    load = Load(t0, page_s, conn)
    await conn.write_message(json.dumps({"msgid": "ready", "msgtype": "PATCH-DOC"}))
    await conn.write_message("{}")
    await conn.write_message(DOCUMENT_READY)
    load.reader = asyncio.create_task(_collect(load))
    return load


def tree_cpu_s(pid: int) -> float:
    """User + system CPU seconds so far of the process ``pid`` and its descendants (Linux ``/proc``)."""
    total = 0.0
    with contextlib.suppress(OSError):
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        total += (float(fields[11]) + float(fields[12])) / os.sysconf("SC_CLK_TCK")
    for child in child_pids(pid):
        total += tree_cpu_s(child)
    return total


async def settle(pid: int, quiet_s: float = 2.0, idle_cpu_s: float = 0.05, timeout_s: float = 900.0) -> float:
    """Wait until the server tree of ``pid`` is idle (under ``idle_cpu_s`` of CPU in ``quiet_s``); its CPU
    seconds then. Every deferred part and update of the pages just loaded has been built and sent."""
    deadline = time.monotonic() + timeout_s
    cpu = tree_cpu_s(pid)
    while time.monotonic() < deadline:
        await asyncio.sleep(quiet_s)
        now = tree_cpu_s(pid)
        if now - cpu < idle_cpu_s:
            return now
        cpu = now
    return cpu


def rss_mb(pid: int, field: str = "VmRSS:", file: str = "status") -> float:
    """Resident memory (MB) of the process and all its descendants (the server's forked processes), each
    process's whole RSS: pages shared after a fork count once per process."""
    total = 0.0
    for line in Path(f"/proc/{pid}/{file}").read_text().splitlines():
        if line.startswith(field):
            total += int(line.split()[1]) / 1024.0
    for child in child_pids(pid):
        try:
            total += rss_mb(child, field, file)
        except (OSError, ValueError):  # the child ended meanwhile
            pass
    return total


def pss_mb(pid: int) -> float:
    """Proportional memory (MB) of the process and its descendants: a page shared by k processes counts 1/k
    in each, so the sum is what the server tree holds."""
    return rss_mb(pid, "Pss:", "smaps_rollup")


async def run(url: str, n: int, pid: int, hold_s: float) -> dict:
    cpu0 = tree_cpu_s(pid)
    with ThreadPoolExecutor(max_workers=n) as pool:  # every GET at once, as N browsers send them
        results = await asyncio.gather(*(full_load(url, pool) for _ in range(n)), return_exceptions=True)
    loads = [r for r in results if isinstance(r, Load)]
    errors = [repr(r)[:120] for r in results if isinstance(r, BaseException)]
    cpu = await settle(pid)  # every page's deferred parts and updates built and sent
    await asyncio.sleep(hold_s)
    rss, pss = rss_mb(pid), pss_mb(pid)
    for load in loads:
        load.conn.close()
    await asyncio.gather(*(load.reader for load in loads if load.reader is not None))
    await asyncio.sleep(2.0)
    return {"n": n, "times": [ld.page_s for ld in loads], "complete": [ld.complete_s for ld in loads],
            "errors": errors, "rss_mb": rss, "pss_mb": pss, "cpu_per_session_s": (cpu - cpu0) / n}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sessions", type=int, nargs="+", default=[1, 30, 60])
    ap.add_argument("--hold", type=float, default=5.0, help="s with all sessions open before RSS is read")
    ap.add_argument("--num-procs", type=int, default=None, help="the server's --num-procs (default: its own)")
    args = ap.parse_args()
    serve_args = [] if args.num_procs is None else ["--num-procs", str(args.num_procs)]
    with tempfile.TemporaryDirectory() as home, ServedApp(Path(home), args=serve_args) as app:
        print(f"server up in {app.startup_s:.1f} s (liveness, one app build per app process); "
              f"RSS {rss_mb(app.proc.pid):.0f} MB (PSS {pss_mb(app.proc.pid):.0f} MB)")
        for n in args.sessions:
            before = app.log_path.read_text().count("W-1005")
            out = asyncio.run(run(app.url, n, app.proc.pid, args.hold))
            t = np.array(out["times"]) if out["times"] else np.array([np.nan])
            c = np.array(out["complete"]) if out["complete"] else np.array([np.nan])
            warnings = app.log_path.read_text().count("W-1005") - before
            print(f"{n:3d} sessions: first page p50 {np.percentile(t, 50):6.2f} s, p95 {np.percentile(t, 95):6.2f} s, "
                  f"max {np.max(t):6.2f} s; complete p95 {np.percentile(c, 95):6.2f} s; "
                  f"served {len(out['times'])}/{n}, errors {len(out['errors'])}, "
                  f"RSS {out['rss_mb']:.0f} MB (PSS {out['pss_mb']:.0f} MB), "
                  f"server CPU {out['cpu_per_session_s']:.3f} s/session, W-1005 warnings {warnings}", flush=True)
            for e in out["errors"][:3]:
                print("   ", e)


if __name__ == "__main__":
    main()
