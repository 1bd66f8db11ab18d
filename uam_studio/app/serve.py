"""Serve the app from Python: :func:`serve` (used by ``uam-studio serve``; :func:`warm_up` prepares
the process for the first session) and :class:`ServedApp` (the same server in a subprocess, for the
browser tests and benchmarks).

The server answers only requests addressed to it by a name in its allow-list (:func:`allowed_hosts`):
every request (page, static files, ``/ws`` websocket, ``/liveness``) whose ``Host`` header, or whose
``Origin`` header when it has one, is not in the list gets 403. A web page on another site therefore
cannot drive the app, not even through DNS rebinding (a name of its own that resolves to this machine).
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
import urllib.request
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from tornado.httputil import HTTPServerRequest
from tornado.routing import Matcher, Rule
from tornado.web import RequestHandler

DEFAULT_PORT = 5006
DEFAULT_ADDRESS = "127.0.0.1"
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")

log = logging.getLogger(__name__)


def split_host(value: str) -> tuple[str, int | None]:
    """``HOST[:PORT]`` (an IPv6 address in brackets: ``[::1]:5006``) as ``(host, port or None)``, the
    host in lower case. :class:`ValueError` if it is not of that form (a URL, an empty host, a bad port).
    """
    text = value.strip().lower()
    if "/" in text or "@" in text or not text:
        raise ValueError(f"{value!r} is not HOST[:PORT]")
    if text.startswith("["):
        end = text.find("]")
        host, rest = text[:end + 1], text[end + 1:]
        if end < 2:
            raise ValueError(f"{value!r} is not HOST[:PORT]")
    else:
        host, sep, port = text.partition(":")
        rest = sep + port
        if ":" in port:
            raise ValueError(f"{value!r} is not HOST[:PORT] (write an IPv6 address in brackets: [::1]:5006)")
    if not host:
        raise ValueError(f"{value!r} has no host")
    if not rest:
        return host, None
    if not rest.startswith(":") or not rest[1:].isdigit() or not 0 < int(rest[1:]) <= 65535:
        raise ValueError(f"{value!r} has no valid port; allowed [1, 65535]")
    return host, int(rest[1:])


def _host_literal(address: str) -> str:
    """``address`` as it appears in a Host header: an IPv6 address in brackets."""
    return f"[{address}]" if ":" in address and not address.startswith("[") else address


def allowed_hosts(port: int, address: str | None = None, allow_origin: Iterable[str] = ()) -> list[str]:
    """The ``host:port`` values that requests to the server may name in ``Host`` and ``Origin``.

    Always the loopback names (``127.0.0.1``, ``localhost``, ``[::1]``) on ``port``; the listening
    ``address`` if one is given; and each ``HOST[:PORT]`` of ``allow_origin`` (``port`` when it has none).
    """
    hosts = [f"{name}:{port}" for name in LOOPBACK_NAMES]
    extra = [f"{_host_literal(address)}:{port}"] if address else []
    for value in allow_origin:
        host, host_port = split_host(value)
        extra.append(f"{host}:{host_port or port}")
    return hosts + [h for h in dict.fromkeys(h.lower() for h in extra) if h not in hosts]


class _ForeignRequest(Matcher):
    """Matches a request whose ``Host``, or ``Origin`` when present, is not in ``allowed``."""

    def __init__(self, allowed: Iterable[str]) -> None:
        self.allowed = frozenset(allowed)

    def _is_allowed(self, netloc: str, default_port: int) -> bool:
        try:
            host, port = split_host(netloc)
        except ValueError:
            return False
        return f"{host}:{port or default_port}" in self.allowed

    def match(self, request: HTTPServerRequest) -> dict[str, Any] | None:
        if not self._is_allowed(request.headers.get("Host", ""), 80):
            return {}
        origin = request.headers.get("Origin")
        if origin is not None:
            parts = urlsplit(origin)
            if parts.scheme not in ("http", "https") or not self._is_allowed(
                    parts.netloc, 443 if parts.scheme == "https" else 80):
                return {}
        return None


class _Forbidden(RequestHandler):
    """Answers 403 with one line naming the allow-list, for every method (websocket upgrades too)."""

    def initialize(self, allowed: Sequence[str]) -> None:
        self.allowed = allowed

    def prepare(self) -> None:
        host, origin = self.request.headers.get("Host"), self.request.headers.get("Origin")
        log.warning("refused %s %s: Host %r, Origin %r not in %s", self.request.method, self.request.path,
                    host, origin, ", ".join(self.allowed))
        self.set_status(403)
        self.set_header("Content-Type", "text/plain; charset=utf-8")
        self.finish(f"403 Forbidden: this server answers only to {', '.join(self.allowed)} "
                    "(uam-studio serve --allow-origin HOST[:PORT] adds a name)\n")


def install_host_guard(server: Any, allowed: Sequence[str]) -> None:
    """Make the bokeh ``server`` answer 403 to every request whose ``Host``, or ``Origin`` when present,
    is not in ``allowed``: a route ahead of all others in its tornado Application. Its own websocket
    Origin check gets the same list."""
    app = server._tornado  # bokeh's Server keeps its tornado Application there (panel reads it too)
    app.default_router.rules.insert(0, Rule(_ForeignRequest(allowed), _Forbidden, {"allowed": list(allowed)}))
    app.websocket_origins.clear()  # the live set bokeh's /ws handler checks Origin against
    app.websocket_origins.update(allowed)


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

    The port is bound first (:class:`OSError` if it cannot be, within a second: :func:`check_can_listen`
    runs before the app's imports; :class:`ValueError` for a bad ``allow_origin`` before that), then the
    Dynaformer and the health population are loaded in a background thread, so the first session does
    not wait for them.
    """
    address = address or DEFAULT_ADDRESS
    allowed_hosts(port, address, allow_origin)  # ValueError for a bad allow_origin, before binding
    check_can_listen(address, port)

    import panel as pn

    from uam_studio.app.main import EXTENSIONS, TITLE, create_app
    from uam_studio.app.session import configure_server_threads

    configure_server_threads()
    pn.extension(*EXTENSIONS)
    if num_procs != 1:  # this process forks the workers (in pn.serve) and then only waits for them
        signal.signal(signal.SIGTERM, _forward_to_workers)
    server = pn.serve({"/": create_app}, port=port, address=address, show=show, title=TITLE, start=False,
                      threaded=False, liveness=True, num_procs=num_procs)
    install_host_guard(server, allowed_hosts(server.port, address, allow_origin))
    warm = threading.Thread(target=warm_up, daemon=True, name="uam-warm-up")
    warm.start()
    server.io_loop.asyncio_loop.set_exception_handler(quiet_closed_connections)
    logging.getLogger("tornado.application").addFilter(OneLineRefusedWebsockets())
    # SIGTERM (a service manager, ``kill``) stops the server as Ctrl-C does: panel's SIGINT handler ends the
    # loop, the sessions and the comparison process close (a plain SIGTERM left semaphores behind)
    signal.signal(signal.SIGTERM, signal.getsignal(signal.SIGINT))
    try:
        server.start()
        server.io_loop.start()  # until Ctrl-C (panel's SIGINT handler stops the loop)
    finally:
        from uam_studio.app.planner.comparison import close_comparisons

        close_comparisons()  # no comparison process started again while this one exits
        warm.join()  # a daemon thread still inside torch at interpreter exit aborts the process


def child_pids(pid: int) -> list[int]:
    """The processes ``pid`` started (Linux ``/proc``; empty elsewhere)."""
    out: list[int] = []
    with contextlib.suppress(OSError):
        for task in Path(f"/proc/{pid}/task").iterdir():
            out += [int(c) for c in (task / "children").read_text().split()]
    return out


def _forward_to_workers(signum: int, frame: Any) -> None:
    """SIGTERM in the process that forked ``--num-procs`` workers: pass it on to each. They stop as on
    Ctrl-C and exit 0, and Tornado's forking process then exits 0 (a worker that fails is restarted)."""
    for pid in child_pids(os.getpid()):
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGTERM)


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
    """Load the Dynaformer and the health population, and plan the example mission with the default
    policy, now (server start), so the first session shows its first plan at once. With a
    comparison runner (``compare``: default :func:`~uam_studio.app.planner.comparison.compare_mode` of a
    server), also start it and compare the example's planners, so the first session's comparison is
    ready too."""
    from uam_studio.app.planner.comparison import cached_row, compare_mode, comparison_runner
    from uam_studio.app.planner.mission import EXAMPLE_MISSION
    from uam_studio.app.planner.plans import PlanRequest, compute_plan
    from uam_studio.app.services import LEARNED_POLICIES, default_policy, population
    from uam_studio.planning.missions.mission import mission_from_dict

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
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
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
