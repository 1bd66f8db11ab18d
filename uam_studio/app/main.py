"""The app: tabs (Planner, Fly, Battery lab, Retrain, Fleet, Glossary) on one set of state models.

    panel serve uam_studio/app/main.py        # or: uam-studio serve [--port P]

In Jupyter, ``create_app()`` returns a plain layout (no template); when served, it is wrapped in a
template. Absolute imports only: ``panel serve`` runs this file as a script.

The tabs are :data:`TABS`, a list of ``(title, build)`` pairs; ``build(session)`` gets the
:class:`AppSession` (the shared Planner state, the session's dispatcher...) and returns the tab's
view. Every tab but the first is built the first time it is shown.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import panel as pn

from uam_studio.app.panel_compat import keep_stylesheets_local, paint_without_restyling
from uam_studio.app.planner.comparison import compare_mode
from uam_studio.app.planner.state import PlannerState
from uam_studio.app.session import configure_server_threads, in_server_session, session_dispatcher
from uam_studio.app.style import draw_on_canvas

TITLE = "uam_studio: health-aware eVTOL mission planning"
EXTENSIONS = ("tabulator",)


@dataclass
class AppSession:
    """What the tabs of one session share.

    :param planner: the Planner's state (the mission every tab works on).
    :param served: built for a server session (not Jupyter).
    :param dispatch: hands a worker thread's result to the session's thread (None outside a server).
    :param compare: where plan comparisons run (:func:`~uam_studio.app.planner.comparison.compare_mode`).
    :param cleanups: called when the session ends (tabs add their own).
    """

    planner: PlannerState
    served: bool
    dispatch: Callable[[Callable[[], None]], None] | None
    compare: str
    cleanups: list[Callable[[], None]] = field(default_factory=list)


def _planner_tab(session: AppSession) -> Any:
    from uam_studio.app.planner.view import PlannerView

    return PlannerView(session.planner)


def _battery_lab_tab(session: AppSession) -> Any:
    from uam_studio.app.battery_lab.state import BatteryLabState
    from uam_studio.app.battery_lab.view import BatteryLabView

    return BatteryLabView(BatteryLabState(background=session.served, dispatch=session.dispatch))


def _retrain_tab(session: AppSession) -> Any:
    from uam_studio.app.retrain.state import RetrainState
    from uam_studio.app.retrain.view import RetrainView

    view = RetrainView(RetrainState(dispatch=session.dispatch, compare=session.compare), session.planner)
    session.cleanups.append(view.close)
    return view


def _fly_tab(session: AppSession) -> Any:
    from uam_studio.app.fly.state import FlyState
    from uam_studio.app.fly.view import FlyView

    planner = session.planner
    view = FlyView(FlyState(lambda: planner.mission, background=session.served, dispatch=session.dispatch))
    session.cleanups.append(view.close)
    return view


def _fleet_tab(session: AppSession) -> Any:
    from uam_studio.app.fleet.state import FleetState
    from uam_studio.app.fleet.view import FleetView

    return FleetView(FleetState(background=session.served, dispatch=session.dispatch))


def _glossary_tab(session: AppSession) -> Any:
    from uam_studio.glossary import glossary_markdown

    return pn.pane.Markdown("## Glossary\n\n" + glossary_markdown(), css_classes=["uam-glossary"],
                            sizing_mode="stretch_width", styles={"max-width": "900px"})


TABS: list[tuple[str, Callable[[AppSession], Any]]] = [
    ("Planner", _planner_tab),
    ("Fly", _fly_tab),
    ("Battery lab", _battery_lab_tab),
    ("Retrain", _retrain_tab),
    ("Fleet", _fleet_tab),
    ("Glossary", _glossary_tab),
]
"""The tabs in order: (title, build). Append a pair to add a tab."""


def _lazy(build: Callable[[AppSession], Any], session: AppSession) -> pn.viewable.Viewable:
    """A pane that calls ``build(session)`` the first time it is rendered."""

    # param's stub of depends wants a method (a first `self` argument); a function is valid too
    @pn.depends()  # type: ignore[arg-type]
    def view() -> Any:
        return build(session)

    return pn.param.ParamFunction(view, lazy=True, sizing_mode="stretch_width")


def new_session() -> AppSession:
    """The shared state of one new session, set up for where it is built.

    - A server session (``panel serve``, ``uam-studio serve``): plans, flights and lab runs in the
      background, results handed back through the session's dispatcher, comparisons in the
      server's comparison process, and everything closed when the session is destroyed.
    - A document a server builds without a session (``/liveness?endpoint=/`` checks that the app
      builds, then drops it): everything inline and no comparisons. A worker thread updating the
      panes of such a document would run beside the server's event loop, and Panel would resolve
      the shared stylesheets of whichever session that loop was serving against this document
      (Panel's CDN address): pages would then ask the CDN for ``loading.css``.
    - Jupyter or plain Python (no document being built): everything inline but the comparisons,
      which run in a thread.
    """
    served = in_server_session()
    server_built = pn.state.curdoc is not None  # a server is building a document, session or not
    if served:
        configure_server_threads()
    dispatch = session_dispatcher()
    compare = "off" if server_built and not served else compare_mode(served)
    session = AppSession(PlannerState(background=served, dispatch=dispatch, compare=compare), served, dispatch,
                         compare)
    session.cleanups.append(session.planner.close)
    if server_built:
        def _cleanup(_ctx: Any) -> None:
            for fn in session.cleanups:
                fn()

        pn.state.on_session_destroyed(_cleanup)  # a session's end; at once for a build without one
    return session


def create_app(template: bool | None = None) -> pn.viewable.Viewable | pn.template.BaseTemplate:
    """Build one session of the app.

    :param template: wrap the tabs in a page template; default: only when building a server session
        (``panel serve`` / ``uam-studio serve``), never in Jupyter.
    :return: the template, or a ``pn.Tabs`` with one tab per entry of :data:`TABS`.
    """
    pn.extension(*EXTENSIONS, notifications=False)
    draw_on_canvas()
    keep_stylesheets_local()
    session = new_session()
    if session.served:
        paint_without_restyling(pn.state.curdoc)
    tabs = []
    for i, (title, build) in enumerate(TABS):
        if i == 0:
            tabs.append((title, build(session)))
        else:  # built when first shown: a new page loads only what it shows
            tabs.append((title, _lazy(build, session)))
    app = pn.Tabs(*tabs, dynamic=True, sizing_mode="stretch_width")
    if template if template is not None else session.served:
        # No template-wide busy indicator: it would send the browser two extra changes (each a page
        # layout) on every callback; each tab shows its own busy state once work takes longer.
        return pn.template.BootstrapTemplate(title=TITLE, main=[app], header_background="#1f4e79",
                                             busy_indicator=None)
    return app


if pn.state.served:
    create_app().servable(title=TITLE)
