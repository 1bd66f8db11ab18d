"""The app's views outside a server (as in Jupyter): plain layout, Bokeh models build, contract labels.

Also the ``uam-studio serve`` argument errors (one line, exit 2), without starting a server.
"""

from __future__ import annotations

import holoviews as hv
import numpy as np
import panel as pn
import pytest
from bokeh.document import Document

from uam_studio.app import create_app
from uam_studio.app.planner.map_geometry import route_legs
from uam_studio.app.planner.state import PlannerState
from uam_studio.app.planner.summary import request_digest, summary_html
from uam_studio.app.planner.view import PlannerView
from uam_studio.app.services import registry
from uam_studio.cli import main


@pytest.fixture(autouse=True)
def home(tmp_path, monkeypatch):
    monkeypatch.setenv("UAM_STUDIO_HOME", str(tmp_path / "home"))
    registry().refresh()


def _figures(model) -> list:
    from bokeh.models import Plot

    return [m for m in model.references() if isinstance(m, Plot)]


def test_create_app_in_notebook_is_plain_tabs_and_renders(monkeypatch):
    """... and every figure of its tabs draws on the canvas, even where HoloViews' default is WebGL (which
    draws no line in a browser without a GPU)."""
    import holoviews as hv

    from uam_studio.app.main import TABS

    monkeypatch.setattr(type(hv.renderer("bokeh")), "webgl", True)
    app = create_app()
    assert isinstance(app, pn.Tabs)  # no template outside a server
    names = [name for name, _ in zip(app._names, app)]
    assert names == [title for title, _ in TABS]  # one list to extend
    assert names[0] == "Planner" and {"Battery lab", "Retrain"} <= set(names)
    root = app.get_root(Document())
    assert root is not None
    figures = _figures(root)
    for name in ("Battery lab", "Retrain"):  # the later tabs are built when shown
        app.active = names.index(name)
        figures += _figures(app.get_root(Document()))
    titles = {f.title.text.split(",")[0] for f in figures if f.title is not None and f.title.text}
    assert {"Voltage: physics (what happens) vs Dynaformer (predicted)", "Voltage (physics model)",
            "Per-cell current", "Priority of its plan of this map after each epoch "
            "(0 = unsafe)"} <= titles, titles
    assert {f.output_backend for f in figures} == {"canvas"}


def test_the_page_document_validates_without_warnings(caplog):
    """Bokeh validates every session's document; a warning there was logged once per student
    (W-1005 for the map, sized by its frame)."""
    import logging

    doc = Document()
    create_app(template=True).server_doc(doc)
    with caplog.at_level(logging.WARNING, logger="bokeh.core.validation.check"):
        doc.validate()
    assert [r.getMessage() for r in caplog.records] == []


def test_planner_view_contract():
    state = PlannerState(policy="greedy")
    view = PlannerView(state)
    view.__panel__().get_root(Document())
    assert "q_max" in view.q_max.name and "R0" in view.r0.name
    html = summary_html(state)
    assert html.startswith("<div class='uam-plan-summary' data-busy='false' data-inputs='greedy;single_charge;")
    for name in state.plan["route"]:
        assert name in html
    for needle in ("<b>Policy:</b> Greedy", "<b>Route:</b>", "<b>Reached:</b>", "class='uam-verdict' data-level='safe'",
                   "physics: safe by", "predicted: safe by", "(90%: "):
        assert needle in html, needle
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
    assert legs["leg"][2] == "3: V\u2192B" and legs["label"][2] == "#3 1000 m"
    assert route_legs(None, rows, (0.0, 0.0))["leg"] == []


@pytest.mark.parametrize("argv, needle", [(["serve", "--port", "70000"], "--port"),
                                          (["serve", "--port", "x"], "--port")])
def test_serve_argument_errors(capsys, argv, needle):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith("error:") and needle in err


def test_retrain_view_start_from_widget_drives_the_state():
    from uam_studio.app.retrain.state import RetrainState
    from uam_studio.app.retrain.view import RetrainView

    planner = PlannerState(policy="greedy")
    state = RetrainState(runner="thread")
    view = RetrainView(state, planner)
    view.__panel__().get_root(Document())
    assert state.start_from == "scratch" and view.start_from.value == "scratch"
    view.start_from.value = "bundled"
    assert state.start_from == "bundled"
    planner.close()


def test_retrain_view_planner_choice_shows_its_settings_and_curves():
    """Choosing the attention planner shows its settings (missions, epochs) and its curves (priority
    on the map with the oracle's line, loss) in place of the DQN's; a run locks the choice."""
    import pandas as pd

    from uam_studio.app.retrain.state import EPOCH_COLUMNS, RetrainState
    from uam_studio.app.retrain.view import RetrainView

    planner = PlannerState(policy="greedy")
    state = RetrainState(runner="thread", compare="inline")
    view = RetrainView(state, planner)
    view.__panel__().get_root(Document())
    dqn_parts = [view.steps, view.alpha, view.rewards, view.dqn_curves]
    attention_parts = [view.missions, view.epochs, view.attention_curves]
    assert all(x.visible for x in dqn_parts) and not any(x.visible for x in attention_parts)
    view.model.value = "attention"
    assert state.model == "attention"
    assert all(x.visible for x in attention_parts) and not any(x.visible for x in dqn_parts)
    view.missions.value, view.epochs.value = 40, 7
    assert (state.missions, state.epochs) == (40, 7)
    rows = pd.DataFrame([[1, 1.2, 0.4, 0, 0], [2, 0.9, 0.6, 6, 4]], columns=EPOCH_COLUMNS)
    el = view._priority_element(rows, state.reference)
    search, alone, oracle = el.values()
    assert search.data["priority"].tolist() == [0, 6] and alone.data["priority_net"].tolist() == [0, 4]
    assert oracle.data.iloc[:, 1].tolist() == [6.0, 6.0]  # the exact oracle's priority on this map
    assert el.opts.get().kwargs["xlim"] == (0.0, 10.0)
    assert [c.label for c in view._loss_element(rows).values()] == ["loss (cross-entropy)",
                                                                    "oracle's choice ranked first (share)"]
    state.running = True
    assert view.model.disabled and view.start.disabled
    state.running = False
    planner.close()


def _legend_labels(element) -> list[str]:

    plot = hv.renderer("bokeh").get_plot(element)
    return [item.label.value for lg in plot.state.legend for item in lg.items if hasattr(item.label, "value")]


def _figure_legend_labels(fig) -> list[str]:
    """The labels of a Bokeh figure's visible legend entries."""
    return [item.label.value for lg in fig.legend for item in lg.items if item.visible]


def test_voltage_plot_always_shows_eod_with_a_legend_entry_and_the_band():
    state = PlannerState(policy="greedy")
    view = PlannerView(state)
    data = view._voltage_data()
    lo, hi = data["ylim"]
    assert lo < 3.0 < hi and min(data["physics"][1]) > 3.3  # the default plan stays far above EOD
    view._draw_voltage(data)
    assert _figure_legend_labels(view.voltage_fig) == ["Dynaformer 90%", "physics", "Dynaformer", "EOD 3 V"]
    assert len(data["band"][1]) == len(data["physics"][1]) > 0
    state.apply(eod_v=2.5)
    lo, hi = view._voltage_data()["ylim"]
    assert lo < 2.5 < hi
    state.close()


def test_failed_takeoff_draws_the_takeoff_not_an_empty_plot():
    state = PlannerState(policy="greedy")
    view = PlannerView(state)
    state.apply(r0=0.45)
    data = view._voltage_data()
    t, v = data["physics"]
    assert len(t) > 5 and v[-1] < 3.0 and data["xlim"] == (0.0, t[-1]) and data["ylim"][0] < v.min()
    assert "cannot take off" in summary_html(state) and "data-level='unsafe'" in summary_html(state)
    view._draw_voltage(data)  # no legend entry for a series that has no data
    labels = _figure_legend_labels(view.voltage_fig)
    assert labels and all("Dynaformer" not in lbl for lbl in labels) and "physics" in labels, labels
    assert data["legs"] == ([], [])  # no leg took off
    # no route: the altitude chart says so, and the map shows no empty legend box
    view._draw_altitude(view._route_data())
    texts = [t for r in view.altitude_fig.renderers for t in r.data_source.data.get("text", [])]
    assert texts == ["no route: nothing is flown"], texts
    state.apply(r0=0.117)
    root = view.__panel__().get_root(Document())
    legend = next(m for m in root.references() if type(m).__name__ == "Legend" and m.name == "uam-route-legend")
    assert legend.visible is True
    state.apply(r0=0.45)
    assert legend.visible is False
    state.apply(r0=0.117)  # a route again: the legend is back
    assert legend.visible is True
    state.close()


def test_verdict_is_amber_where_the_models_disagree():
    state = PlannerState(policy="dqn")
    state.apply(r0=0.246)
    html = summary_html(state)
    assert "data-level='disagree'" in html and "#fff4e5" in html and "Models disagree" in html
    state.close()


def test_comparison_panel_names_the_three_planners_with_their_numbers():
    from uam_studio.app.planner.summary import comparison_html

    state = PlannerState(compare="inline")
    view = PlannerView(state)
    view.__panel__().get_root(Document())
    html = view.compare.object
    assert html == comparison_html(state) and html.startswith("<div class='uam-plan-compare' data-pending='false'")
    for label, prio in (("Attention (default)", ">6<"), ("Greedy", ">6<"), ("Oracle (exact)", ">6<")):
        row = html.split(f">{label}<")[1].split("</tr>")[0]
        assert prio in row and "3." in row, (label, row)
    assert "matches" in html and "reference" in html
    assert "<tr class='uam-compare-agent' style='font-weight:bold;'>" in html  # the shown plan's row
    state.apply(policy="dqn")  # the paper's DQN: 1 priority short of the oracle on the example
    html = view.compare.object
    row = html.split(">DQN (paper)<")[1].split("</tr>")[0]
    assert ">5<" in row and "-1 priority (-17%)" in row
    state.close()


def test_policy_select_starts_on_the_attention_planner():
    state = PlannerState()
    view = PlannerView(state)
    assert view.policy.value == "attention"
    assert list(view.policy.options)[:4] == ["Attention (bundled, default)", "DQN (paper, up to 8)",
                                             "Oracle (exact up to 8)", "Greedy"]
    assert "<b>Policy:</b> Attention (bundled, default)" in view.summary.object
    view.policy.value = "oracle"
    assert state.policy == "oracle" and "<b>Policy:</b> Oracle (exact optimum)" in view.summary.object
    state.close()


def test_map_route_has_a_cycle_legend_and_out_and_back_labels_do_not_overlap():
    from uam_studio.app.planner.map_geometry import NAME_CHAR_KM, altitude_labels, leg_arrows

    state = PlannerState(policy="greedy")
    view = PlannerView(state)
    root = view.__panel__().get_root(Document())
    legends = [m for m in root.references() if type(m).__name__ == "Legend" and m.name == "uam-route-legend"]
    assert len(legends) == 1 and [item.label.field for item in legends[0].items] == ["legend", "failed"]
    assert set(view._route_data()["legend"]) == {"cycle 1"}

    rows = [{"name": "A", "x_km": 30.0, "y_km": 0.0}, {"name": "B", "x_km": 0.0, "y_km": 30.0}]
    plan = {"route": ["A", "vertiport", "B", "vertiport"], "altitudes_m": [1000, 500, 500, 500],
            "reached": ["A", "B"], "safe": True}
    legs = route_legs(plan, rows, (0.0, 0.0))
    labels = altitude_labels(legs, [(0.0, 0.0), (30.0, 0.0), (0.0, 30.0)], ["", "A ***", "B *"])
    assert sorted(labels["text"]) == ["#1/#2 1000/500 m", "#3/#4 500 m"]  # one per out-and-back pair, in order
    for x, y in zip(labels["x"], labels["y"]):
        for nx, ny in [(0.0, 0.0), (30.0, 0.0), (0.0, 30.0)]:
            assert np.hypot(x - nx, y - ny) > 10.0  # away from the places and their names
    # a long name is an obstacle over its whole width: a label clears its right end too
    wide = altitude_labels(legs, [(0.0, 0.0), (30.0, 0.0), (0.0, 30.0)], ["", "A very long destination name", "B"])
    right_end = (30.0 + 0.5 * NAME_CHAR_KM * len("A very long destination name"), 5.5)
    assert all(np.hypot(x - right_end[0], y - right_end[1]) > 3.0 for x, y in zip(wide["x"], wide["y"]))
    arrows = leg_arrows(legs)  # one arrowhead per leg, pointing the way it is flown
    assert len(arrows["x"]) == 4 and np.allclose(arrows["angle"][0], -np.pi / 2)  # V -> A: east
    assert legs["legend"] == ["cycle 1", "cycle 1", "cycle 2", "cycle 2"]
    state.close()


def _label_overlaps(mission, plan: dict) -> list[tuple[str, str]]:
    """Pairs (leg label, what it covers) on the Planner's map of ``plan`` at its default zoom."""
    from uam_studio.app.planner.map_geometry import altitude_labels, label_overlaps

    rows = [{"name": d.name, "x_km": d.x_km, "y_km": d.y_km} for d in mission.destinations]
    legs = route_legs(plan, rows, (mission.vertiport.x_km, mission.vertiport.y_km))
    names = ["vertiport"] + [f"{d.name} {'*' * d.priority}" for d in mission.destinations]
    nodes = [(mission.vertiport.x_km, mission.vertiport.y_km)] + [(d.x_km, d.y_km) for d in mission.destinations]
    return label_overlaps(altitude_labels(legs, nodes, names), nodes, names)


def test_leg_labels_overlap_no_label_name_or_marker_on_small_maps():
    """At the map's default zoom no leg label covers another label, a place's marker or its name:
    on the example mission and on 90 random maps of 1-3 destinations (denser maps cannot always
    be labelled clear; benchmarks/RESULTS.md has the measured share)."""
    from uam_studio.planning.missions.generate import random_mission
    from uam_studio.planning.solvers.greedy import greedy_plan

    def plan_of(m) -> dict:
        p = greedy_plan(m)
        return {"route": p.route, "altitudes_m": p.altitudes_m, "reached": p.reached, "safe": True}

    example = PlannerState(policy="greedy")
    assert _label_overlaps(example.mission, example.plan) == [] and example.plan["route"]
    example.close()
    for n in (1, 2, 3):
        for k in range(30):
            m = random_mission(np.random.default_rng([3030, n, k]), (n, n), "multi_charge")
            assert _label_overlaps(m, plan_of(m)) == [], (n, k)


def test_map_names_stay_on_their_places_at_any_zoom():
    """Names are drawn at their place's own coordinates, moved by a fixed number of screen pixels
    (not km): zooming in cannot drift them away from their points (an offset in km grows with the zoom)."""

    from uam_studio.app.fly.state import FlyState
    from uam_studio.app.fly.view import FlyView
    from uam_studio.app.style import NAME_OFFSET_PX

    state = PlannerState(policy="greedy")
    view = PlannerView(state)
    rows = state.destination_rows()
    texts = [r for r in view.map_fig.renderers if type(r.glyph).__name__ == "Text"]
    names = next(r for r in texts if r.data_source is view._names_src)
    vp_label = next(r for r in texts if r.data_source is view._vp_src)
    assert list(names.data_source.data["x"]) == [r["x_km"] for r in rows]
    assert list(names.data_source.data["y"]) == [r["y_km"] for r in rows]
    assert [list(vp_label.data_source.data[c]) for c in ("x", "y")] == [[state.vertiport_x_km], [state.vertiport_y_km]]
    for renderer, offset in ((names, -NAME_OFFSET_PX), (vp_label, NAME_OFFSET_PX)):
        assert renderer.glyph.y_offset == offset and renderer.glyph.x_offset == 0
    fig = FlyView(FlyState(lambda: state.mission)).map_fig
    texts = [r for r in fig.renderers if type(r.glyph).__name__ == "Text" and "name" in r.data_source.data]
    assert len(texts) == 1 and texts[0].glyph.y_offset == -NAME_OFFSET_PX
    assert list(texts[0].data_source.data["y_km"]) == [d.y_km for d in state.mission.destinations]
    state.close()


def test_battery_lab_plots_share_time_and_sort_the_legend_by_value():
    from uam_studio.app.battery_lab.state import BatteryLabState
    from uam_studio.app.battery_lab.view import BatteryLabView, eod_text

    view = BatteryLabView(BatteryLabState())
    view.__panel__().get_root(Document())
    c = view.state.result
    data = view._plot_data(c)
    labels = ["altitude 500 m", "altitude 1000 m", "altitude 2000 m", "altitude 3000 m", "this setting"]
    assert _legend_labels(view._current_element(data, labels, "altitude")) == labels
    assert _legend_labels(view._voltage_element(data, labels, "altitude")) == labels + ["EOD 3 V"]
    figs = [m for pane in (view.current_plot, view.voltage_plot) for m in pane.get_root(Document()).references()
            if type(m).__name__ == "figure"]
    assert len(figs) == 2 and [(f.x_range.start, f.x_range.end) for f in figs] == [data["xlim"]] * 2
    texts = [eod_text(cv) for cv in c["family"]]
    assert texts[0].startswith("not reached (lowest 3.") and "nan" not in " ".join(texts)
    view.state.vary = "wind"  # new factor: new legend
    assert view._factor[0] == "wind" and "wind -39 kt" in view.eod_table.object


def test_battery_lab_loads_the_vtc6_cell():
    """The identified real cell: its nominal health and ranges reach the sliders, its own health family
    the legend, and it flies the same per-cell current further than the paper's cell."""
    from uam_studio.app.battery_lab.state import NASA_NAME, VTC6_NAME, BatteryLabState
    from uam_studio.app.battery_lab.view import BatteryLabView
    from uam_studio.battery.parameters import VTC6

    view = BatteryLabView(BatteryLabState())
    view.__panel__().get_root(Document())
    nasa = view.state.result["setting"][0]
    sent = []  # every slider state the browser is sent: each must hold its value (or the browser clamps it)
    for key in ("q_max", "r0"):
        w = view.widgets[key]
        w.param.watch(lambda e, w=w: sent.append((w.start, w.value, w.end)), ["start", "end", "value"])
    view.widgets["cell"].value = VTC6_NAME
    assert sent and all(lo <= v <= hi for lo, v, hi in sent), sent
    q, r = view.widgets["q_max"], view.widgets["r0"]
    assert (q.start, q.end, q.value) == (7000.0, 11500.0, VTC6.q_max) and (r.start, r.end) == (0.01, 0.1)
    assert view.state.r0 == VTC6.r0
    vtc6 = view.state.result["setting"][0]
    assert vtc6["eod_s"] is None and nasa["eod_s"] is not None  # 3 legs: the NASA cell is empty, the VTC6 is not
    # the same load: equal current at every sample time both (thinned) curves hold; the NASA cell's ends at its EOD
    common, i, j = np.intersect1d(vtc6["time_s"], nasa["time_s"], return_indices=True)
    assert common.size > 100 and nasa["time_s"][-1] <= nasa["eod_s"] + 1.0 < vtc6["time_s"][-1]
    np.testing.assert_allclose(vtc6["current_a"][i], nasa["current_a"][j])
    view.state.vary = "q_max"
    assert view._factor == ("q_max", "q_max 8000 C", "q_max 9000 C", "q_max 10000 C", "q_max 11000 C")
    assert "q_max 8000 C" in view.eod_table.object
    sent.clear()
    view.widgets["cell"].value = NASA_NAME  # back: 10943 C to 7600 C, inside every range sent
    assert (q.start, q.end, q.value) == (5000.0, 8000.0, 7600.0) and view.state.q_max == 7600.0
    assert sent and all(lo <= v <= hi for lo, v, hi in sent), sent


def test_retrain_view_shows_progress_numbers_and_the_oracle_line():
    from uam_studio.app.retrain.state import RetrainState
    from uam_studio.app.retrain.view import RetrainView

    planner = PlannerState(policy="greedy")
    view = RetrainView(RetrainState(runner="thread", compare="inline"), planner)
    view.__panel__().get_root(Document())
    assert "exact oracle" in view.reference_text.object and "3 of 4 destinations" in view.reference_text.object
    el = view._reached_element(view.buffer.data, view.state.reference)
    curves = el.values()
    assert curves[-1].data.iloc[:, 1].tolist() == [3.0, 3.0]  # the oracle's line
    assert el.opts.get().kwargs["xlim"] == (0.0, 50.0)  # before any episode: 50 episodes, not 0-1
    assert view.progress_text.object == "<span class='uam-train-progress-text'>not started</span>"
    planner.close()


def test_inputs_are_handled_without_panel_s_50_ms_wait_and_the_page_has_no_global_spinner():
    from uam_studio.app.battery_lab.state import BatteryLabState
    from uam_studio.app.battery_lab.view import BatteryLabView
    from uam_studio.app.session import value_property

    view = PlannerView(PlannerState(policy="greedy"))
    lab = BatteryLabView(BatteryLabState())
    props = {}
    for wd in [*view._inputs.values(), *lab.widgets.values()]:
        props[wd.name] = value_property(wd)
        assert props[wd.name] in wd._priority_changes, wd.name  # handled on the next tick, not after 50 ms
    assert props["Vary"] == "active"  # a radio-button group's value travels as `active`
    assert "value" not in pn.widgets.FloatSlider._priority_changes  # other sliders keep Panel's default
    assert "value" not in pn.widgets.FloatSlider(name="x")._priority_changes
    page = create_app(template=True)
    assert isinstance(page, pn.template.BaseTemplate) and page.busy_indicator is None


def test_a_server_build_without_a_session_runs_nothing_beside_the_event_loop():
    """``/liveness?endpoint=/`` builds a document with no session: no comparison thread may update
    its panes later (Panel would resolve a live session's stylesheets against it: CDN addresses)."""
    from bokeh.document import Document
    from panel.io.state import set_curdoc

    from uam_studio.app.main import new_session

    doc = Document()
    with set_curdoc(doc):
        session = new_session()
    assert (session.served, session.compare, session.dispatch) == (False, "off", None)
    assert session.planner.compare == "off"
    closed = []
    session.cleanups.append(lambda: closed.append(True))
    for callback in list(doc.session_destroyed_callbacks):  # what the server does as it drops the document
        callback(None)
    assert closed == [True]


def test_a_notebook_session_compares_in_a_thread_and_is_closed_by_its_owner(monkeypatch):
    from uam_studio.app.main import new_session

    monkeypatch.delenv("UAM_STUDIO_COMPARE", raising=False)

    session = new_session()
    assert (session.served, session.compare, session.dispatch) == (False, "thread", None)
    session.planner.close()


def test_a_hidden_tab_changing_keeps_the_page_stylesheets_on_this_server():
    """A pane of a tab that is not shown (dynamic Tabs: its models are detached) changes during a
    session. Panel 1.9 alone rewrites the session's shared stylesheets to its CDN address, and the
    browser fetches them from there."""
    from panel.io.state import set_curdoc, state

    from uam_studio.app.panel_compat import keep_stylesheets_local

    keep_stylesheets_local()  # what create_app does
    doc = Document()
    doc._template_variables["dist_url"] = "static/extensions/panel/"  # what a Panel server sets on its page
    with set_curdoc(doc):
        hidden = pn.pane.Markdown("before")
        tabs = pn.Tabs(("Planner", pn.Column(hidden)), ("Fly", pn.pane.Markdown("fly")), dynamic=True)
        doc.add_root(tabs.get_root(doc))
        tabs.active = 1
        assert all(model.document is None for model, _ in hidden._models.values())  # detached
        hidden.object = "a comparison arrived"
    urls = [s.url for s in state._stylesheets[doc].values()]  # the session's shared stylesheet objects
    assert any("loading.css" in u for u in urls)
    assert not [u for u in urls if u.startswith("http")], urls


def test_the_glossary_defines_what_the_app_shows_and_is_a_tab():
    from uam_studio.app.main import TABS
    from uam_studio.glossary import GLOSSARY, glossary_markdown

    terms = " ".join(GLOSSARY)
    for word in ("EOD", "RTE", "PC1 / PC2", "Stars", "Min V", "Hindsight oracle", "q_max", "R0", "90% band"):
        assert word in terms, word
    assert all(text.strip() for text in GLOSSARY.values())
    build = dict(TABS)["Glossary"]
    pane = build(None)
    assert pane.object.count("**") == 2 * len(GLOSSARY) and glossary_markdown() in pane.object


def test_the_busy_mark_changes_its_content_only_never_the_layout():
    """Showing "planning..." beside "Plan" must not make the browser lay the page out again: the mark is a
    fixed-size pane whose visibility and size never change, only its content (a visibility change cost about
    300 ms a slider step in chromium; ``bench_app.py steps``)."""
    from uam_studio.app.planner.view import BUSY_WIDTH_PX

    state = PlannerState()
    view = PlannerView(state)
    mark = view.busy
    fixed = (mark.visible, mark.width, mark.height)
    assert "planning..." not in mark.object and "data-busy='false'" in mark.object
    state.busy = True
    view._show_busy()
    assert "planning..." in mark.object and "data-busy='true'" in mark.object
    assert "data-busy='true'" in view.summary.object
    state.busy = False
    assert "planning..." not in mark.object and "data-busy='false'" in view.summary.object
    assert (mark.visible, mark.width, mark.height) == fixed == (True, BUSY_WIDTH_PX, 22)
