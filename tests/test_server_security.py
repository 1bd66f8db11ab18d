"""``uam-studio serve`` answers only this machine by default: it listens on loopback, refuses (403)
every request whose Host, or Origin when present, is not one of its own names (DNS rebinding, other
sites' pages), websocket included; and a port it cannot bind is one line and exit 2.

The served tests start ``python -m uam_studio.cli serve --no-show`` in a subprocess on a free port.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import http.client
import ipaddress
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("panel")

from tornado.httpclient import HTTPClientError, HTTPRequest  # noqa: E402
from tornado.websocket import websocket_connect  # noqa: E402

from uam_studio.app.serve import ServedApp, allowed_hosts, child_pids, split_host  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
EVIL = "evil.example"


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "uam_studio.cli", *args]


def _get(port: int, path: str, host: str, origin: str | None = None) -> int:
    """Status of ``GET path`` sent to 127.0.0.1:port with the given Host (and Origin) headers."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=120)
    try:
        conn.putrequest("GET", path, skip_host=True)
        conn.putheader("Host", host)
        if origin is not None:
            conn.putheader("Origin", origin)
        conn.endheaders()
        resp = conn.getresponse()
        resp.read()
        return resp.status
    finally:
        conn.close()


@pytest.fixture(scope="module")
def server(tmp_path_factory) -> Iterator[ServedApp]:
    """``uam-studio serve --no-show`` on a free port (its process group ended after the module). ServedApp
    ends it with SIGTERM: it must stop as on Ctrl-C, exit 0, no semaphore of its worker pools left behind."""
    with ServedApp(tmp_path_factory.mktemp("serve"), timeout_s=120) as srv:
        yield srv
    log = srv.log_path.read_text()
    assert srv.proc.returncode == 0 and "leaked" not in log, (srv.proc.returncode, log[-2000:])
    # the websocket probes without Bokeh's subprotocol (test_websocket_own_origin_is_accepted): one line each
    assert "Traceback" not in log, log[-3000:]
    assert "websocket refused: Subprotocol header is not 'bokeh'" in log, log[-3000:]


def _listeners(port: int) -> list[str]:
    """Addresses of the TCP sockets listening on ``port`` (from /proc/net/tcp and tcp6)."""
    found = []
    for name, family in (("tcp", socket.AF_INET), ("tcp6", socket.AF_INET6)):
        path = Path("/proc/net") / name
        if not path.exists():
            continue
        for line in path.read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            addr_hex, port_hex = local.split(":")
            if state != "0A" or int(port_hex, 16) != port:  # 0A: LISTEN
                continue
            raw = bytes.fromhex(addr_hex)
            raw = b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4))  # host-order 32-bit words
            found.append(socket.inet_ntop(family, raw))
    return found


@pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="needs Linux /proc/net")
def test_default_listens_on_loopback_only(server):
    addrs = _listeners(server.port)
    assert addrs, "no listening socket found"
    assert all(ipaddress.ip_address(a).is_loopback for a in addrs), addrs


@pytest.mark.parametrize("path", ["/", "/liveness", "/static/js/bokeh.min.js", "/autoload.js", "/no-such-page"])
def test_http_foreign_host_is_refused(server, path):
    assert _get(server.port, path, f"{EVIL}:{server.port}") == 403
    assert _get(server.port, path, EVIL) == 403


@pytest.mark.parametrize("path", ["/", "/liveness", "/static/js/bokeh.min.js"])
@pytest.mark.parametrize("name", ["127.0.0.1", "localhost", "LocalHost"])
def test_http_own_host_is_served(server, path, name):
    assert _get(server.port, path, f"{name}:{server.port}") == 200


def test_http_foreign_origin_is_refused(server):
    own = f"127.0.0.1:{server.port}"
    assert _get(server.port, "/", own, origin=f"http://{EVIL}:{server.port}") == 403
    assert _get(server.port, "/", own, origin="null") == 403
    assert _get(server.port, "/", own, origin=f"http://{own}") == 200


def _ws(port: int, host: str, origin: str | None) -> int:
    """101 if a websocket handshake with ``/ws`` succeeds with these Host/Origin headers, else the HTTP status."""
    headers = {"Host": host, **({"Origin": origin} if origin else {})}

    async def handshake() -> int:
        try:
            conn = await websocket_connect(HTTPRequest(f"ws://127.0.0.1:{port}/ws", headers=headers,
                                                       request_timeout=60))
        except HTTPClientError as err:
            return err.code
        conn.close()
        return 101

    # A thread of its own: an earlier test (Playwright's sync API) may leave an event loop running in
    # this one, where asyncio.run refuses to start.
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        return pool.submit(asyncio.run, handshake()).result()


def test_websocket_foreign_host_is_refused(server):
    port = server.port
    # DNS rebinding: the page's own origin is the rebound name, and so is Host.
    assert _ws(port, f"{EVIL}:{port}", f"http://{EVIL}:{port}") == 403
    assert _ws(port, f"{EVIL}:{port}", f"http://localhost:{port}") == 403
    assert _ws(port, f"{EVIL}:{port}", None) == 403


def test_websocket_foreign_origin_is_refused(server):
    port = server.port
    assert _ws(port, f"127.0.0.1:{port}", f"http://{EVIL}:{port}") == 403
    assert _ws(port, f"localhost:{port}", f"http://{EVIL}") == 403


@pytest.mark.parametrize("name", ["127.0.0.1", "localhost"])
def test_websocket_own_origin_is_accepted(server, name):
    port = server.port
    assert _ws(port, f"{name}:{port}", f"http://{name}:{port}") == 101


def test_port_in_use_is_one_line_and_exit_2(tmp_path):
    env = {**os.environ, "UAM_STUDIO_HOME": str(tmp_path), "PYTHONPATH": str(ROOT)}
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        res = subprocess.run(_cli("serve", "--no-show", "--port", str(port)), cwd=ROOT, env=env,
                             capture_output=True, text=True, timeout=180)
    assert res.returncode == 2, (res.returncode, res.stderr[-2000:])
    assert res.stdout == ""
    lines = res.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --port:") and str(port) in lines[0], res.stderr


def test_port_in_use_is_found_before_the_app_is_imported(tmp_path):
    """A port in use is refused before panel and the app are imported (seconds of a user's wait)."""
    env = {**os.environ, "UAM_STUDIO_HOME": str(tmp_path), "PYTHONPATH": str(ROOT)}
    code = ("import sys\nfrom uam_studio.cli import main\nrc = main(sys.argv[1:])\n"
            "print(sorted(m for m in ('panel', 'torch', 'uam_studio.app.main') if m in sys.modules))\nsys.exit(rc)")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        res = subprocess.run([sys.executable, "-c", code, "serve", "--no-show", "--port", str(port)], cwd=ROOT,
                             env=env, capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and res.stderr.startswith("error: --port:"), res.stderr[-2000:]
    assert res.stdout == "[]\n", res.stdout


def test_port_in_use_starts_no_warm_up(monkeypatch):
    """The port is bound before the warm-up thread starts: a thread still inside torch when the
    process exits on the bind error aborted it (exit 134, "terminate called without an active exception")."""
    import uam_studio.app.serve as serve_mod
    import uam_studio.app.session as session_mod

    started: list[str] = []
    monkeypatch.setattr(serve_mod, "warm_up", lambda: started.append("warm_up"))  # what serve() starts
    monkeypatch.setattr(session_mod, "configure_server_threads", lambda: None)  # keep this process's torch threads
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        with pytest.raises(OSError):
            serve_mod.serve(port=taken.getsockname()[1], show=False)
    time.sleep(0.5)
    assert started == []


@pytest.mark.parametrize("value", ["http://host:5006", "host:port", "host:0", ":5006", "::1", ""])
def test_bad_allow_origin_is_refused(value, capsys):
    from uam_studio.cli import main

    assert main(["serve", "--no-show", "--allow-origin", value]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --allow-origin:") and len(err.splitlines()) == 1, err


def test_allowed_hosts():
    assert allowed_hosts(5006) == ["127.0.0.1:5006", "localhost:5006", "[::1]:5006"]
    assert allowed_hosts(80, "0.0.0.0", ["Lab-PC", "[fe80::1]:8000", "lab-pc:80"]) == [
        "127.0.0.1:80", "localhost:80", "[::1]:80", "0.0.0.0:80", "lab-pc:80", "[fe80::1]:8000"]
    assert allowed_hosts(5006, "::1") == ["127.0.0.1:5006", "localhost:5006", "[::1]:5006"]
    assert split_host("[::1]:5006") == ("[::1]", 5006)
    assert split_host("Example.ORG") == ("example.org", None)


def test_a_page_closing_mid_message_is_one_log_line_not_a_traceback(caplog):
    """The served loop's exception handler: tornado's closed-connection errors from tasks nobody awaited
    are one info line; any other task exception still reaches asyncio's default handler."""
    import logging

    from tornado.iostream import StreamClosedError
    from tornado.websocket import WebSocketClosedError

    from uam_studio.app.serve import quiet_closed_connections

    loop = asyncio.new_event_loop()
    seen: list[dict] = []
    loop.default_exception_handler = seen.append  # what asyncio would print as a traceback
    try:
        with caplog.at_level(logging.INFO, logger="uam_studio.serve"):
            for exc in (WebSocketClosedError(), StreamClosedError()):
                quiet_closed_connections(loop, {"message": "Task exception was never retrieved", "exception": exc})
            other = {"message": "Task exception was never retrieved", "exception": ValueError("a real bug")}
            quiet_closed_connections(loop, other)
    finally:
        loop.close()
    assert seen == [other]
    lines = [r.getMessage() for r in caplog.records if r.name == "uam_studio.serve"]
    assert lines == ["a page closed with messages on their way (WebSocketClosedError)",
                     "a page closed with messages on their way (StreamClosedError)"]


@pytest.mark.parametrize("value", ["-1", "65", "two", "1.5"])
def test_num_procs_out_of_range_is_one_line(value, capsys):
    from uam_studio.cli import main

    assert main(["serve", "--no-show", "--num-procs", value]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --num-procs:") and "[0, 64]" in err and len(err.splitlines()) == 1, err


def test_every_process_of_a_two_process_server_refuses_a_foreign_host_and_allows_added_names(tmp_path):
    """``--num-procs 2``: the front's host guard answers every request before it reaches an app process
    (16 connections: every foreign one is refused, every own one answered), each ``--allow-origin`` adds
    exactly its name (a port given with it is that port only), and the app processes accept what the front
    relays under those names (an allowed websocket is relayed and opened)."""
    import http.client

    from uam_studio.app.serve import ServedApp

    added = ["--allow-origin", "classroom.example", "--allow-origin", "10.0.0.5:8080"]
    with ServedApp(tmp_path, args=["--num-procs", "2", *added]) as app:
        port = app.port
        codes = []
        for host in [f"evil.example:{port}"] * 12 + [f"127.0.0.1:{port}"] * 4:
            conn = http.client.HTTPConnection("127.0.0.1", port, timeout=120)
            conn.request("GET", "/liveness", headers={"Host": host})  # the guard is before every route
            codes.append(conn.getresponse().status)
            conn.close()
        added_codes = [_get(port, "/liveness", host) for host in
                       (f"classroom.example:{port}", "10.0.0.5:8080", f"10.0.0.5:{port}", f"{EVIL}:{port}")]
        added_ws = [_ws(port, f"classroom.example:{port}", f"http://{origin}:{port}")
                    for origin in ("classroom.example", EVIL)]
        workers = child_pids(app.proc.pid)
    assert codes == [403] * 12 + [200] * 4, codes
    # SIGTERM to the group: the front passes it on and exits 0 once its app processes stopped cleanly
    assert app.proc.returncode == 0 and "leaked" not in app.log_path.read_text(), app.log_path.read_text()[-2000:]
    assert added_codes == [200, 200, 403, 403] and added_ws == [101, 403], (added_codes, added_ws)
    assert len(workers) >= 2, workers
    alive = [pid for pid in workers if Path(f"/proc/{pid}").exists()
             and Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"]
    assert not alive, alive  # the forked workers ended with the server


def test_a_refused_websocket_is_one_warning_line():
    """The filter on tornado's application log: Bokeh's ProtocolError (the reason a websocket is refused)
    becomes one warning naming it, without the traceback; other records pass unchanged."""
    import logging

    from bokeh.protocol.exceptions import ProtocolError

    from uam_studio.app.serve import OneLineRefusedWebsockets

    def record(exc: BaseException) -> logging.LogRecord:
        try:
            raise exc
        except type(exc):
            return logging.LogRecord("tornado.application", logging.ERROR, __file__, 1, "Uncaught exception %s",
                                     ("GET /ws",), sys.exc_info())

    refused = record(ProtocolError("Token is expired."))
    assert OneLineRefusedWebsockets().filter(refused)
    assert (refused.getMessage(), refused.levelname, refused.exc_info) == (
        "websocket refused: Token is expired.", "WARNING", None)
    other = record(ValueError("a bug"))
    assert OneLineRefusedWebsockets().filter(other)
    assert (other.levelname == "ERROR" and other.exc_info is not None
            and other.getMessage() == "Uncaught exception GET /ws")


def test_child_pids_lists_the_processes_this_one_started():
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert child.pid in child_pids(os.getpid())
    finally:
        child.kill()
        child.wait()
    assert child.pid not in child_pids(os.getpid())


def test_num_procs_auto_is_one_process_per_core(monkeypatch, capsys):
    import uam_studio.app.serve as served
    from uam_studio.cli import main

    seen = {}
    monkeypatch.setattr(served, "serve", lambda **kw: seen.update(kw))
    assert main(["serve", "--no-show", "--num-procs", "auto"]) == 0 and seen["num_procs"] == 0
    assert main(["serve", "--no-show", "--num-procs", "3"]) == 0 and seen["num_procs"] == 3
    assert main(["serve", "--no-show"]) == 0 and seen["num_procs"] == 1
    assert "warning" not in capsys.readouterr().err  # several processes are routed: nothing to warn of
