"""The Planner tab: edit a mission on a map and in a table, and see the plan update live.

View only: everything it shows comes from a :class:`~uam_studio.app.state.PlannerState`. The map's
destinations are a :class:`holoviews.streams.PointDraw` on a DynamicMap fed by a
:class:`~holoviews.streams.Pipe`; map and table are linked both ways through the state (an edit in
either goes to :meth:`PlannerState.set_destinations`; an accepted or rejected edit re-sends the
state's destinations to both).
"""

from __future__ import annotations

import html
import io
from typing import Any

import holoviews as hv
import numpy as np
import pandas as pd
import panel as pn
import param

from uam_studio.app.session import ensure_bokeh_backend, in_server_session
from uam_studio.app.state import APP_EOD_RANGE, APP_Q_RANGE, APP_R0_RANGE, PlannerState, population
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning.missions.mission import COORD_RANGE_KM, SCENARIOS, VERTIPORT

CYCLE_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22")
FAILED_COLOR = "#d62728"
COLUMNS = ["name", "x_km", "y_km", "priority", "wind_kts", "dwell_s"]
MAP_HALF_KM = 80.0


def cycle_color(k: int) -> str:
    """Colour of charging cycle ``k`` (1-based)."""
    return CYCLE_COLORS[(k - 1) % len(CYCLE_COLORS)]


# ----------------------------------------------------------------------------- pure helpers


LEG_COLUMNS = ("leg", "from", "to", "x0", "y0", "x1", "y1", "altitude_m", "cycle", "color", "completed", "label")


def route_legs(plan: dict[str, Any] | None, state_rows: list[dict[str, Any]], vertiport: tuple[float, float]) \
        -> dict[str, list]:
    """The legs of ``plan`` as columns (one entry per leg): from/to names and coordinates, altitude,
    charging cycle (1-based), colour, whether it was completed (physics check) and a label."""
    out: dict[str, list] = {c: [] for c in LEG_COLUMNS}
    if not plan or not plan.get("route"):
        return out
    pos = {r["name"]: (r["x_km"], r["y_km"]) for r in state_rows}
    pos[VERTIPORT] = vertiport
    reached = set(plan.get("reached", []))
    prev, cycle, failed = VERTIPORT, 1, False
    for i, (to, alt) in enumerate(zip(plan["route"], plan["altitudes_m"]), 1):
        if to not in pos:  # the mission changed under this plan; draw what is known
            break
        if not failed and to != VERTIPORT and to not in reached:
            failed = True
        if not failed and to == VERTIPORT and i == len(plan["route"]) and not plan.get("safe", True):
            failed = True
        (x0, y0), (x1, y1) = pos[prev], pos[to]
        row = {"leg": f"{i}: {'V' if prev == VERTIPORT else prev}\u2192{'V' if to == VERTIPORT else to}",
               "from": prev, "to": to, "x0": x0, "y0": y0, "x1": x1, "y1": y1, "altitude_m": float(alt),
               "cycle": cycle, "color": FAILED_COLOR if failed else cycle_color(cycle),
               "completed": not failed, "label": f"{alt:g} m"}
        for c in LEG_COLUMNS:
            out[c].append(row[c])
        if to == VERTIPORT:
            cycle += 1
        prev = to
    return out


def _equal(a: Any, b: Any) -> bool:
    """Deep equality of plot data (dicts, lists, tuples, arrays, numbers)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple, np.ndarray)) and isinstance(b, (list, tuple, np.ndarray)):
        if len(a) != len(b):
            return False
        if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
            x, y = np.asarray(a), np.asarray(b)
            return x.shape == y.shape and x.dtype == y.dtype and bool(np.array_equal(x, y))
        return all(_equal(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and a == b


def _same_frame(a: pd.DataFrame, b: pd.DataFrame) -> bool:
    """Same rows and values (numbers compared as floats)."""
    if list(a.columns) != list(b.columns) or len(a) != len(b):
        return False
    for c in a.columns:
        x, y = a[c].tolist(), b[c].tolist()
        if c == "name":
            if x != y:
                return False
        elif not np.allclose(np.asarray(x, float), np.asarray(y, float), equal_nan=True):
            return False
    return True


def _fmt_v(x: float | None) -> str:
    return "-" if x is None else f"{x:.3f} V"


def summary_html(state: PlannerState) -> str:
    """The summary pane (``<div class="uam-plan-summary">``): route (names), altitudes, minimum
    predicted and physics voltage, margin to EOD, safety, and the planner's notes.

    Attributes: ``data-busy`` ("true" while a newer plan is being computed) and ``data-inputs``
    (:func:`request_digest` of the request the shown plan was computed for)."""
    req = state.plan_request
    inputs = "" if req is None else request_digest(req)
    return (f"<div class='uam-plan-summary' data-busy='{str(bool(state.busy)).lower()}' "
            f"data-inputs='{html.escape(inputs, quote=True)}'>{_summary_body(state)}</div>")


def request_digest(req: Any) -> str:
    """What a plan was computed for, compactly (the summary's ``data-inputs`` attribute): policy,
    scenario, cell, EOD, return wind and ``name:priority:wind`` of each destination. Lets a test or a
    script wait for the plan of a given edit."""
    m = req.mission
    dests = "|".join(f"{d.name}:{d.priority}:{d.wind_kts:g}" for d in m.destinations)
    return (f"{req.policy};{m.scenario};q_max={m.battery.q_max:g};r0={m.battery.r0:g};eod={m.eod_v:g};"
            f"return_wind={m.vertiport.wind_kts:g};{dests}")


def _summary_body(state: PlannerState) -> str:
    plan, req = state.plan, state.plan_request
    e = html.escape
    if state.plan_error:
        return f"<p class='uam-plan-error'><b>Planning error:</b> {e(state.plan_error)}</p>"
    if plan is None or req is None:
        return "<p>planning...</p>"
    eod = req.mission.eod_v
    label = state.policy_objects.get(req.policy, req.policy) if req.policy.startswith("agent:") else plan["policy"]
    parts = [f"<p><b>Policy:</b> {e(label)} &middot; <b>scenario:</b> {e(req.mission.scenario)} &middot; "
             f"q_max {req.mission.battery.q_max:g} C, R0 {req.mission.battery.r0:g} ohm, EOD {eod:g} V</p>"]
    if plan["route"]:
        legs = []
        cycle = 1
        for to, alt in zip(plan["route"], plan["altitudes_m"]):
            legs.append(f"<span style='color:{cycle_color(cycle)}'>{e(to)}</span> ({alt:g} m)")
            if to == VERTIPORT:
                cycle += 1
        parts.append("<p class='uam-route'><b>Route:</b> vertiport &rarr; " + " &rarr; ".join(legs) + "</p>")
        parts.append("<p><b>Altitudes:</b> " + ", ".join(f"{a:g}" for a in plan["altitudes_m"]) + " m</p>")
    else:
        parts.append("<p class='uam-route'><b>Route:</b> none (nothing is flown)</p>")
    pred = plan.get("predicted")
    vmin_pred = min(pred["voltage_v"]) if pred and pred.get("voltage_v") else None
    vmin = plan.get("min_voltage_v")
    parts.append(f"<p><b>Min predicted voltage:</b> {_fmt_v(vmin_pred)} (Dynaformer) &middot; "
                 f"<b>physics:</b> {_fmt_v(vmin)}</p>")
    if plan["route"]:
        margin = None if vmin is None else vmin - eod
        mp = None if vmin_pred is None else vmin_pred - eod
        parts.append(f"<p><b>Margin to EOD ({eod:g} V):</b> {'-' if margin is None else f'{margin:+.3f} V'} "
                     f"(physics), {'-' if mp is None else f'{mp:+.3f} V'} (predicted)</p>")
        safe = "yes" if plan["safe"] else f"NO (end of discharge at {plan['physics'].get('eod_s') or 0:.0f} s)"
        parts.append(f"<p><b>Safe:</b> {safe} &middot; <b>charging cycles:</b> {plan['charging_cycles']} "
                     f"&middot; <b>reached:</b> {len(plan['reached'])} of {len(req.mission.destinations)} "
                     f"(priority {plan['reached_priority']})</p>")
    if plan.get("messages"):
        parts.append("<ul class='uam-notes'>" + "".join(f"<li>{e(m)}</li>" for m in plan["messages"]) + "</ul>")
    return "\n".join(parts)


# ----------------------------------------------------------------------------- the view


class PlannerView(pn.viewable.Viewer):
    """Map, table, controls, plots and summary of a :class:`PlannerState`."""

    state = param.ClassSelector(class_=PlannerState)

    def __init__(self, state: PlannerState, **params: Any) -> None:
        ensure_bokeh_backend()
        super().__init__(state=state, **params)
        s = state
        self._syncing = False
        self.scenario = pn.widgets.Select(name="Scenario", options=list(SCENARIOS), value=s.scenario, width=280)
        self.policy = pn.widgets.Select(name="Policy", options=dict(s.policy_objects), value=s.policy, width=280)
        self.q_max = pn.widgets.FloatSlider(name="q_max (C)", start=APP_Q_RANGE[0], end=APP_Q_RANGE[1], step=50,
                                            value=s.q_max, width=280)
        self.r0 = pn.widgets.FloatSlider(name="R0 (ohm)", start=APP_R0_RANGE[0], end=APP_R0_RANGE[1], step=0.001,
                                         value=s.r0, format="0.000", width=280)
        self.eod = pn.widgets.FloatSlider(name="EOD cut-off (V)", start=APP_EOD_RANGE[0], end=APP_EOD_RANGE[1],
                                          step=0.05, value=s.eod_v, format="0.00", width=280)
        self.return_wind = pn.widgets.FloatSlider(name="Wind on return legs (kt, negative = tailwind)",
                                                  start=WIND_RANGE_KTS[0], end=WIND_RANGE_KTS[1], step=1,
                                                  value=s.return_wind, width=280)
        self._inputs = {"scenario": self.scenario, "policy": self.policy, "q_max": self.q_max, "r0": self.r0,
                        "eod_v": self.eod, "return_wind": self.return_wind}
        for key, w in self._inputs.items():
            w.param.watch(lambda ev, key=key: self._on_widget(key, ev), "value")
        s.param.watch(self._on_state_input, list(self._inputs))
        s.param.watch(self._on_policy_objects, "policy_objects")

        self.download = pn.widgets.FileDownload(callback=self._download, filename="mission.json",
                                                label="Save mission (JSON)", button_type="primary", width=280)
        self.upload = pn.widgets.FileInput(accept=".json,application/json", multiple=False, width=280,
                                           name="Load mission (JSON)")
        self.upload.param.watch(self._on_upload, "value")
        self.remove = pn.widgets.Button(name="Remove selected rows", width=135)
        self.remove.on_click(self._on_remove)
        self.reset = pn.widgets.Button(name="Reset to example", width=135)
        self.reset.on_click(lambda _ev: s.reset_example())
        self.error = pn.pane.Alert("", alert_type="danger", visible=False, css_classes=["uam-error"],
                                   sizing_mode="stretch_width")
        self.notice = pn.pane.Alert("", alert_type="info", visible=False, css_classes=["uam-notice"],
                                    sizing_mode="stretch_width")
        s.param.watch(self._on_error, ["error", "notice"])

        self.table = pn.widgets.Tabulator(
            self._frame(), show_index=False, selectable="checkbox", layout="fit_data_fill", height=260,
            editors={"name": {"type": "input"},
                     "x_km": {"type": "number", "min": COORD_RANGE_KM[0], "max": COORD_RANGE_KM[1], "step": 0.1},
                     "y_km": {"type": "number", "min": COORD_RANGE_KM[0], "max": COORD_RANGE_KM[1], "step": 0.1},
                     "priority": {"type": "star", "stars": 3},
                     "wind_kts": {"type": "number", "min": WIND_RANGE_KTS[0], "max": WIND_RANGE_KTS[1], "step": 1},
                     "dwell_s": {"type": "number", "min": 0, "step": 60}},
            formatters={"priority": {"type": "star", "stars": 3}},
            titles={"name": "Name", "x_km": "x km", "y_km": "y km", "priority": "Priority",
                    "wind_kts": "Wind kt", "dwell_s": "Dwell s"},
            css_classes=["uam-destinations"], sizing_mode="stretch_width",
        )
        self.table.on_edit(self._on_table_edit)

        self._points_pipe = hv.streams.Pipe(data=self._frame())
        self._route_pipe = hv.streams.Pipe(data=self._route_data())
        self._voltage_pipe = hv.streams.Pipe(data=self._voltage_data())
        self._health_pipe = hv.streams.Pipe(data=self._health_data())
        self._sent: dict[str, Any] = {}  # last data sent on each pipe (unchanged data is not re-sent)
        points = hv.DynamicMap(self._points_element, streams=[self._points_pipe])
        self._draw = hv.streams.PointDraw(source=points, drag=True, add=True, empty_value=0,
                                          tooltip="Click to add a destination, drag to move, select + Backspace "
                                                  "to delete")
        self._draw.add_subscriber(self._on_draw)
        route = hv.DynamicMap(self._route_element, streams=[self._route_pipe])
        names = hv.DynamicMap(self._names_element, streams=[self._points_pipe])
        h = MAP_HALF_KM
        self.map = pn.pane.HoloViews((route * names * points).opts(
            hv.opts.Overlay(frame_width=500, frame_height=460, title="Map (km); route colour = charging cycle",
                            show_grid=True, xlim=(-h, h), ylim=(-h, h), xlabel="x (km)", ylabel="y (km)")),
            css_classes=["uam-map"], linked_axes=False)
        self.altitude_plot = pn.pane.HoloViews(
            hv.DynamicMap(self._altitude_element, streams=[self._route_pipe]), linked_axes=False)
        self.voltage_plot = pn.pane.HoloViews(
            hv.DynamicMap(self._voltage_element, streams=[self._voltage_pipe]), linked_axes=False)
        self.health_plot = pn.pane.HoloViews(self._population_element() * hv.DynamicMap(
            self._health_element, streams=[self._health_pipe]), linked_axes=False)
        # The class sits on the content (inside the pane's shadow root), so that a locator for
        # ".uam-plan-summary" finds exactly one element whose text is the summary.
        self.summary = pn.pane.HTML(summary_html(s), sizing_mode="stretch_width", min_height=160)
        self.busy = pn.indicators.LoadingSpinner(value=s.busy, size=20, name="planning..." if s.busy else "",
                                                 css_classes=["uam-busy"])
        s.param.watch(self._on_plan, ["plan", "plan_error", "plan_request"])
        s.param.watch(self._on_busy, "busy")
        s.param.watch(self._on_destinations, ["destinations", "vertiport_x_km", "vertiport_y_km"])

    # ------------------------------------------------------------------ layout

    def __panel__(self) -> pn.viewable.Viewable:
        controls = pn.Column(
            "### Mission", self.scenario, self.policy, self.q_max, self.r0, self.eod, self.return_wind,
            "### File", self.download, pn.pane.Markdown("Load a mission (JSON, as `uam-studio plan` reads):"),
            self.upload, pn.Row(self.remove, self.reset), width=310,
        )
        center = pn.Column(
            pn.pane.Markdown("Click the map to add a destination, drag to move it, select it and press "
                             "Backspace to delete it. Edit names, priorities (stars), the wind on legs *to* "
                             "each destination (kt, negative = tailwind) and dwell times in the table."),
            self.map, self.table, width=620,
        )
        # Served, the plots below the summary load right after the page (defer_load): the map, the table
        # and the summary come first.
        plots = (self.voltage_plot, self.altitude_plot, self.health_plot)
        deferred = [pn.panel(lambda p=p: p, defer_load=True) for p in plots] if in_server_session() else plots
        results = pn.Column(pn.Row("### Plan", self.busy), self.summary, *deferred, width=520)
        return pn.Column(self.error, self.notice, pn.Row(controls, center, results))

    # ------------------------------------------------------------------ state -> views

    def _frame(self) -> pd.DataFrame:
        return pd.DataFrame(self.state.destination_rows(), columns=COLUMNS)

    def _on_state_input(self, *events: param.parameterized.Event) -> None:
        self._syncing = True
        try:
            for ev in events:
                w = self._inputs[ev.name]
                if w.value != ev.new:
                    w.value = ev.new
        finally:
            self._syncing = False

    def _on_policy_objects(self, event: param.parameterized.Event) -> None:
        self._syncing = True
        try:
            self.policy.options = dict(event.new)
            self.policy.value = self.state.policy
        finally:
            self._syncing = False

    def _sync_destinations(self) -> None:
        """Send the state's destinations to the table and the map (after any edit, accepted or not)."""
        df = self._frame()
        self._syncing = True
        try:
            if not _same_frame(self.table.value, df):
                self.table.value = df
            self._points_pipe.send(df)
        finally:
            self._syncing = False

    def _on_destinations(self, *events: param.parameterized.Event) -> None:
        with pn.io.hold():
            self._sync_destinations()
            self._send("route", self._route_pipe, self._route_data())

    def _on_plan(self, *events: param.parameterized.Event) -> None:
        with pn.io.hold():  # one batch of model changes per plan
            self.summary.object = summary_html(self.state)
            self._send("route", self._route_pipe, self._route_data())
            self._send("voltage", self._voltage_pipe, self._voltage_data())
            self._send("health", self._health_pipe, self._health_data())

    def _send(self, key: str, pipe: hv.streams.Pipe, data: Any) -> None:
        """Send ``data`` on ``pipe`` unless it equals the last data sent there (re-rendering a plot
        costs tens of ms)."""
        if key in self._sent and _equal(self._sent[key], data):
            return
        self._sent[key] = data
        pipe.send(data)

    def _on_busy(self, event: param.parameterized.Event) -> None:
        self.summary.object = summary_html(self.state)  # data-busy
        self.busy.value = bool(event.new)
        self.busy.name = "planning..." if event.new else ""

    def _on_error(self, *events: param.parameterized.Event) -> None:
        s = self.state
        self.error.object = f"**Not applied.** {html.escape(s.error)}" if s.error else ""
        self.error.visible = bool(s.error)
        self.notice.object = html.escape(s.notice)
        self.notice.visible = bool(s.notice) and not s.error

    # ------------------------------------------------------------------ views -> state

    def _on_widget(self, key: str, event: param.parameterized.Event) -> None:
        if self._syncing:
            return
        self.state.notice = ""
        if not self.state.apply(**{key: event.new}):
            self._syncing = True
            try:
                event.obj.value = getattr(self.state, key)
            finally:
                self._syncing = False

    def _on_table_edit(self, event: Any) -> None:
        if self._syncing:
            return
        # Apply the edit itself to the state's rows: the table's own value may be patched after
        # this event arrives, so it is not read here. Rows are indexed as the state orders them.
        rows = self.state.destination_rows()
        i = int(event.row)
        if event.column not in COLUMNS or not 0 <= i < len(rows):
            self._sync_destinations()
            return
        value = event.value
        if hasattr(value, "item"):  # numpy scalar from the frame
            value = value.item()
        rows[i][event.column] = value
        self.state.notice = ""
        if not self.state.set_destinations(rows):
            self._sync_destinations()

    def _on_draw(self, data: dict[str, list] | None = None, **_: Any) -> None:
        if self._syncing or not data:
            return
        n = len(data.get("x_km", []))
        rows = [{c: (data[c][i] if c in data and i < len(data[c]) else None) for c in COLUMNS} for i in range(n)]
        self.state.notice = ""
        if not self.state.set_destinations(rows):
            self._sync_destinations()
        elif len(rows) != len(self.table.value) or any(r["name"] in (None, 0, "") for r in rows):
            self._sync_destinations()  # new points got names and priorities: show them on both views

    def _on_remove(self, _event: Any) -> None:
        sel = set(self.table.selection)
        if not sel:
            self.state.error = "destinations: select rows in the table first (checkbox column)"
            return
        rows = [r for i, r in enumerate(self.state.destination_rows()) if i not in sel]
        self.state.notice = ""
        if not self.state.set_destinations(rows):
            self._sync_destinations()

    def _on_upload(self, event: param.parameterized.Event) -> None:
        if event.new is None:
            return
        self.state.notice = ""
        self.state.load_json(event.new, self.upload.filename)

    def _download(self) -> io.StringIO:
        name = "".join(c if c.isalnum() or c in "-_" else "_" for c in self.state.mission_name) or "mission"
        self.download.filename = f"{name}.json"
        return io.StringIO(self.state.to_json())

    # ------------------------------------------------------------------ plots

    def _route_data(self) -> dict[str, list]:
        s = self.state
        return route_legs(s.plan, s.destination_rows(), (s.vertiport_x_km, s.vertiport_y_km))

    @staticmethod
    def _points_element(data: pd.DataFrame) -> hv.Points:
        return hv.Points(data, kdims=["x_km", "y_km"], vdims=["name", "priority", "wind_kts", "dwell_s"]).opts(
            size=14, color="#444444", line_color="white", line_width=2, tools=["hover"],
            active_tools=["point_draw", "wheel_zoom"],
        )

    def _names_element(self, data: pd.DataFrame) -> hv.Overlay:
        s = self.state
        rows = s.destination_rows()
        names = hv.Labels({"x": [r["x_km"] for r in rows], "y": [r["y_km"] + 3.5 for r in rows],
                           "text": [f"{r['name']} {'*' * int(r['priority'])}" for r in rows]},
                          kdims=["x", "y"], vdims="text").opts(text_font_size="9pt", text_font_style="bold",
                                                               text_color="#222222")
        vp = hv.Points([(s.vertiport_x_km, s.vertiport_y_km)], kdims=["x_km", "y_km"]).opts(
            marker="square", size=16, color="#d62728")
        vp_label = hv.Labels([(s.vertiport_x_km, s.vertiport_y_km - 5.0, "vertiport")], kdims=["x", "y"],
                             vdims="text").opts(text_font_size="9pt", text_color="#d62728")
        return names * vp * vp_label

    @staticmethod
    def _route_element(data: dict[str, list]) -> hv.Overlay:
        done = np.asarray(data["completed"], dtype=bool)
        cols = ("x0", "y0", "x1", "y1", "color", "leg", "altitude_m")

        def pick(mask: np.ndarray) -> dict[str, Any]:
            return {c: [v for v, k in zip(data[c], mask) if k] for c in cols}

        seg_kw = dict(kdims=["x0", "y0", "x1", "y1"], vdims=["color", "leg", "altitude_m"])
        legs = hv.Segments(pick(done), **seg_kw).opts(color="color", line_width=4, alpha=0.85, tools=["hover"])
        lost = hv.Segments(pick(~done), **seg_kw).opts(color=FAILED_COLOR, line_width=3, line_dash="dashed")
        x0, y0, x1, y1 = (np.asarray(data[c], dtype=float) for c in ("x0", "y0", "x1", "y1"))
        alt_labels = hv.Labels({"x": (x0 + x1) / 2, "y": (y0 + y1) / 2, "text": list(data["label"])},
                               kdims=["x", "y"], vdims="text").opts(text_font_size="8pt", text_color="#333333")
        return legs * lost * alt_labels

    @staticmethod
    def _altitude_element(data: dict[str, list]) -> hv.Overlay:
        # Numeric x (leg number) with tick labels: categorical axes do not survive empty -> full updates.
        n = len(data["leg"])
        idx = np.arange(1, n + 1, dtype=float)
        alt = np.asarray(data["altitude_m"], dtype=float)
        bars = hv.Rectangles({"x0": idx - 0.38, "y0": np.zeros(n), "x1": idx + 0.38, "y1": alt,
                              "color": list(data["color"]), "leg": list(data["leg"]), "altitude_m": alt},
                             kdims=["x0", "y0", "x1", "y1"], vdims=["color", "leg", "altitude_m"]).opts(
            color="color", line_color="white", tools=["hover"])
        labels = hv.Labels({"x": idx, "y": alt + 120, "text": [f"{a:g}" for a in alt]},
                           kdims=["x", "y"], vdims="text").opts(text_font_size="8pt", text_color="#222222")
        ticks = [(float(i), str(lbl)) for i, lbl in zip(idx, data["leg"])] if n else [(1.0, "")]
        return (bars * labels).opts(
            hv.opts.Rectangles(xticks=ticks, xrotation=30, xlim=(0.4, max(n, 1) + 0.6), ylim=(0, 3300),
                               xlabel="", ylabel="altitude (m)", framewise=True),
            hv.opts.Labels(framewise=True),
        ).opts(width=500, height=240, title="Cruise altitude per leg (colour = charging cycle)")

    def _voltage_data(self) -> dict[str, Any]:
        s = self.state
        plan = s.plan or {}
        phys = plan.get("physics") or {"time_s": [], "voltage_v": []}
        pred = plan.get("predicted") or {"time_s": [], "voltage_v": []}
        eod = s.plan_request.mission.eod_v if s.plan_request is not None else s.eod_v
        return {"physics": (np.asarray(phys["time_s"], float) / 60.0, np.asarray(phys["voltage_v"], float)),
                "predicted": (np.asarray(pred["time_s"], float) / 60.0, np.asarray(pred["voltage_v"], float)),
                "eod": eod}

    @staticmethod
    def _voltage_element(data: dict[str, Any]) -> hv.Overlay:
        t, v = data["physics"]
        tp, vp = data["predicted"]
        phys = hv.Curve((t, v), "time (min)", "voltage (V)", label="physics").opts(
            color="#1f77b4", line_width=2, framewise=True)
        pred = hv.Curve((tp, vp), "time (min)", "voltage (V)", label="Dynaformer").opts(
            color="#ff7f0e", line_width=2, line_dash="dashed", framewise=True)
        eod = hv.HLine(data["eod"], label="EOD").opts(color=FAILED_COLOR, line_width=1.5)
        return (phys * pred * eod).opts(width=500, height=250, title="Voltage: predicted vs physics",
                                        legend_position="right", show_grid=True)

    def _health_data(self) -> tuple[float, float] | None:
        return self.state.health

    @staticmethod
    def _population_element() -> hv.Points:
        pop = population()
        if pop is None:
            df = pd.DataFrame({"PC1": [], "PC2": [], "R0 (ohm)": [], "q_max (C)": []})
        else:
            df = pd.DataFrame({"PC1": pop.pc1, "PC2": pop.pc2, "R0 (ohm)": pop.r0, "q_max (C)": pop.q_max})
        return hv.Points(df, ["PC1", "PC2"], ["R0 (ohm)", "q_max (C)"], label="training population").opts(
            color="R0 (ohm)", cmap="viridis", colorbar=True, size=5, alpha=0.6, tools=["hover"],
            width=500, height=280, title="Health estimate (Dynaformer PCs) vs population", show_grid=True)

    @staticmethod
    def _health_element(data: tuple[float, float] | None) -> hv.Points:
        pts = [] if data is None else [tuple(data)]
        return hv.Points(pts, ["PC1", "PC2"], label="this cell").opts(
            color="#d62728", marker="star", size=22, line_color="black")
