"""The Fly tab: the Planner's mission flown in a world the operator cannot see, played back.

The aircraft moves along the flown route on the map; the voltage plot shows the sensor's readings up
to the playback time against the operator's prediction, the world's hidden truth and the EOD line,
with every decision marked; the log lists the decisions made so far with their reasons. Controls:
world seed, forecast error, sensor noise, playback speed, and a wind change injected at the playback
time. Everything comes from :class:`~uam_studio.app.fly.state.FlyState`; this view only draws it.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from typing import Any, cast

import numpy as np
import pandas as pd
import panel as pn
import param
from bokeh.models import ColumnDataSource, HoverTool, Range1d
from bokeh.models.annotations import Span  # = bokeh.models.Span, a re-export mypy misses (its stubs lack __all__)

from uam_studio.app.fly.many import ManyFlightsView
from uam_studio.app.fly.state import PACKS, RISKS, SPEEDS, WORLD_LABELS, FlyState
from uam_studio.app.planner.map_geometry import altitude_labels, place_label
from uam_studio.app.style import (
    MEASURED_COLOR,
    NAME_OFFSET_PX,
    PHYSICS_COLOR,
    PREDICTED_COLOR,
    busy_html,
    busy_mark,
    derived_looks,
    legend_above,
    page_figure,
    same_plot_data,
    window_height,
)
from uam_studio.planning import VERTIPORT, Mission
from uam_studio.planning.operations import record_csv

TICK_MS = 250
MAP_PX = 400
# The decision log takes the window's height left below the figures (about 600 px down), at least 300 px.
LOG_HEIGHT_CSS = "max(300px, calc(100vh - 600px))"
EOD_COLOR = "#d62728"
EVENT_COLOR = "#e377c2"  # injected wind changes
# The voltage figure's series: (the record's key, legend label, style); colours as the Planner's.
VOLTAGE_SERIES = (
    ("predicted", "predicted (operator)", {"color": PREDICTED_COLOR, "line_dash": "dashed", "line_width": 2}),
    ("true", "true (hidden)", {"color": PHYSICS_COLOR, "line_width": 2}),
    ("measured", "measured", {"color": MEASURED_COLOR, "line_width": 1, "alpha": 0.8}),
)


def _leg_labels(path: list[tuple[float, float]], altitudes_m: list[float], mission: Mission) -> dict[str, list]:
    """A label ``"#k altitude m"`` beside each leg of ``path`` (km; the last point is the aircraft, so
    the leg it flies is labelled from its take-off on), placed as the Planner's map places them
    (:func:`~uam_studio.app.planner.map_geometry.altitude_labels`: clear of the places, their names and each
    other)."""
    legs: dict[str, list] = {c: [] for c in ("from", "to", "altitude_m", "x0", "y0", "x1", "y1")}
    for k, ((x0, y0), (x1, y1)) in enumerate(zip(path, path[1:])):
        if k < len(altitudes_m) and (x0, y0) != (x1, y1):
            for c, v in zip(legs, (f"{x0:.3f},{y0:.3f}", f"leg {k}", altitudes_m[k], x0, y0, x1, y1)):
                legs[c].append(v)
    nodes = [(d.x_km, d.y_km) for d in mission.destinations]
    names = [place_label(d.name, d.priority) for d in mission.destinations]
    # altitude_labels numbers the legs it is given from #1: here every leg flown so far, in order
    return altitude_labels(legs, [(mission.vertiport.x_km, mission.vertiport.y_km), *nodes], ["", *names])


FLYING = "flying..."  # the busy mark's label while a flight is computed


def _replace(source: ColumnDataSource, data: dict[str, Any]) -> None:
    """Set ``source.data`` to ``data`` unless it holds the same columns already
    (:func:`~uam_studio.app.style.same_plot_data`): a flight's completion, or a wind change's, would otherwise send
    every source of the part already shown (11 of them)."""
    if not same_plot_data(dict(source.data), data):
        source.data = data


def _held(action: Callable[[], None]) -> None:
    """``action()``, its changes (the busy mark, the status) sent to the browser as one batch."""
    with pn.io.hold():
        action()


class FlyView(pn.viewable.Viewer):
    """Controls, map, voltage plot and decision log of a :class:`FlyState`."""

    # a required argument of __init__: never None once built (param types it Optional, as it has no default)
    state = cast("param.ClassSelector[FlyState]", param.ClassSelector(class_=FlyState))

    def __init__(self, state: FlyState, **params: Any) -> None:
        super().__init__(state=state, **params)
        s = self.state
        w = 200
        self.fly_button = pn.widgets.Button(name="Fly the mission", button_type="primary", width=w)
        self.play = pn.widgets.Toggle(name="Play / pause", value=s.playing, width=w)
        self.speed = pn.widgets.Select(name="Playback speed (x)", options=list(SPEEDS), value=s.speed, width=w)
        self.seed = pn.widgets.IntInput(name="World seed", value=s.seed, start=0, width=w)
        self.world = pn.widgets.Select(name="The world", options=list(WORLD_LABELS), value=s.world, width=w,
                                       css_classes=["uam-fly-world"])
        self.pack = pn.widgets.Select(name="The aircraft's pack", options=list(PACKS), value=s.pack, width=w,
                                      css_classes=["uam-fly-pack"])
        self.sigma = pn.widgets.FloatSlider(name="Forecast error (kt, std)", start=0, end=40, step=1,
                                            value=s.forecast_sigma_kt, width=w)
        self.noise = pn.widgets.FloatSlider(name="Voltage sensor noise (mV)", start=0, end=20, step=0.5,
                                            value=s.sensor_noise_mv, width=w)
        self.risk = pn.widgets.Select(name="Declared risk (its cautions follow)", options=list(RISKS), value=s.risk,
                                      width=w, css_classes=["uam-fly-risk"])
        self.reserve = pn.widgets.FloatSlider(name="Weather reserve (kt)", start=0, end=40, step=0.5,
                                              value=s.reserve_kt, width=w, format="0.0")
        self.inject_kts = pn.widgets.FloatSlider(name="Wind change (kt, + = headwind)", start=-40, end=40, step=5,
                                                 value=s.inject_kts, width=w)
        self.inject_button = pn.widgets.Button(name="Inject wind change now", button_type="warning", width=w)
        self.clear_button = pn.widgets.Button(name="Clear wind changes", width=w)
        self.download = pn.widgets.FileDownload(callback=self._record_csv, filename="flight_record.csv",
                                                label="Save the flight record (CSV)", width=w, disabled=True,
                                                css_classes=["uam-fly-csv"])
        self.clock = pn.widgets.FloatSlider(name="Playback time (s)", start=0, end=1, value=0, width=w)
        self.status = pn.pane.Markdown("", css_classes=["uam-fly-status"], sizing_mode="stretch_width")
        self.error = pn.pane.Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width")
        self.progress = busy_mark(bool(s.running), 110, FLYING)  # its content alone changes: no new layout
        self.log = pn.widgets.Tabulator(pd.DataFrame(columns=["t (s)", "at", "belief from", "q_max (C)", "R0 (ohm)",
                                                              "fit flags", "leg wind vs forecast (kt)",
                                                              "common shift (kt)",
                                                              "wind changed (p)", "next", "reason"]),
                                        disabled=True, show_index=False, sizing_mode="stretch_both",
                                        css_classes=["uam-fly-log"], layout="fit_columns",
                                        configuration={"columnDefaults": {"headerWordWrap": True},
                                                       "renderVertical": "basic"},  # every row in the page
                                        formatters={"reason": {"type": "textarea"}},
                                        widths={"t (s)": 55, "at": 85, "belief from": 105, "q_max (C)": 100,
                                                "R0 (ohm)": 85,
                                                "fit flags": 70, "leg wind vs forecast (kt)": 150,
                                                "common shift (kt)": 110, "wind changed (p)": 95, "next": 85})
        self._shown = (-1, -1, -1)
        self._log_rows: list[dict[str, Any]] = []  # the rows the decision log shows
        self._figures()
        self.map_pane = pn.pane.Bokeh(self.map_fig, width=MAP_PX + 10, height=MAP_PX + 10)
        self.volt_pane = pn.pane.Bokeh(self.volt_fig, sizing_mode="stretch_width", height=MAP_PX)
        self.fly_button.on_click(lambda _e: _held(s.fly))
        self.inject_button.on_click(lambda _e: _held(s.inject))
        self.clear_button.on_click(lambda _e: _held(s.clear_events))
        self.play.param.watch(lambda e: setattr(s, "playing", e.new), "value")
        self.speed.param.watch(lambda e: setattr(s, "speed", e.new), "value")
        self.seed.param.watch(lambda e: setattr(s, "seed", e.new), "value")
        self.pack.param.watch(lambda e: setattr(s, "pack", e.new), "value")
        self.world.param.watch(lambda e: setattr(s, "world", e.new), "value")
        self.sigma.param.watch(lambda e: setattr(s, "forecast_sigma_kt", e.new), "value")
        self.noise.param.watch(lambda e: setattr(s, "sensor_noise_mv", e.new), "value")
        self.reserve.param.watch(lambda e: setattr(s, "reserve_kt", e.new), "value")
        self.risk.param.watch(lambda e: setattr(s, "risk", e.new), "value")
        s.param.watch(lambda e: setattr(self.reserve, "value", e.new), "reserve_kt")
        self.inject_kts.param.watch(lambda e: setattr(s, "inject_kts", e.new), "value")
        self.clock.param.watch(self._on_clock, "value_throttled")
        s.param.watch(self._on_flight, ["record", "t_s"])  # once for both when a flight shows (param.update)
        s.param.watch(lambda e: setattr(self.play, "value", e.new), "playing")
        s.param.watch(lambda e: setattr(self.progress, "object", busy_html(bool(e.new), FLYING)), "running")
        s.param.watch(self._on_text, ["status", "error"])
        self._callback: pn.io.PeriodicCallback | None = None
        self._layout = pn.Row(
            pn.Column(self.fly_button, self.play, self.speed, self.clock, pn.Spacer(height=10),
                      self.inject_kts, self.inject_button, self.clear_button, pn.Spacer(height=10),
                      self.pack, self.world, self.seed, self.sigma, self.noise, self.risk, self.reserve,
                      pn.Spacer(height=10),
                      self.download,
                      width=230),
            pn.Column(self.error, pn.Row(self.progress, self.status, sizing_mode="stretch_width"),
                      pn.Row(self.map_pane, self.volt_pane, sizing_mode="stretch_width"),
                      pn.Card(ManyFlightsView(s.many), title="Many flights: the price of safety (click to open)",
                              collapsed=True, sizing_mode="stretch_width", css_classes=["uam-many-card"]),
                      window_height(self.log, LOG_HEIGHT_CSS),
                      sizing_mode="stretch_width"),
            sizing_mode="stretch_width", css_classes=["uam-fly"])
        if s.record is not None:
            self._draw_record()

    # ------------------------------------------------------------------ figures
    def _figures(self) -> None:
        """The map and voltage figures, built once as plain Bokeh models: each playback tick only
        replaces their sources' data and moves the time line, a few milliseconds of the session's
        thread (``benchmarks/bench_app.py flytick``)."""
        self.dests = ColumnDataSource({"x_km": [], "y_km": [], "name": []})
        self.vertiport = ColumnDataSource({"x_km": [], "y_km": []})
        self.seen = ColumnDataSource({"x_km": [], "y_km": []})
        self.leg_labels = ColumnDataSource({"x": [], "y": [], "text": []})
        self.pos = ColumnDataSource({"x_km": [], "y_km": []})
        fig = page_figure(title="flight", width=MAP_PX, height=MAP_PX, x_axis_label="x (km)", y_axis_label="y (km)",
                          x_range=Range1d(start=0.0, end=1.0), y_range=Range1d(start=0.0, end=1.0))
        fig.scatter("x_km", "y_km", source=self.vertiport, marker="square", size=14, color="black")
        dots = fig.scatter("x_km", "y_km", source=self.dests, size=10, color="#ff7f0e", line_color="black")
        fig.text("x_km", "y_km", text="name", source=self.dests, text_font_size="9pt", text_baseline="bottom",
                 text_align="center", y_offset=-NAME_OFFSET_PX)
        fig.line("x_km", "y_km", source=self.seen, color="#1f77b4", line_width=3)
        fig.text("x", "y", text="text", source=self.leg_labels, text_font_size="8pt", text_color="#333333",
                 text_align="center", text_baseline="middle", background_fill_color="white",
                 background_fill_alpha=0.85)
        fig.scatter("x_km", "y_km", source=self.pos, marker="triangle", size=16, color=EOD_COLOR)
        fig.add_tools(HoverTool(renderers=[dots], tooltips=[("", "@name"), ("x (km)", "@x_km"), ("y (km)", "@y_km")]))
        self.map_fig = derived_looks(fig)

        self.curves = {key: ColumnDataSource({"time_min": [], "voltage_v": []}) for key, _, _ in VOLTAGE_SERIES}
        self.cutoff = ColumnDataSource({"x": [], "y": []})
        self.marks = ColumnDataSource({"time_min": [], "voltage_v": [], "decision": []})
        self.changes = ColumnDataSource({"x": [], "y": [], "text": [], "y0": []})
        fig = page_figure(title="voltage: fly the mission to see it", height=MAP_PX, sizing_mode="stretch_width",
                          x_range=Range1d(start=0.0, end=1.0), y_range=Range1d(start=2.9, end=4.25),
                          x_axis_label="time (min)", y_axis_label="voltage (V)", min_border_top=0)
        for key, label, style in VOLTAGE_SERIES:
            fig.line("time_min", "voltage_v", source=self.curves[key], legend_label=label, **style)
        fig.line("x", "y", source=self.cutoff, legend_label="EOD cut-off", color=EOD_COLOR, line_dash="dashed",
                 line_width=2)
        marks = fig.scatter("time_min", "voltage_v", source=self.marks, legend_label="decisions", marker="triangle",
                            size=11, color="black", line_color="white")
        fig.segment("x", "y0", "x", "y", source=self.changes, color=EVENT_COLOR, line_width=2, line_dash="dashdot")
        fig.text("x", "y", text="text", source=self.changes, text_color=EVENT_COLOR, text_font_size="9pt",
                 text_align="left", text_baseline="top", x_offset=4)
        fig.add_tools(HoverTool(renderers=[marks], tooltips=[("time (min)", "@time_min{0.0}"),
                                                              ("voltage (V)", "@voltage_v{0.000}"),
                                                              ("decision", "@decision")]))
        self.now_line = Span(location=0.0, dimension="height", line_color="black", line_width=1)
        fig.add_layout(self.now_line)
        legend_above(fig)
        self.volt_fig = derived_looks(fig)
        self._draw_flight()

    def _draw_flight(self) -> None:
        """Set the figures to the current record (or the Planner's mission before a flight): the places,
        the axes' ranges, the cut-off line and the title; the playback's own data is :meth:`_draw_time`'s."""
        s = self.state
        m = s.mission_flown if s.mission_flown is not None else s._mission()
        xs = [d.x_km for d in m.destinations]
        ys = [d.y_km for d in m.destinations]
        names = [place_label(d.name, d.priority) for d in m.destinations]
        _replace(self.dests, {"x_km": xs, "y_km": ys, "name": names})
        _replace(self.vertiport, {"x_km": [m.vertiport.x_km], "y_km": [m.vertiport.y_km]})
        pad = 8.0
        allx, ally = np.array(xs + [m.vertiport.x_km]), np.array(ys + [m.vertiport.y_km])
        x0, x1, y0, y1 = allx.min() - pad, allx.max() + pad, ally.min() - pad, ally.max() + 2 * pad  # room for names
        span = max(x1 - x0, y1 - y0)  # equal scales on both axes in a square frame
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        self.map_fig.x_range.update(start=cx - span / 2, end=cx + span / 2)
        self.map_fig.y_range.update(start=cy - span / 2, end=cy + span / 2)
        r = s.record
        eod = m.eod_v
        if r is None or r.time_s.size == 0:
            end_min, lo, title = 1.0, eod - 0.1, "voltage: fly the mission to see it"
        else:
            end_min = float(r.time_s[-1]) / 60.0 * 1.02
            lo, title = (min(eod, float(r.true_voltage_v.min())) - 0.08,
                         "voltage: measured vs predicted, and the cut-off")
        self.volt_fig.title.text = title
        if not s.complete:  # a part of a flight: the axes only grow until it is all known (one layout, not three)
            end_min, lo = max(end_min, self.volt_fig.x_range.end), min(lo, self.volt_fig.y_range.start)
        if (end_min, lo) != (self.volt_fig.x_range.end, self.volt_fig.y_range.start):
            self.volt_fig.x_range.update(start=0.0, end=end_min)
            self.volt_fig.y_range.update(start=lo, end=4.25)
        # the cut-off moves without the axes when both flights fell below it
        _replace(self.cutoff, {"x": [0.0, end_min], "y": [eod, eod]})

    # ------------------------------------------------------------------ updates
    def _on_flight(self, *events: param.parameterized.Event) -> None:
        """Draw a new record (or the same flight with its references put in: nothing drawn changes) or the
        playback's time, as one batch of model changes (each batch costs the browser a page layout)."""
        new = next((e for e in events if e.name == "record"), None)
        same = new is not None and new.old is not None and new.new is not None and new.new.time_s is new.old.time_s
        with pn.io.hold():
            if new is not None and not same:
                self._draw_record()
            elif len(events) > 1 or new is None:  # the time moved (the same flight with its references: nothing)
                self._draw_time()

    def _draw_record(self) -> None:
        s = self.state
        self.download.disabled = s.record is None
        self.clock.end = max(1.0, s.end_s, 0.0 if s.complete else self.clock.end)
        self._draw_flight()
        self._shown = (-1, -1, -1)
        self._draw_time()
        self._ensure_timer()

    def _draw_time(self) -> None:
        s = self.state
        if s.record is None:
            return
        self.clock.value = min(s.t_s, self.clock.end)
        x, y, leg = s.position()
        m = s.mission_flown
        assert m is not None  # set with the record (FlyState._flown updates both at once)
        nodes = [VERTIPORT] + list(s.record.route)
        path = [(m.node(n).x_km, m.node(n).y_km) for n in nodes[: max(leg, 0) + 1]] + [(x, y)]
        _replace(self.seen, {"x_km": [p[0] for p in path], "y_km": [p[1] for p in path]})
        _replace(self.pos, {"x_km": [x], "y_km": [y]})
        series = s.series_until()
        for key, _label, _style in VOLTAGE_SERIES:  # not `_`: the name of this method's *args
            t, v = series[key]
            _replace(self.curves[key], {"time_min": np.asarray(t, dtype=float),
                                        "voltage_v": np.asarray(v, dtype=float)})
        self.now_line.location = float(s.t_s) / 60.0
        shown = (leg, len(series["decisions"]), len(series["changes"]))
        if shown == self._shown:  # the labels, marks and log change only at a new leg, decision or change
            return
        self._shown = shown
        _replace(self.leg_labels, _leg_labels(path, s.record.altitudes_m, m))
        decisions = series["decisions"]
        _replace(self.marks, {"time_min": [d[0] for d in decisions], "voltage_v": [d[1] for d in decisions],
                              "decision": [d[2] for d in decisions]})
        changes = series["changes"]
        _replace(self.changes, {"x": [c[0] for c in changes], "y": [4.22] * len(changes),
                                "text": [c[1] for c in changes], "y0": [self.volt_fig.y_range.start] * len(changes)})
        rows = s.decisions_until()
        if rows != self._log_rows:  # the table is the costliest model to redraw in the browser
            self._log_rows = rows
            self.log.value = pd.DataFrame(rows) if rows else self.log.value.iloc[0:0]

    def _record_csv(self) -> io.StringIO:
        """The shown flight's record as CSV (:func:`~uam_studio.planning.operations.record_csv`)."""
        r = self.state.record
        return io.StringIO(record_csv(r) if r is not None else "")

    def _on_clock(self, event: param.parameterized.Event) -> None:
        self.state.t_s = float(event.new)

    def _on_text(self, *_: Any) -> None:
        s = self.state
        self.status.object = s.status
        self.error.object = s.error
        self.error.visible = bool(s.error)

    def _ensure_timer(self) -> None:
        """Start the playback timer, or start it again when a new flight begins: its first tick then comes a whole
        period after the flight's first frame, not while the browser draws it."""
        if self._callback is None and pn.state.curdoc is not None and pn.state.curdoc.session_context is not None:
            self._callback = pn.state.add_periodic_callback(self._tick, period=TICK_MS)
        elif self._callback is not None and self.state.t_s == 0.0:
            self._callback.stop()
            self._callback.start()

    def _tick(self) -> None:
        with pn.io.hold():  # the tick's changes (figures, clock, status) in one batch
            self.state.tick(TICK_MS / 1000.0)

    def close(self) -> None:
        """Stop the playback timer."""
        if self._callback is not None:
            self._callback.stop()
            self._callback = None

    def __panel__(self) -> pn.viewable.Viewable:
        return self._layout


__all__ = ["FlyView"]
