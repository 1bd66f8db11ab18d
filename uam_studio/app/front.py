"""The front of a server with several app processes (``uam-studio serve --num-procs N``, N > 1).

Bokeh keeps a session's document in the process that built it, and a page's websocket must reach that
process: a process that gets a websocket for a session it did not build builds the document again
(``tests/test_server_sessions.py``). So the public port belongs to one front process, which does not
build documents, and each app process listens on a loopback port of its own. The front routes:

- a page (any ``GET`` that answers HTML with a session token) to the next app process in turn (round
  robin), and remembers which process built that session;
- a websocket (``/ws``: the page's token rides in its ``Sec-WebSocket-Protocol`` header) to the process
  that built the token's session (any process for a token it never saw), and relays its messages both
  ways unchanged;
- everything else (static files, the same in every process) to the next process in turn, with a turn
  of its own: however many files a page asks for, the next page still goes to the next process;
- ``/liveness``: answered 200 only when every app process answers its own ``/liveness`` (with the same
  query, so ``?endpoint=/`` builds the app once in each).

The front applies the same host guard as a single server (:mod:`uam_studio.app.host_guard`)
before any routing; requests go on to the app processes with their ``Host`` and ``Origin`` unchanged,
and the app processes allow the front's names.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import re
from collections import OrderedDict
from collections.abc import Sequence
from typing import Any

from tornado import httpclient, httputil, web, websocket
from tornado.routing import Matcher, PathMatches, Rule

from uam_studio.app.host_guard import host_guard_rule

log = logging.getLogger(__name__)

TOKEN = re.compile(rb'"token":\s*"([^"]+)"')
MAX_MESSAGE_BYTES = 1 << 28  # a websocket message (B) relayed either way; Bokeh's own default is 20 MiB
REMEMBERED_SESSIONS = 100_000  # session ids whose process the front keeps (oldest forgotten first)
FILE_PATHS = ("/static/", "/favicon.ico")  # requests that never build a document: their own turn
HOP_BY_HOP = frozenset({"connection", "keep-alive", "proxy-authenticate", "proxy-authorization", "te", "trailer",
                        "trailers", "transfer-encoding", "upgrade", "content-length", "accept-encoding"})
WEBSOCKET_OWN = frozenset({"sec-websocket-key", "sec-websocket-version", "sec-websocket-extensions",
                           "sec-websocket-protocol"})
TIMEOUT_S = 600.0  # s, a request relayed to an app process (a first page under a class's load)


class AppProcesses:
    """The app processes behind a front: their loopback ports, whether each is alive, and which process
    built each session the front has seen.

    :param ports: each app process's port on 127.0.0.1.
    """

    def __init__(self, ports: Sequence[int]) -> None:
        if not ports:
            raise ValueError("a front needs at least one app process")
        self.ports = list(ports)
        self.alive = [True] * len(self.ports)
        self._turns = {kind: itertools.cycle(range(len(self.ports))) for kind in ("page", "file")}
        self._sessions: OrderedDict[str, int] = OrderedDict()

    def next(self, kind: str = "page") -> int:
        """The next live process in turn (round robin) for a ``"page"`` or a ``"file"`` (each kind has its
        own turn); the first one if none is alive (its request then fails with 502)."""
        turn = self._turns[kind]
        for _ in range(len(self.ports)):
            k = next(turn)
            if self.alive[k]:
                return k
        return 0

    def remember(self, session_id: str, k: int) -> None:
        """Session ``session_id`` was built by process ``k``."""
        self._sessions[session_id] = k
        self._sessions.move_to_end(session_id)
        while len(self._sessions) > REMEMBERED_SESSIONS:
            self._sessions.popitem(last=False)

    def of_session(self, session_id: str | None) -> int | None:
        """The process that built ``session_id``, or None if the front never saw it."""
        return None if session_id is None else self._sessions.get(session_id)

    def sessions_per_process(self) -> list[int]:
        """How many remembered sessions each process built."""
        counts = [0] * len(self.ports)
        for k in self._sessions.values():
            counts[k] += 1
        return counts


def session_of_token(token: str | bytes | None) -> str | None:
    """The session id a Bokeh session token names, or None if it is not a token."""
    if not token:
        return None
    from bokeh.util.token import get_session_id

    try:
        return str(get_session_id(token.decode() if isinstance(token, bytes) else token))
    except Exception:  # noqa: BLE001 - any malformed token: route as an unknown session
        return None


async def _fetch(request: httpclient.HTTPRequest) -> tuple[httpclient.HTTPResponse | None, BaseException | None]:
    """An app process's answer to ``request`` (any HTTP status), or ``(None, why)`` when nothing answered:
    a timeout (tornado's 599) or a refused connection (which tornado raises even with ``raise_error=False``)."""
    try:
        resp = await httpclient.AsyncHTTPClient().fetch(request, raise_error=False)
    except OSError as err:
        return None, err
    return (None, resp.error) if resp.code == 599 else (resp, None)


def _forwarded_headers(headers: httputil.HTTPHeaders, drop: frozenset[str] = frozenset()) -> httputil.HTTPHeaders:
    out = httputil.HTTPHeaders()
    for name, value in headers.get_all():
        if name.lower() not in HOP_BY_HOP and name.lower() not in drop:
            out.add(name, value)
    return out


class _WebSocketUpgrade(Matcher):
    """Matches a websocket upgrade request."""

    def match(self, request: httputil.HTTPServerRequest) -> dict[str, Any] | None:
        return {} if request.headers.get("Upgrade", "").lower() == "websocket" else None


class _HttpRelay(web.RequestHandler):
    """Relays a request to an app process (see the module docstring) and its answer back."""

    SUPPORTED_METHODS = ("GET", "HEAD", "POST")

    def initialize(self, procs: AppProcesses) -> None:
        self.procs = procs

    async def get(self, *_: Any) -> None:
        k = self.procs.next("file" if self.request.path.startswith(FILE_PATHS) else "page")
        url = f"http://127.0.0.1:{self.procs.ports[k]}{self.request.uri}"
        req = httpclient.HTTPRequest(url, method=self.request.method, headers=_forwarded_headers(self.request.headers),
                                     body=self.request.body if self.request.method == "POST" else None,
                                     follow_redirects=False, decompress_response=False,
                                     connect_timeout=TIMEOUT_S, request_timeout=TIMEOUT_S)
        resp, error = await _fetch(req)
        if resp is None:  # no answer at all: the process is gone or did not answer in time
            log.warning("app process %d (port %d) did not answer %s: %s", k, self.procs.ports[k], self.request.uri,
                        error)
            self.set_status(502)
            self.set_header("Content-Type", "text/plain; charset=utf-8")
            self.finish(f"502 Bad Gateway: app process {k} did not answer\n")
            return
        body = resp.body or b""
        if "html" in resp.headers.get("Content-Type", "") and (m := TOKEN.search(body)):
            session = session_of_token(m.group(1))
            if session is not None:
                self.procs.remember(session, k)
        self.clear()
        for name in ("Content-Type", "Server", "Date"):
            self.clear_header(name)
        self.set_status(resp.code, resp.reason)
        for name, value in resp.headers.get_all():
            if name.lower() not in HOP_BY_HOP:
                self.add_header(name, value)
        if body and self.request.method != "HEAD" and resp.code not in (204, 304):
            self.write(body)
        await self.finish()

    head = get
    post = get


class _WebSocketRelay(websocket.WebSocketHandler):
    """A page's websocket, relayed message by message to the app process that built its session."""

    def initialize(self, procs: AppProcesses) -> None:
        self.procs = procs
        self.upstream: websocket.WebSocketClientConnection | None = None
        self._pump: asyncio.Task | None = None  # the app process -> page relay (asyncio holds tasks weakly)
        self._closed = False

    def check_origin(self, origin: str) -> bool:
        return True  # the host guard has checked Host and Origin; the app process checks Origin again

    def select_subprotocol(self, subprotocols: list[str]) -> str | None:
        return subprotocols[0] if len(subprotocols) == 2 else None  # as Bokeh: "bokeh", then the token

    async def open(self, *_: Any) -> None:
        protocols = [p.strip() for p in self.request.headers.get("Sec-WebSocket-Protocol", "").split(",") if p.strip()]
        session = session_of_token(protocols[1]) if len(protocols) == 2 else None
        k = self.procs.of_session(session)
        if k is None:
            k = self.procs.next("file")
            if session is not None:
                log.info("websocket for session %s, which no page through this front built: app process %d",
                         session, k)
        url = f"ws://127.0.0.1:{self.procs.ports[k]}{self.request.uri}"
        headers = _forwarded_headers(self.request.headers, WEBSOCKET_OWN)
        try:
            self.upstream = await websocket.websocket_connect(
                httpclient.HTTPRequest(url, headers=headers, connect_timeout=TIMEOUT_S, request_timeout=TIMEOUT_S),
                subprotocols=protocols or None, max_message_size=MAX_MESSAGE_BYTES)
        except Exception as err:  # noqa: BLE001 - refused or gone: close this side with the reason
            log.warning("websocket to app process %d refused: %s", k, err)
            self.close(1011, "the app process refused the websocket")
            return
        if self._closed:  # the page went away while connecting
            self.upstream.close()
            return
        self._pump = asyncio.get_running_loop().create_task(self._downstream(self.upstream))

    async def _downstream(self, upstream: websocket.WebSocketClientConnection) -> None:
        while True:
            msg = await upstream.read_message()
            if msg is None:
                code, reason = upstream.close_code, upstream.close_reason
                if not self._closed:
                    self.close(code, reason)
                return
            try:
                await self.write_message(msg, binary=isinstance(msg, bytes))
            except websocket.WebSocketClosedError:
                upstream.close()
                return

    async def on_message(self, message: str | bytes) -> None:
        if self.upstream is not None:
            try:
                await self.upstream.write_message(message, binary=isinstance(message, bytes))
            except websocket.WebSocketClosedError:
                self.close(1011, "the app process closed the websocket")

    def on_close(self) -> None:
        self._closed = True
        if self.upstream is not None:
            self.upstream.close()


class _Liveness(web.RequestHandler):
    """200 when every app process answers its own ``/liveness`` (same query) with 200, else 503."""

    def initialize(self, procs: AppProcesses) -> None:
        self.procs = procs

    async def get(self) -> None:
        async def ask(port: int) -> int:
            resp, _ = await _fetch(httpclient.HTTPRequest(f"http://127.0.0.1:{port}{self.request.uri}",
                                                          headers={"Host": self.request.headers.get("Host", "")},
                                                          request_timeout=TIMEOUT_S))
            return resp.code if resp is not None else 599

        codes = await asyncio.gather(*(ask(p) for p, up in zip(self.procs.ports, self.procs.alive) if up))
        ok = bool(codes) and all(c == 200 for c in codes)
        self.set_status(200 if ok else 503)
        self.finish({"ok": ok, "processes": len(self.procs.ports), "answering": sum(c == 200 for c in codes),
                     "sessions_per_process": self.procs.sessions_per_process()})


def front_application(procs: AppProcesses, allowed: Sequence[str]) -> web.Application:
    """The front's tornado application: the host guard, then the websocket relay, ``/liveness`` and the
    HTTP relay."""
    return web.Application([
        host_guard_rule(allowed),
        Rule(_WebSocketUpgrade(), _WebSocketRelay, {"procs": procs}),
        Rule(PathMatches(r"/liveness"), _Liveness, {"procs": procs}),
        Rule(PathMatches(r"/.*"), _HttpRelay, {"procs": procs}),
    ], websocket_max_message_size=MAX_MESSAGE_BYTES)
