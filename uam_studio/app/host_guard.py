"""The host guard of the app's server: it answers only requests addressed to it by a name in its allow-list.

Every request (page, static files, ``/ws`` websocket, ``/liveness``) whose ``Host`` header, or whose
``Origin`` header when it has one, is not in :func:`allowed_hosts` gets 403. A web page on another site
therefore cannot drive the app, not even through DNS rebinding (a name of its own that resolves to this
machine). Used by a single server (:func:`install_host_guard`) and by the front of several app processes
(:func:`host_guard_rule`, :mod:`uam_studio.app.front`).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from typing import Any
from urllib.parse import urlsplit

from tornado.httputil import HTTPServerRequest
from tornado.routing import Matcher, Rule
from tornado.web import RequestHandler

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


def host_guard_rule(allowed: Sequence[str]) -> Rule:
    """A tornado routing rule that answers 403 to every request whose ``Host``, or ``Origin`` when
    present, is not in ``allowed``; it goes ahead of all other rules."""
    return Rule(_ForeignRequest(allowed), _Forbidden, {"allowed": list(allowed)})


def install_host_guard(server: Any, allowed: Sequence[str]) -> None:
    """Make the bokeh ``server`` answer 403 to every request whose ``Host``, or ``Origin`` when present,
    is not in ``allowed`` (:func:`host_guard_rule`, ahead of all others in its tornado Application). Its
    own websocket Origin check gets the same list."""
    app = server._tornado  # bokeh's Server keeps its tornado Application there (panel reads it too)
    app.default_router.rules.insert(0, host_guard_rule(allowed))
    app.websocket_origins.clear()  # the live set bokeh's /ws handler checks Origin against
    app.websocket_origins.update(allowed)
