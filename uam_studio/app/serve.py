"""Serve the app from Python: :func:`serve` (used by ``uam-studio serve``)."""

from __future__ import annotations

import threading

from uam_studio.app.state import warm_up

DEFAULT_PORT = 5006


def serve(port: int = DEFAULT_PORT, show: bool = True, address: str | None = None,
          allow_websocket_origin: list[str] | None = None) -> None:
    """Start a Panel server with the app at ``/`` and block until it is stopped (Ctrl-C).

    The Dynaformer and the health population are loaded in a background thread at start, so the
    first session does not wait for them.
    """
    import panel as pn

    from uam_studio.app.main import EXTENSIONS, TITLE, create_app
    from uam_studio.app.session import configure_server_threads

    configure_server_threads()
    threading.Thread(target=warm_up, daemon=True, name="uam-warm-up").start()
    pn.extension(*EXTENSIONS)
    pn.serve({"/": create_app}, port=port, address=address, show=show, title=TITLE,
             websocket_origin=allow_websocket_origin, start=True, threaded=False,
             print_url=True)


class ServedApp:
    """``panel serve uam_studio/app/main.py --warm --liveness`` in a subprocess on a free local port:
    how the browser tests and ``benchmarks/bench_app.py`` start the app the way users do.

    Use as a context manager; ``url`` is the app's page, ``log_path`` the server's output and
    ``startup_s`` the seconds from launch to the first ``/liveness`` answer (``--warm`` builds the
    app once before the server answers).

    :param home: the user folder (``UAM_STUDIO_HOME``) for the server.
    :param timeout_s: how long to wait for the server (s); :class:`RuntimeError` with the log's tail after.
    """

    def __init__(self, home, timeout_s: float = 300.0, **env: str) -> None:
        from pathlib import Path

        self.home = Path(home)
        self.timeout_s = timeout_s
        self.extra_env = env
        self.log_path = self.home / "serve.log"

    def __enter__(self) -> ServedApp:
        import os
        import socket
        import subprocess
        import sys
        import time
        import urllib.request
        from pathlib import Path

        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
        self.home.mkdir(parents=True, exist_ok=True)
        self._log = open(self.log_path, "w")  # noqa: SIM115 - closed in __exit__
        env = {**os.environ, "UAM_STUDIO_HOME": str(self.home), **self.extra_env}
        root = Path(__file__).resolve().parents[2]
        t0 = time.perf_counter()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "panel", "serve", "uam_studio/app/main.py", "--port", str(self.port),
             "--address", "127.0.0.1", "--allow-websocket-origin", f"127.0.0.1:{self.port}", "--warm",
             "--liveness"], cwd=root, env=env, stdout=self._log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + self.timeout_s
        while True:  # /liveness answers once the server is up, and builds no session
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{self.port}/liveness", timeout=30) as r:
                    if r.status == 200:
                        break
            except OSError:
                pass
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.__exit__()
                raise RuntimeError(f"panel serve did not start: {self.log_path.read_text()[-2000:]}")
            time.sleep(0.25)
        self.startup_s = time.perf_counter() - t0
        self.url = f"http://127.0.0.1:{self.port}/main"
        return self

    def __exit__(self, *exc) -> None:
        import subprocess

        self.proc.terminate()
        try:
            self.proc.wait(20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
        self._log.close()
