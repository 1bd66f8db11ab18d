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
