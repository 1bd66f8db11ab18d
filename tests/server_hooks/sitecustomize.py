"""Loaded by a test's server process (PYTHONPATH): logs each session document the app builds, with the
process that built it and the session's id, to the file named by ``UAM_TEST_BUILD_LOG``
(tests/test_server_sessions.py). Any other process: nothing."""

import os

_LOG = os.environ.get("UAM_TEST_BUILD_LOG")
if _LOG:
    import panel as pn

    from uam_studio.app.planner.state import PlannerState

    _init = PlannerState.__init__

    def _logged(self, *args, **kwargs):
        doc = pn.state.curdoc
        context = getattr(doc, "session_context", None) if doc is not None else None
        with open(_LOG, "a") as fh:  # one short line per build: appends from several processes do not mix
            fh.write(f"{os.getpid()} {getattr(context, 'id', None) or '-'}\n")
        _init(self, *args, **kwargs)

    PlannerState.__init__ = _logged
