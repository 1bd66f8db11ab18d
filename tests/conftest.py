"""Fixtures shared by the browser tests (tests/test_app_browser.py, tests/test_app_fly_browser.py)."""

from __future__ import annotations

import shutil

import pytest

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"


@pytest.fixture(scope="session")
def app_url(tmp_path_factory):
    """Serve the app in a subprocess (the way users start it) and yield its URL: one server per worker, shared
    by both browser files where they run on the same one."""
    from uam_studio.app.serve import ServedApp

    home = tmp_path_factory.mktemp("uam_home")
    try:
        # the offline notebooks' resource settings left in the shell: the served page still loads only
        # from the server (the browser tests refuse any other request)
        with ServedApp(home, timeout_s=180, BOKEH_RESOURCES="inline", PANEL_INLINE="1") as srv:
            yield srv.url
    except RuntimeError as err:
        pytest.fail(str(err))
    # Tracebacks other than a page closing with messages in flight are app errors.
    blocks = (home / "serve.log").read_text().split("Traceback (most recent call last):")[1:]
    errors = [b for b in blocks if "WebSocketClosedError" not in b and "StreamClosedError" not in b]
    assert not errors, errors[0][-3000:]


@pytest.fixture(scope="session")
def browser_type_launch_args(browser_type_launch_args):
    return {**browser_type_launch_args, "executable_path": CHROMIUM, "args": ["--no-sandbox"]}
