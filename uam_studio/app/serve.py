"""Serve the app from Python: :func:`serve` (used by ``uam-studio serve``; :func:`warm_up` prepares
the process for the first session) and :class:`ServedApp` (the same server in a subprocess, for the
browser tests and benchmarks).

The server answers only requests addressed to it by a name in its allow-list
(:mod:`uam_studio.app.host_guard`). With several app processes (``num_procs``), a front process holds the
port and routes each page's websocket to the process that built the page (:mod:`uam_studio.app.front`).
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
import urllib.request
import webbrowser
from collections.abc import Sequence
from multiprocessing import util as mp_util
from pathlib import Path
from typing import Any

from uam_studio.app.host_guard import allowed_hosts, install_host_guard, split_host

__all__ = ["DEFAULT_ADDRESS", "DEFAULT_PORT", "ServedApp", "allowed_hosts", "check_can_listen", "child_pids",
           "free_loopback_port", "serve", "serve_app", "serve_front", "split_host", "warm_up"]

log = logging.getLogger(__name__)

DEFAULT_PORT = 5006
DEFAULT_ADDRESS = "127.0.0.1"


def quiet_closed_connections(loop: Any, context: dict[str, Any]) -> None:
    """The server loop's asyncio exception handler: a page that closed while messages were on their way
    (tornado's ``WebSocketClosedError`` / ``StreamClosedError`` in a task nobody awaited) is one log
    line, not a "Task exception was never retrieved" traceback; anything else goes to asyncio's
    default handler."""
    from tornado.iostream import StreamClosedError
    from tornado.websocket import WebSocketClosedError

    exc = context.get("exception")
    if isinstance(exc, (WebSocketClosedError, StreamClosedError)):
        logging.getLogger("uam_studio.serve").info("a page closed with messages on their way (%s)",
                                                   type(exc).__name__)
        return
    loop.default_exception_handler(context)


class OneLineRefusedWebsockets(logging.Filter):
    """For tornado's ``tornado.application`` log: a websocket that Bokeh refuses (no ``bokeh`` subprotocol,
    no token, a bad signature, an expired session: a page left open overnight) is one warning line naming
    the reason, not an "Uncaught exception" traceback."""

    def filter(self, record: logging.LogRecord) -> bool:
        from bokeh.protocol.exceptions import ProtocolError

        exc = record.exc_info[1] if record.exc_info else None
        if isinstance(exc, ProtocolError):
            record.msg, record.args = "websocket refused: %s", (exc,)
            record.exc_info, record.exc_text = None, None
            record.levelno, record.levelname = logging.WARNING, "WARNING"
        return True


def serve(port: int = DEFAULT_PORT, show: bool = True, address: str | None = None,
          allow_origin: Sequence[str] = (), num_procs: int = 1) -> None:
    """Start a Panel server with the app at ``/`` and block until it is stopped (Ctrl-C or SIGTERM).

    It listens on ``address`` (default ``127.0.0.1``: this machine only) and answers only requests
    naming a host of :func:`allowed_hosts` (``allow_origin`` adds names); others get 403. ``/liveness``
    answers once the server is up; ``/liveness?endpoint=/`` builds the app once first.

    ``num_procs`` app processes (0: one per core). With more than one, a front process holds the port and
    routes each page's websocket to the process that built the page (:mod:`uam_studio.app.front`); the
    processes are forked after the models are loaded, so they share them.

    The port is bound first (:class:`OSError` if it cannot be, within a second: :func:`check_can_listen`
    runs before the app's imports; :class:`ValueError` for a bad ``allow_origin`` before that), then the
    Dynaformer and the health population are loaded in a background thread, so the first session does
    not wait for them.
    """
    address = address or DEFAULT_ADDRESS
    allowed_hosts(port, address, allow_origin)  # ValueError for a bad allow_origin, before binding
    # The page's JavaScript and CSS come from this server, so the app works with no network. Bokeh's and
    # Panel's resource settings left in the shell (BOKEH_RESOURCES=inline, PANEL_INLINE=1: the offline
    # notebooks' settings) would inline BokehJS (a 5 MB page) and send Panel's CSS to its CDN.
    for name in ("BOKEH_RESOURCES", "PANEL_INLINE"):
        os.environ.pop(name, None)
    check_can_listen(address, port)
    procs = num_procs if num_procs > 0 else (os.cpu_count() or 1)
    if procs > 1:
        serve_front(port, show, address, allow_origin, procs)
        return
    serve_app(port, show, address, hosts=None, allow_origin=allow_origin)


def serve_app(port: int, show: bool, address: str, hosts: Sequence[str] | None = None,
              allow_origin: Sequence[str] = ()) -> None:
    """One app process: a Panel server of the app on ``address``:``port`` until Ctrl-C or SIGTERM.

    :param hosts: the ``Host`` / ``Origin`` names it answers (an app process behind a front: the
        front's names); None: :func:`allowed_hosts` of its own port, address and ``allow_origin``.
    """
    import panel as pn

    from uam_studio.app.main import EXTENSIONS, TITLE, create_app
    from uam_studio.app.session import configure_server_threads

    configure_server_threads()
    pn.extension(*EXTENSIONS)
    server = pn.serve({"/": create_app}, port=port, address=address, show=show, title=TITLE, start=False,
                      threaded=False, liveness=True)
    install_host_guard(server, hosts if hosts is not None
                       else allowed_hosts(server.port, address, allow_origin))
    warm = threading.Thread(target=warm_up, daemon=True, name="uam-warm-up")
    warm.start()
    server.io_loop.asyncio_loop.set_exception_handler(quiet_closed_connections)
    logging.getLogger("tornado.application").addFilter(OneLineRefusedWebsockets())
    # SIGTERM (a service manager, ``kill``) stops the server as Ctrl-C does: panel's SIGINT handler ends the
    # loop, the sessions and the comparison process close (a plain SIGTERM left semaphores behind)
    signal.signal(signal.SIGTERM, _stop_once(signal.getsignal(signal.SIGINT)))
    try:
        server.start()
        server.io_loop.start()  # until Ctrl-C (panel's SIGINT handler stops the loop)
    finally:
        from uam_studio.app.planner.comparison import close_comparisons

        close_comparisons()  # no comparison process started again while this one exits
        warm.join()  # a daemon thread still inside torch at interpreter exit aborts the process


def _stop_once(stop: Any) -> Any:
    """A SIGTERM handler that calls ``stop`` (the SIGINT handler) and then ignores further SIGTERMs: a
    front that signals its app processes after their process group was signalled does not cut their
    shutdown short."""
    def on_term(signum: int, frame: Any) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        if callable(stop):
            stop(signum, frame)
        else:
            raise KeyboardInterrupt

    return on_term


def free_loopback_port() -> int:
    """A port free on 127.0.0.1 now (the system's choice; another program may take it before it is bound)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_listening(port: int, pid: int, timeout_s: float = 300.0) -> bool:
    """Wait until 127.0.0.1:``port`` accepts connections; False if process ``pid`` ended first or time ran out."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=1.0):
            return True
        done, _ = os.waitpid(pid, os.WNOHANG)
        if done:
            return False
        time.sleep(0.1)
    return False


def _stop(pids: Sequence[int], timeout_s: float = 20.0) -> None:
    """SIGTERM each app process, wait up to ``timeout_s`` for all of them, then SIGKILL the rest."""
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGTERM)
    deadline = time.monotonic() + timeout_s
    left = set(pids)
    while left and time.monotonic() < deadline:
        for pid in list(left):
            with contextlib.suppress(ChildProcessError):
                if os.waitpid(pid, os.WNOHANG)[0] == 0:
                    continue
            left.discard(pid)
        time.sleep(0.1)
    for pid in left:
        with contextlib.suppress(ProcessLookupError, ChildProcessError):
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)


def serve_front(port: int, show: bool, address: str, allow_origin: Sequence[str], n: int) -> None:
    """``n`` app processes behind a front on ``address``:``port`` (module docstring), until Ctrl-C or SIGTERM.

    Before forking, this process loads what every session reads (panel's extensions, the Dynaformer and
    the health population), so the app processes share those pages (copy on write) instead of loading
    them ``n`` times. Each app process then listens on a free loopback port and warms up as a single
    server does. The app processes share the front's comparison workers
    (:class:`~uam_studio.app.planner.comparison_pool.SharedComparisons`: one per four app processes) instead
    of one comparison process each. An app process that ends is logged and gets no new pages; when none is
    left, the front stops too.
    """
    import panel as pn
    from tornado.httpserver import HTTPServer
    from tornado.ioloop import IOLoop, PeriodicCallback
    from tornado.netutil import bind_sockets

    from uam_studio.app.front import MAX_MESSAGE_BYTES, AppProcesses, front_application
    from uam_studio.app.main import EXTENSIONS
    from uam_studio.app.planner.comparison import use_shared_workers
    from uam_studio.app.planner.comparison_pool import SharedComparisons
    from uam_studio.app.services import population
    from uam_studio.app.session import configure_server_threads

    configure_server_threads()
    pn.extension(*EXTENSIONS)
    population()  # the Dynaformer and the health population, loaded once before the fork
    sockets = bind_sockets(port, address)
    public_port = int(sockets[0].getsockname()[1])
    allowed = allowed_hosts(public_port, address, allow_origin)
    ports = [free_loopback_port() for _ in range(n)]
    comparisons = SharedComparisons(n)  # its pipes before the fork, its workers after
    pids: list[int] = []
    for slot, p in enumerate(ports):
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # an app process
            code = 0
            try:
                for s in sockets:
                    s.close()
                use_shared_workers(*comparisons.app_side(slot))
                serve_app(p, False, "127.0.0.1", hosts=allowed)
            except BaseException:  # noqa: BLE001 - reported, then this process ends with 1
                traceback.print_exc()
                code = 1
            finally:
                # as multiprocessing's own forked children end: its finalizers of this process (the comparison
                # process's queues and semaphores) run; those the front made before the fork are skipped
                mp_util._exit_function()  # type: ignore[attr-defined]
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(code)
        pids.append(pid)
    comparisons.front_side()
    try:
        comparisons.start()
        procs = AppProcesses(ports)
        for k, (p, pid) in enumerate(zip(ports, pids)):
            if not _wait_listening(p, pid):
                procs.alive[k] = False
                log.error("app process %d (pid %d) did not start", k, pid)
        if not any(procs.alive):
            raise RuntimeError("no app process started (see the log above)")
        server = HTTPServer(front_application(procs, allowed), xheaders=False, max_body_size=MAX_MESSAGE_BYTES)
        server.add_sockets(sockets)
        loop = IOLoop.current()

        def check() -> None:
            for k, pid in enumerate(pids):
                if procs.alive[k]:
                    with contextlib.suppress(ChildProcessError):
                        done, status = os.waitpid(pid, os.WNOHANG)
                        if done:
                            procs.alive[k] = False
                            log.error("app process %d (pid %d) ended (status %d); it gets no new pages", k, pid,
                                      status)
            if not any(procs.alive):
                loop.stop()
            for w in comparisons.check():
                log.error("comparison worker %d ended; replaced", w)

        watch = PeriodicCallback(check, 1000)
        watch.start()
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, lambda *_: loop.add_callback_from_signal(loop.stop))
        url = f"http://{'localhost' if address in ('127.0.0.1', '0.0.0.0', '::') else address}:{public_port}/"
        print(f"uam-studio: {n} app processes behind {url} (pids {', '.join(map(str, pids))})", flush=True)
        if show:
            webbrowser.open(url)
        loop.start()
        watch.stop()
        server.stop()
    finally:
        _stop(pids)


def child_pids(pid: int) -> list[int]:
    """The processes ``pid`` started (Linux ``/proc``; empty elsewhere)."""
    out: list[int] = []
    with contextlib.suppress(OSError):
        for task in Path(f"/proc/{pid}/task").iterdir():
            out += [int(c) for c in (task / "children").read_text().split()]
    return out


def check_can_listen(address: str, port: int) -> None:
    """Bind, then release, each socket the server will listen on (``address``, ``port``; the options
    Tornado binds with): :class:`OSError` now, as the server's own bind would give it, instead of after
    the app's imports (seconds). Port 0 (any free port) is not checked."""
    if port == 0:
        return
    for family, kind, proto, _, sockaddr in socket.getaddrinfo(address, port, type=socket.SOCK_STREAM,
                                                               flags=socket.AI_PASSIVE):
        with socket.socket(family, kind, proto) as sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if family == socket.AF_INET6 and hasattr(socket, "IPPROTO_IPV6"):
                sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
            try:
                sock.bind(sockaddr)
            except OSError as err:  # as Tornado: a host without IPv6 still serves "localhost" on IPv4
                if not (err.errno == errno.EADDRNOTAVAIL and address == "localhost" and sockaddr[0] == "::1"):
                    raise


def warm_up(compare: str | None = None) -> None:
    """Load the compiled battery kernel (from numba's disk cache, compiling it if the cache is empty), the
    Dynaformer and the health population, and plan the example mission with the default policy, now
    (server start), so the first session shows its first plan at once. With a
    comparison runner (``compare``: default :func:`~uam_studio.app.planner.comparison.compare_mode` of a
    server), also start it and compare the example's planners, so the first session's comparison is
    ready too."""
    from uam_studio.app.planner.comparison import cached_row, compare_mode, comparison_runner
    from uam_studio.app.planner.mission import EXAMPLE_MISSION
    from uam_studio.app.planner.plans import PlanRequest, compute_plan
    from uam_studio.app.services import LEARNED_POLICIES, default_policy, population
    from uam_studio.battery import kernel
    from uam_studio.planning.missions.mission import mission_from_dict

    kernel.warm_up()
    population()
    mission = mission_from_dict(EXAMPLE_MISSION)
    policy = default_policy(mission.scenario)
    compute_plan(PlanRequest(mission, policy))
    mode = compare or compare_mode(True)
    if mode in ("process", "thread"):
        runner = comparison_runner(mode)
        runner.start()
        agent = policy if policy in LEARNED_POLICIES else "attention"
        todo = [PlanRequest(mission, p) for p in (agent, "greedy", "oracle")
                if cached_row(PlanRequest(mission, p)) is None]
        runner.submit("warm-up", [(r, lambda _row: None) for r in todo])


def _group_alive(pgid: int) -> bool:
    """Whether any process of the process group ``pgid`` is still alive (or not yet reaped)."""
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


class ServedApp:
    """``uam-studio serve --no-show`` in a subprocess on a free local port: how the browser tests and
    ``benchmarks/bench_app.py`` start the app the way users do.

    Use as a context manager; ``url`` is the app's page, ``log_path`` the server's output and
    ``startup_s`` the seconds from launch to the first answer of ``/liveness?endpoint=/`` (which
    builds the app once: imports, one app build).

    :param home: the user folder (``UAM_STUDIO_HOME``) for the server.
    :param timeout_s: how long to wait for the server (s); :class:`RuntimeError` with the log's tail after.
    """

    def __init__(self, home, timeout_s: float = 300.0, args: Sequence[str] = (), **env: str) -> None:
        self.home = Path(home)
        self.args = list(args)
        self.timeout_s = timeout_s
        self.extra_env = env
        self.log_path = self.home / "serve.log"

    def __enter__(self) -> ServedApp:
        self.port = free_loopback_port()
        self.home.mkdir(parents=True, exist_ok=True)
        self._log = open(self.log_path, "w")  # noqa: SIM115 - closed in __exit__
        env = {**os.environ, "UAM_STUDIO_HOME": str(self.home), **self.extra_env}
        root = Path(self.home)  # outside any checkout: the installed package is what runs
        t0 = time.perf_counter()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "uam_studio.cli", "serve", "--no-show", "--port", str(self.port), *self.args],
            cwd=root, env=env, stdout=self._log, stderr=subprocess.STDOUT,
            start_new_session=True)  # its own process group: ``--num-procs`` workers end with it
        deadline = time.monotonic() + self.timeout_s
        liveness = f"http://127.0.0.1:{self.port}/liveness?endpoint=/"
        while True:  # answers once the server is up and has built the app once
            try:
                with urllib.request.urlopen(liveness, timeout=60) as r:
                    if r.status == 200:
                        break
            except OSError:
                pass
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.__exit__()
                raise RuntimeError(f"uam-studio serve did not start: {self.log_path.read_text()[-2000:]}")
            time.sleep(0.25)
        self.startup_s = time.perf_counter() - t0
        self.url = f"http://127.0.0.1:{self.port}/"
        return self

    def __exit__(self, *exc) -> None:
        """Stop the server and every process it forked (its process group): SIGTERM, up to 20 s for
        all of them to end, then SIGKILL."""
        deadline = time.monotonic() + 20.0
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.proc.pid, signal.SIGTERM)
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(20.0)
        while _group_alive(self.proc.pid) and time.monotonic() < deadline:
            time.sleep(0.2)
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.proc.pid, signal.SIGKILL)
        self.proc.wait()
        self._log.close()
