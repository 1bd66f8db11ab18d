"""The app's views outside a server (as in Jupyter): plain layout, Bokeh models build, contract labels.

Also the ``uam-studio serve`` argument errors (one line, exit 2), without starting a server.
"""

from __future__ import annotations

import panel as pn
import pytest
from bokeh.document import Document

from uam_studio.app import create_app
from uam_studio.app.planner import PlannerView, request_digest, route_legs, summary_html
from uam_studio.app.state import PlannerState, registry
from uam_studio.cli import main


@pytest.fixture(autouse=True)
def home(tmp_path, monkeypatch):
    monkeypatch.setenv("UAM_STUDIO_HOME", str(tmp_path / "home"))
    registry().refresh()


def test_create_app_in_notebook_is_plain_tabs_and_renders():
    app = create_app()
    assert isinstance(app, pn.Tabs)  # no template outside a server
    assert [name for name, _ in zip(app._names, app)] == ["Planner", "Battery lab", "Retrain"]
    root = app.get_root(Document())
    assert root is not None


def test_planner_view_contract():
    state = PlannerState(policy="greedy")
    view = PlannerView(state)
    view.__panel__().get_root(Document())
    assert "q_max" in view.q_max.name and "R0" in view.r0.name
    html = summary_html(state)
    assert html.startswith("<div class='uam-plan-summary' data-busy='false' data-inputs='greedy;single_charge;")
    for name in state.plan["route"]:
        assert name in html
    assert "Min predicted voltage" in html and "Altitudes:" in html and "Margin to EOD" in html
    assert request_digest(state.plan_request).endswith("|Napa:2:20")
    # widget -> state -> plan -> summary, in place (no server)
    view.r0.value = 0.2
    assert state.plan_request.mission.battery.r0 == 0.2 and "R0 0.2 ohm" in view.summary.object


def test_route_legs_colours_cycles_and_marks_failed_legs():
    rows = [{"name": "A", "x_km": 10.0, "y_km": 0.0}, {"name": "B", "x_km": 0.0, "y_km": 10.0}]
    plan = {"route": ["A", "vertiport", "B", "vertiport"], "altitudes_m": [500, 500, 1000, 500],
            "reached": ["A"], "safe": False}
    legs = route_legs(plan, rows, (0.0, 0.0))
    assert legs["cycle"] == [1, 1, 2, 2]
    assert legs["completed"] == [True, True, False, False]
    assert legs["leg"][2] == "3: V\u2192B" and legs["label"][2] == "1000 m"
    assert route_legs(None, rows, (0.0, 0.0))["leg"] == []


@pytest.mark.parametrize("argv, needle", [(["serve", "--port", "70000"], "--port"),
                                          (["serve", "--port", "x"], "--port")])
def test_serve_argument_errors(capsys, argv, needle):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith("error:") and needle in err


def test_retrain_view_start_from_widget_drives_the_state():
    from uam_studio.app.retrain import RetrainView
    from uam_studio.app.state import RetrainState

    planner = PlannerState(policy="greedy")
    state = RetrainState(runner="thread")
    view = RetrainView(state, planner)
    view.__panel__().get_root(Document())
    assert state.start_from == "scratch" and view.start_from.value == "scratch"
    view.start_from.value = "bundled"
    assert state.start_from == "bundled"
    planner.close()
