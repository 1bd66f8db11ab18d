"""The Planner tab: edit a mission on a map and in a table, and see the plan update live.

View only: everything it shows comes from a :class:`~uam_studio.app.planner.state.PlannerState`. The plots are
plain Bokeh figures built once per view, whose sources each new state replaces; the map's destinations
are a Bokeh ``PointDrawTool`` on their own source. Map and table are linked both ways through the state (an edit in
either goes to :meth:`PlannerState.set_destinations`; an accepted or rejected edit re-sends the
state's destinations to both). Its plots come from :class:`~uam_studio.app.planner.plots.PlannerPlots`,
its summary and comparison panes from :mod:`~uam_studio.app.planner.summary`.
"""

from __future__ import annotations

import html
import io
from collections.abc import Callable
from typing import Any, cast

import numpy as np
import pandas as pd
import panel as pn
import param
from bokeh.core.validation import silence
from bokeh.core.validation.warnings import FIXED_SIZING_MODE

from uam_studio.app.planner.plots import WIDE_MIN_PX, PlannerPlots
from uam_studio.app.planner.state import PlannerState
from uam_studio.app.planner.summary import comparison_html, summary_html
from uam_studio.app.services import APP_EOD_RANGE, APP_Q_RANGE, APP_R0_RANGE
from uam_studio.app.session import (
    after_page,
    respond_at_once,
    session_dispatcher,
)
from uam_studio.app.style import NOTE_STYLE, busy_html, busy_mark, heading, same_plot_data
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning.missions.mission import COORD_RANGE_KM, SCENARIOS
from uam_studio.planning.planner import plan_csv  # its module: mypy reads uam_studio.planning's lazy names as object

# The map is sized by its frame (frame_width/frame_height, as HoloViews sets them); Bokeh's
# FIXED_SIZING_MODE check (W-1005) reads only width/height, and warned once for every session served.
silence(FIXED_SIZING_MODE, True)

COLUMNS = ["name", "x_km", "y_km", "priority", "wind_kts", "dwell_s"]
MAP_HALF_KM = 80.0


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


BUSY_AFTER_MS = 150  # served: a plan taking longer than this shows the busy state
BUSY_WIDTH_PX = 120
CONTROLS_WIDTH = 260
MAP_FRAME_PX = 440  # the map's square frame (data area)


class PlannerView(PlannerPlots, pn.viewable.Viewer):
    """Map, table, controls, plots, summary and planner comparison of a :class:`PlannerState`.

    Layout (a wrapping flex row, sized for 1366 px wide screens and up): the controls, the map with
    the table under it, the plan (summary, comparison, voltage against EOD) and the other plots
    (altitude per leg, health estimate), which wrap below on narrow screens and stand beside the
    plan on wide ones.
    """

    # a required argument of __init__: never None once built (param types it Optional, as it has no default)
    state = cast("param.ClassSelector[PlannerState]", param.ClassSelector(class_=PlannerState))

    def __init__(self, state: PlannerState, **params: Any) -> None:
        super().__init__(state=state, **params)
        s = state
        self._syncing = False
        self._busy_later = session_dispatcher(delay_ms=BUSY_AFTER_MS) or (lambda cb: cb())
        self._busy_shown = bool(s.busy)
        w = CONTROLS_WIDTH - 20
        self.scenario = pn.widgets.Select(name="Scenario", options=list(SCENARIOS), value=s.scenario, width=w)
        self.policy = pn.widgets.Select(name="Policy", options=dict(s.policy_objects), value=s.policy, width=w)
        self.q_max = pn.widgets.FloatSlider(name="q_max (C)", start=APP_Q_RANGE[0], end=APP_Q_RANGE[1], step=50,
                                            value=s.q_max, width=w)
        self.r0 = pn.widgets.FloatSlider(name="R0 (ohm)", start=APP_R0_RANGE[0], end=APP_R0_RANGE[1], step=0.001,
                                         value=s.r0, format="0.000", width=w)
        self.eod = pn.widgets.FloatSlider(name="EOD cut-off (V)", start=APP_EOD_RANGE[0], end=APP_EOD_RANGE[1],
                                          step=0.05, value=s.eod_v, format="0.00", width=w)
        self.return_wind = pn.widgets.FloatSlider(name="Wind home (kt, - = tail)",
                                                  start=WIND_RANGE_KTS[0], end=WIND_RANGE_KTS[1], step=1,
                                                  value=s.return_wind, width=w)
        self._inputs = {"scenario": self.scenario, "policy": self.policy, "q_max": self.q_max, "r0": self.r0,
                        "eod_v": self.eod, "return_wind": self.return_wind}
        for key, wd in self._inputs.items():
            wd.param.watch(lambda ev, key=key: self._on_widget(key, ev), "value")
        respond_at_once(self._inputs.values())
        s.param.watch(self._on_state_input, list(self._inputs))
        s.param.watch(self._on_policy_objects, "policy_objects")

        self.download = pn.widgets.FileDownload(callback=self._download, filename="mission.json",
                                                label="Save mission (JSON)", button_type="primary", width=w)
        self.download_plan = pn.widgets.FileDownload(callback=self._download_plan, filename="plan.csv",
                                                     label="Save the plan's voltage (CSV)", width=w,
                                                     css_classes=["uam-plan-csv"])
        self.upload = pn.widgets.FileInput(accept=".json,application/json", multiple=False, width=w,
                                           name="Load mission (JSON)")
        self.upload.param.watch(self._on_upload, "value")
        self.remove = pn.widgets.Button(name="Remove ticked rows", width=w)
        self.remove.on_click(self._on_remove)
        self.reset = pn.widgets.Button(name="Reset to the example", width=w)
        self.reset.on_click(lambda _ev: s.reset_example())
        self.error = pn.pane.Alert("", alert_type="danger", visible=False, css_classes=["uam-error"],
                                   sizing_mode="stretch_width", margin=(0, 10))
        self.notice = pn.pane.Alert("", alert_type="info", visible=False, css_classes=["uam-notice"],
                                    sizing_mode="stretch_width", margin=(0, 10))
        # A table edit that is not applied is explained beside the table, where the eye is.
        self.table_error = pn.pane.Alert("", alert_type="danger", visible=False, css_classes=["uam-table-error"],
                                         sizing_mode="stretch_width", margin=(0, 10))
        self._editing_table = False
        s.param.watch(self._on_error, ["error", "notice"])

        self.table = pn.widgets.Tabulator(
            self._frame(), show_index=False, selectable="checkbox", layout="fit_columns", height=230,
            widths={"name": 105, "x_km": 62, "y_km": 62, "priority": 88, "wind_kts": 84, "dwell_s": 84},
            configuration={"columnDefaults": {"headerSort": False}},
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

        self._sent: dict[str, Any] = {}  # last data drawn on each plot (unchanged data is not redrawn)
        self.map_fig = self._map_figure(MAP_HALF_KM, MAP_FRAME_PX)
        self.map_fig.css_classes = ["uam-map"]  # on the figure: the Bokeh pane's model is the figure
        self.map_fig.margin = (0, 5, 0, 5)
        self.altitude_fig = self._altitude_figure()
        self._sync_destinations()
        self._send("route", self._draw_route, self._route_data())
        self.map = pn.pane.Bokeh(self.map_fig)
        self.altitude_plot = pn.pane.Bokeh(self.altitude_fig)
        self.voltage_fig = self._voltage_figure()
        self._send("voltage", self._draw_voltage, self._voltage_data())
        self.voltage_fig.css_classes = ["uam-voltage"]  # on the figure: the Bokeh pane's model is the figure
        self.voltage_plot = pn.pane.Bokeh(self.voltage_fig, sizing_mode="stretch_width")
        self.health_fig = self._health_figure()
        self._send("health", self._draw_health, self._health_data())
        self.health_plot = pn.pane.Bokeh(self.health_fig)
        # The class sits on the content (inside the pane's shadow root), so that a locator for
        # ".uam-plan-summary" finds exactly one element whose text is the summary.
        self.summary = pn.pane.HTML(summary_html(s), sizing_mode="stretch_width", margin=(0, 10))
        self.compare = pn.pane.HTML(comparison_html(s), sizing_mode="stretch_width", margin=(0, 10))
        self.busy = busy_mark(bool(s.busy), BUSY_WIDTH_PX)  # its content alone changes: no new layout
        # onlychanged=False: param's own equality test walks every sample of a plan (tens of ms);
        # _send compares the plot data itself
        s.param.watch(self._on_plan, ["plan", "plan_error", "plan_request", "band", "takeoff"], onlychanged=False)
        s.param.watch(self._on_busy, "busy")
        s.param.watch(self._on_comparison, "comparison")
        s.param.watch(self._on_destinations, ["destinations", "vertiport_x_km", "vertiport_y_km"])

    # ------------------------------------------------------------------ layout

    def __panel__(self) -> pn.viewable.Viewable:
        w = CONTROLS_WIDTH - 20
        controls = pn.Column(
            heading("Mission"), self.scenario, self.policy, self.q_max, self.r0, self.eod, self.return_wind,
            heading("File"), self.download, self.download_plan, self.upload, self.remove, self.reset,
            pn.pane.Markdown("Mission files: the JSON that `uam-studio plan` reads.", width=w, styles=NOTE_STYLE),
            width=CONTROLS_WIDTH, css_classes=["uam-controls"],
        )
        hint = pn.pane.Markdown(
            "Destinations: edit names, priorities (stars), the wind on legs *to* each one (kt, negative = "
            "tailwind) and dwell times below; tick rows to remove them.", sizing_mode="stretch_width",
            styles=NOTE_STYLE, margin=(0, 10))
        # Served, the table and the plots that are not above the fold load right after the page: the
        # map, the summary, the comparison and the voltage come first.
        table, *extras = after_page([(self.table, dict(height=230, sizing_mode="stretch_width")),
                                     (self.altitude_plot, {}), (self.health_plot, {})])
        center = pn.Column(self.map, hint, self.table_error, table, width=MAP_FRAME_PX + 100,
                           css_classes=["uam-map-column"])
        results = pn.Column(pn.Row(heading("Plan"), self.busy), self.summary,
                            self.compare, self.voltage_plot, min_width=WIDE_MIN_PX, sizing_mode="stretch_width",
                            styles={"flex": f"1 1 {WIDE_MIN_PX}px"}, css_classes=["uam-results"])
        more = pn.FlexBox(*extras, flex_wrap="wrap", gap="10px", min_width=WIDE_MIN_PX,
                          sizing_mode="stretch_width", styles={"flex": f"1 1 {WIDE_MIN_PX}px"},
                          css_classes=["uam-more-plots"])
        body = pn.FlexBox(controls, center, results, more, flex_wrap="wrap", gap="10px",
                          sizing_mode="stretch_width", css_classes=["uam-planner"])
        return pn.Column(self.error, self.notice, body, sizing_mode="stretch_width")

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
            self._draw_points(df)
        finally:
            self._syncing = False

    def _on_destinations(self, *events: param.parameterized.Event) -> None:
        with pn.io.hold():
            self._sync_destinations()
            self._send("route", self._draw_route, self._route_data())

    def _on_plan(self, *events: param.parameterized.Event) -> None:
        with pn.io.hold():  # one batch of model changes per plan: each costs the browser a page layout
            self.summary.object = summary_html(self.state)
            self.compare.object = comparison_html(self.state)  # the bold row follows the policy
            self._send("route", self._draw_route, self._route_data())
            self._send("voltage", self._draw_voltage, self._voltage_data())
            self._send("health", self._draw_health, self._health_data())

    def _draw_route(self, data: dict[str, list]) -> None:
        """A route on the map and in the altitude figure."""
        self._draw_map_route(data)
        self._draw_altitude(data)

    def _on_comparison(self, event: param.parameterized.Event) -> None:
        self.compare.object = comparison_html(self.state)

    def _send(self, key: str, draw: Callable[[Any], None], data: Any) -> None:
        """Draw ``data`` with ``draw`` (a figure's ``_draw_*`` method) unless it equals the last data
        drawn under ``key`` (comparing is cheaper than redrawing)."""
        if key in self._sent and same_plot_data(self._sent[key], data):
            return
        self._sent[key] = data
        draw(data)

    def _on_busy(self, event: param.parameterized.Event) -> None:
        """Served, the busy state is shown only once a plan has taken :data:`BUSY_AFTER_MS`: every
        change sent to the browser costs it a page layout, which a fast plan would otherwise pay twice."""
        if event.new:
            self._busy_later(self._show_busy)
        elif self._busy_shown:
            self._busy_shown = False
            self.summary.object = summary_html(self.state)  # data-busy
            self.busy.object = busy_html(False)  # no idle ring beside "Plan"

    def _show_busy(self) -> None:
        if self.state.busy and not self._busy_shown:
            self._busy_shown = True
            self.summary.object = summary_html(self.state)  # data-busy
            self.busy.object = busy_html(True)

    def _on_error(self, *events: param.parameterized.Event) -> None:
        s = self.state
        text = f"**Not applied.** {html.escape(s.error)}" if s.error else ""
        at_table = bool(s.error) and self._editing_table
        self.table_error.object, self.table_error.visible = (text, True) if at_table else ("", False)
        self.error.object = "" if at_table else text
        self.error.visible = bool(s.error) and not at_table
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
        self._editing_table = True
        try:
            applied = self.state.set_destinations(rows)
        finally:
            self._editing_table = False
        if not applied:
            self._sync_destinations()

    def _on_points_edit(self, _attr: str, _old: Any, new: dict[str, Any]) -> None:
        """The map's point-drawing tool changed the destinations' points (added, dragged, deleted)."""
        self._on_draw(dict(new))

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

    def _file_stem(self) -> str:
        """The mission's name as a file name's stem (letters, digits, ``-`` and ``_``)."""
        return "".join(c if c.isalnum() or c in "-_" else "_" for c in self.state.mission_name) or "mission"

    def _download(self) -> io.StringIO:
        self.download.filename = f"{self._file_stem()}.json"
        return io.StringIO(self.state.to_json())

    def _download_plan(self) -> io.StringIO:
        """The shown plan's voltage series as CSV (:func:`~uam_studio.planning.plan_csv`)."""
        self.download_plan.filename = f"{self._file_stem()}_plan.csv"
        return io.StringIO(plan_csv(self.state.plan) if self.state.plan else "")
