"""The app: three tabs (Planner, Battery lab, Retrain) on one set of state models.

    panel serve uam_studio/app/main.py        # or: uam-studio serve [--port P]

In Jupyter, ``create_app()`` returns a plain layout (no template); when served, it is wrapped in a
template. Absolute imports only: ``panel serve`` runs this file as a script.
"""

from __future__ import annotations

import panel as pn

from uam_studio.app.battery_lab import BatteryLabView
from uam_studio.app.planner import PlannerView
from uam_studio.app.retrain import RetrainView
from uam_studio.app.session import configure_server_threads, in_server_session, session_dispatcher
from uam_studio.app.state import BatteryLabState, PlannerState, RetrainState

TITLE = "uam_studio: health-aware eVTOL mission planning"
EXTENSIONS = ("tabulator",)


def create_app(template: bool | None = None) -> pn.viewable.Viewable:
    """Build one session of the app.

    :param template: wrap the tabs in a page template; default: only when building a server session
        (``panel serve`` / ``uam-studio serve``), never in Jupyter.
    :return: the template, or a ``pn.Tabs`` with the three tabs.
    """
    pn.extension(*EXTENSIONS, notifications=False)
    served = in_server_session()
    if served:
        configure_server_threads()
    planner_state = PlannerState(background=served, dispatch=session_dispatcher())
    planner = PlannerView(planner_state)
    lab = BatteryLabView(BatteryLabState())
    retrain = RetrainView(RetrainState(), planner_state)
    tabs = pn.Tabs(("Planner", planner), ("Battery lab", lab), ("Retrain", retrain), dynamic=True,
                   sizing_mode="stretch_width")
    if served:
        def _cleanup(_ctx) -> None:
            planner_state.close()
            retrain.close()

        pn.state.on_session_destroyed(_cleanup)
    if template if template is not None else served:
        return pn.template.BootstrapTemplate(title=TITLE, main=[tabs], header_background="#1f4e79")
    return tabs


if pn.state.served:
    create_app().servable(title=TITLE)
