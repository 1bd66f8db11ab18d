"""The front's relay in one process (uam_studio/app/front.py): a stand-in app process (a tornado app that
answers a page carrying a Bokeh session token and echoes on its websocket) behind
:func:`front_application`. Each test runs its own event loop in a thread of its own."""

from __future__ import annotations

import asyncio
import json
from concurrent.futures import ThreadPoolExecutor

from bokeh.util.token import generate_jwt_token
from tornado import httpclient, web, websocket
from tornado.httpserver import HTTPServer

from uam_studio.app.front import AppProcesses, front_application
from uam_studio.app.serve import free_loopback_port


class _Page(web.RequestHandler):
    def initialize(self, name: str) -> None:
        self.name = name

    def get(self) -> None:
        token = generate_jwt_token(f"session-{self.name}-{self.get_argument('n', '0')}", signed=False)
        self.set_header("Set-Cookie", f"seen={self.name}")
        self.write(f'<html><script>var docs = {{"token": "{token}"}};</script>{self.name}</html>')

    def post(self) -> None:
        self.write({"process": self.name, "body": self.request.body.decode(), "host": self.request.headers["Host"]})


class _Echo(websocket.WebSocketHandler):
    def initialize(self, name: str) -> None:
        self.name = name

    def select_subprotocol(self, subprotocols: list[str]) -> str | None:
        return subprotocols[0] if subprotocols else None

    def on_message(self, message: str | bytes) -> None:
        self.write_message(f"{self.name}:{message!s}" if isinstance(message, str) else message,
                           binary=isinstance(message, bytes))


class _Liveness(web.RequestHandler):
    def get(self) -> None:
        self.write("ok")


def _app(name: str) -> web.Application:
    return web.Application([(r"/ws", _Echo, {"name": name}), (r"/liveness", _Liveness),
                            (r"/.*", _Page, {"name": name})])


def _run(coro_fn) -> object:
    with ThreadPoolExecutor(1) as pool:
        return pool.submit(asyncio.run, coro_fn()).result(timeout=120)


async def _serve(app: web.Application, port: int) -> HTTPServer:
    server = HTTPServer(app)
    server.listen(port, "127.0.0.1")
    return server


def test_pages_go_in_turn_and_each_websocket_reaches_the_process_that_built_its_page():
    async def scenario() -> dict:
        ports = [free_loopback_port(), free_loopback_port()]
        backs = [await _serve(_app(n), p) for n, p in zip("ab", ports)]
        procs = AppProcesses(ports)
        front_port = free_loopback_port()
        front = await _serve(front_application(procs, [f"127.0.0.1:{front_port}"]), front_port)
        client = httpclient.AsyncHTTPClient()
        base = f"http://127.0.0.1:{front_port}"
        pages = [await client.fetch(f"{base}/?n={k}") for k in range(4)]
        served = [p.body.decode()[-8:-7] for p in pages]
        tokens = [json.loads(p.body.decode().split("var docs = ")[1].split(";")[0])["token"] for p in pages]
        echoes = []
        for token in reversed(tokens):  # out of order: the route comes from the token, not the turn
            conn = await websocket.websocket_connect(f"ws://127.0.0.1:{front_port}/ws", subprotocols=["bokeh", token])
            await conn.write_message("hi")
            echoes.append(await conn.read_message())
            await conn.write_message(b"\x00\x01", binary=True)
            echoes.append(await conn.read_message())
            conn.close()
        post = await client.fetch(f"{base}/x", method="POST", body="payload")
        foreign = await client.fetch(f"{base}/", headers={"Host": "evil.example"}, raise_error=False)
        live = await client.fetch(f"{base}/liveness", raise_error=False)
        backs[1].stop()
        procs.alive[1] = False
        live_after = await client.fetch(f"{base}/liveness", raise_error=False)
        procs.alive[1] = True  # marked alive but gone: a request sent there gets 502
        gone = [(await client.fetch(f"{base}/", raise_error=False)).code for _ in range(2)]
        front.stop()
        backs[0].stop()
        return {"served": served, "echoes": echoes, "cookie": pages[0].headers.get("Set-Cookie"),
                "post": json.loads(post.body), "foreign": foreign.code, "live": (live.code, json.loads(live.body)),
                "live_after": live_after.code, "gone": sorted(gone), "counts": procs.sessions_per_process()}

    out = _run(scenario)
    assert out["served"] == ["a", "b", "a", "b"]
    assert out["echoes"] == ["b:hi", b"\x00\x01", "a:hi", b"\x00\x01", "b:hi", b"\x00\x01", "a:hi", b"\x00\x01"]
    assert out["cookie"] == "seen=a" and out["counts"] == [2, 2]
    assert out["post"]["body"] == "payload" and out["post"]["host"].startswith("127.0.0.1:")
    assert out["foreign"] == 403
    assert out["live"][0] == 200 and out["live"][1]["answering"] == 2
    assert out["live_after"] == 200  # the ended process is not asked
    assert out["gone"] == [200, 502]


def test_a_websocket_whose_process_is_gone_is_closed_with_the_reason():
    async def scenario() -> tuple:
        procs = AppProcesses([free_loopback_port()])  # nothing listens there
        front_port = free_loopback_port()
        front = await _serve(front_application(procs, [f"127.0.0.1:{front_port}"]), front_port)
        conn = await websocket.websocket_connect(f"ws://127.0.0.1:{front_port}/ws", subprotocols=["bokeh", "x"])
        msg = await conn.read_message()
        front.stop()
        return msg, conn.close_code, conn.close_reason

    assert _run(scenario) == (None, 1011, "the app process refused the websocket")
