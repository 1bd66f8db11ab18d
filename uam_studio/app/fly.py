"""The Fly tab: the Planner's mission flown in a world the operator cannot see, played back.

The aircraft moves along the flown route on the map; the voltage plot shows the sensor's readings up
to the playback time against the operator's prediction, the world's hidden truth and the EOD line,
with every decision marked; the log lists the decisions made so far with their reasons. Controls:
world seed, forecast error, sensor noise, playback speed, and a wind change injected at the playback
time. Everything comes from :class:`~uam_studio.app.fly_state.FlyState`; this view only draws it.
"""

from __future__ import annotations

import io
from typing import Any

import holoviews as hv
import numpy as np
import pandas as pd
import panel as pn
import param

from uam_studio.app.fly_state import SPEEDS, FlyState
from uam_studio.app.map_geometry import altitude_labels
from uam_studio.app.session import ensure_bokeh_backend
from uam_studio.app.style import (
    MEASURED_COLOR,
    NAME_OFFSET_PX,
    PHYSICS_COLOR,
    PREDICTED_COLOR,
    label_background,
    no_scroll_zoom,
    pixel_offset,
    tight_legend_above,
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
DECISION_STYLE = {"marker": "triangle", "size": 11, "color": "black", "line_color": "white", "tools": ["hover"]}
TIME_DIM, VOLT_DIM = hv.Dimension("time_min", label="time (min)"), hv.Dimension("voltage_v", label="voltage (V)")
ROUTE_COLORS = ("#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b")


def _leg_labels(path: list[tuple[float, float]], altitudes_m: list[float], mission: Mission) -> dict[str, list]:
    """A label ``"#k altitude m"`` beside each leg of ``path`` (km; the last point is the aircraft, so
    the leg it flies is labelled from its take-off on), placed as the Planner's map places them
    (:func:`~uam_studio.app.map_geometry.altitude_labels`: clear of the places, their names and each
    other)."""
    legs: dict[str, list] = {c: [] for c in ("from", "to", "altitude_m", "x0", "y0", "x1", "y1")}
    for k, ((x0, y0), (x1, y1)) in enumerate(zip(path, path[1:])):
        if k < len(altitudes_m) and (x0, y0) != (x1, y1):
            for c, v in zip(legs, (f"{x0:.3f},{y0:.3f}", f"leg {k}", altitudes_m[k], x0, y0, x1, y1)):
                legs[c].append(v)
    nodes = [(d.x_km, d.y_km) for d in mission.destinations]
    names = [f"{d.name} {'*' * d.priority}" for d in mission.destinations]
    # altitude_labels numbers the legs it is given from #1: here every leg flown so far, in order
    return altitude_labels(legs, [(mission.vertiport.x_km, mission.vertiport.y_km), *nodes], ["", *names])


class FlyView(pn.viewable.Viewer):
    """Controls, map, voltage plot and decision log of a :class:`FlyState`."""

    state = param.ClassSelector(class_=FlyState)

    def __init__(self, state: FlyState, **params: Any) -> None:
        ensure_bokeh_backend()
        super().__init__(state=state, **params)
        s = self.state
        w = 200
        self.fly_button = pn.widgets.Button(name="Fly the mission", button_type="primary", width=w)
        self.play = pn.widgets.Toggle(name="Play / pause", value=s.playing, width=w)
        self.speed = pn.widgets.Select(name="Playback speed (x)", options=list(SPEEDS), value=s.speed, width=w)
        self.seed = pn.widgets.IntInput(name="World seed", value=s.seed, start=0, width=w)
        self.sigma = pn.widgets.FloatSlider(name="Forecast error (kt, std)", start=0, end=40, step=1,
                                            value=s.forecast_sigma_kt, width=w)
        self.noise = pn.widgets.FloatSlider(name="Voltage sensor noise (mV)", start=0, end=20, step=0.5,
                                            value=s.sensor_noise_mv, width=w)
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
        self.progress = pn.indicators.LoadingSpinner(value=False, size=24, name="flying...", visible=False)
        self.log = pn.widgets.Tabulator(pd.DataFrame(columns=["t (s)", "at", "q_max (C)", "R0 (ohm)", "fit flags",
                                                              "leg wind vs forecast (kt)", "common shift (kt)",
                                                              "next", "reason"]),
                                        disabled=True, show_index=False, sizing_mode="stretch_both",
                                        css_classes=["uam-fly-log"], layout="fit_columns",
                                        configuration={"columnDefaults": {"headerWordWrap": True}},
                                        formatters={"reason": {"type": "textarea"}},
                                        widths={"t (s)": 55, "at": 85, "q_max (C)": 95, "R0 (ohm)": 85,
                                                "fit flags": 80, "leg wind vs forecast (kt)": 190,
                                                "common shift (kt)": 135, "next": 85})
        self.pos = hv.streams.Pipe(data=[])
        self.leg_labels = hv.streams.Pipe(data={"x": [], "y": [], "text": []})
        self.seen = hv.streams.Pipe(data=[])
        self.series = hv.streams.Pipe(data=s.series_until())
        self.now = hv.streams.Pipe(data=0.0)
        self.map_pane = pn.pane.HoloViews(self._map(), width=MAP_PX + 10, height=MAP_PX + 10)
        self.volt_pane = pn.pane.HoloViews(self._voltage(), sizing_mode="stretch_width", height=MAP_PX)
        self.fly_button.on_click(lambda _e: s.fly())
        self.inject_button.on_click(lambda _e: s.inject())
        self.clear_button.on_click(lambda _e: s.clear_events())
        self.play.param.watch(lambda e: setattr(s, "playing", e.new), "value")
        self.speed.param.watch(lambda e: setattr(s, "speed", e.new), "value")
        self.seed.param.watch(lambda e: setattr(s, "seed", e.new), "value")
        self.sigma.param.watch(lambda e: setattr(s, "forecast_sigma_kt", e.new), "value")
        self.noise.param.watch(lambda e: setattr(s, "sensor_noise_mv", e.new), "value")
        self.inject_kts.param.watch(lambda e: setattr(s, "inject_kts", e.new), "value")
        self.clock.param.watch(self._on_clock, "value_throttled")
        s.param.watch(self._on_record, "record")
        s.param.watch(self._on_time, "t_s")
        s.param.watch(lambda e: setattr(self.play, "value", e.new), "playing")
        s.param.watch(lambda e: self.progress.param.update(value=e.new, visible=e.new), "running")
        s.param.watch(self._on_text, ["status", "error"])
        self._callback = None
        self._layout = pn.Row(
            pn.Column(self.fly_button, self.play, self.speed, self.clock, pn.Spacer(height=10),
                      self.inject_kts, self.inject_button, self.clear_button, pn.Spacer(height=10),
                      self.seed, self.sigma, self.noise, pn.Spacer(height=10), self.download, width=230),
            pn.Column(self.error, pn.Row(self.progress, self.status, sizing_mode="stretch_width"), pn.Row(self.map_pane, self.volt_pane, sizing_mode="stretch_width"),
                      window_height(self.log, LOG_HEIGHT_CSS),
                      sizing_mode="stretch_width"),
            sizing_mode="stretch_width", css_classes=["uam-fly"])
        if s.record is not None:
            self._on_record()

    # ------------------------------------------------------------------ figures
    def _map(self) -> hv.Overlay:
        s = self.state
        m = s.mission_flown if s.mission_flown is not None else s._mission()
        xs = [d.x_km for d in m.destinations]
        ys = [d.y_km for d in m.destinations]
        names = [f"{d.name} {'*' * d.priority}" for d in m.destinations]
        dests = hv.Points((xs, ys, names), ["x_km", "y_km"], ["name"], label="destinations").opts(
            size=10, color="#ff7f0e", line_color="black", tools=["hover"])
        labels = hv.Labels((xs, ys, names), ["x_km", "y_km"], "name").opts(
            text_font_size="9pt", text_baseline="bottom", hooks=[pixel_offset(-NAME_OFFSET_PX)])
        vp = hv.Points([(m.vertiport.x_km, m.vertiport.y_km)], ["x_km", "y_km"], label="vertiport").opts(
            marker="square", size=14, color="black")
        flown = hv.DynamicMap(lambda data: hv.Path(data, ["x_km", "y_km"], label="flown").opts(
            color="#1f77b4", line_width=3), streams=[self.seen])
        legs = hv.DynamicMap(lambda data: hv.Labels(data, ["x", "y"], "text").opts(
            text_font_size="8pt", text_color="#333333", hooks=[label_background]), streams=[self.leg_labels])
        craft = hv.DynamicMap(lambda data: hv.Points(data, ["x_km", "y_km"], label="aircraft").opts(
            marker="triangle", size=16, color=EOD_COLOR), streams=[self.pos])
        pad = 8.0
        allx, ally = np.array(xs + [m.vertiport.x_km]), np.array(ys + [m.vertiport.y_km])
        x0, x1, y0, y1 = allx.min() - pad, allx.max() + pad, ally.min() - pad, ally.max() + 2 * pad  # room for names
        span = max(x1 - x0, y1 - y0)  # equal scales on both axes in a square frame
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        return (vp * dests * labels * flown * legs * craft).opts(
            title="flight", width=MAP_PX, height=MAP_PX, legend_position="bottom_right", show_legend=False,
            xlabel="x (km)", ylabel="y (km)", hooks=[no_scroll_zoom],
            xlim=(cx - span / 2, cx + span / 2), ylim=(cy - span / 2, cy + span / 2))

    def _voltage(self) -> hv.Overlay:
        """The voltage figure of the current record (time in min): the cut-off, and up to the playback
        time the operator's prediction, the world's true voltage, the sensor's readings on top, the
        decisions made and the wind changes that have started (:meth:`_on_time` streams them in)."""
        s = self.state
        r = s.record
        eod = (s.mission_flown or s._mission()).eod_v
        cutoff = hv.HLine(eod, label="EOD cut-off").opts(color=EOD_COLOR, line_dash="dashed", line_width=2)
        legend = dict(legend_position="top", legend_opts={"orientation": "horizontal"}, hooks=[no_scroll_zoom, tight_legend_above], responsive=True, height=MAP_PX)
        if r is None or r.time_s.size == 0:  # the same legend as a flight's, so that nothing moves after it
            empty = [hv.Curve([], TIME_DIM, VOLT_DIM, label=label).opts(**style) for _, label, style in VOLTAGE_SERIES]
            marks = hv.Points([], [TIME_DIM, VOLT_DIM], label="decisions").opts(**DECISION_STYLE)
            return hv.Overlay([*empty, cutoff, marks]).opts(title="voltage: fly the mission to see it",
                                                           ylim=(eod - 0.1, 4.25), **legend)
        lo = min(eod, float(r.true_voltage_v.min())) - 0.08

        def curve(key: str, label: str, style: dict[str, Any]) -> hv.DynamicMap:
            return hv.DynamicMap(lambda data: hv.Curve(data[key], TIME_DIM, VOLT_DIM, label=label).opts(**style),
                                 streams=[self.series])

        predicted, true, measured = (curve(*spec) for spec in VOLTAGE_SERIES)
        marks = hv.DynamicMap(lambda data: hv.Points(
            [(t, v, reason) for t, v, reason in data["decisions"]], [TIME_DIM, VOLT_DIM], ["decision"],
            label="decisions").opts(**DECISION_STYLE),
            streams=[self.series])
        changes = hv.DynamicMap(lambda data: hv.VLines([t for t, _ in data["changes"]], TIME_DIM).opts(
            color=EVENT_COLOR, line_width=2, line_dash="dashdot") * hv.Labels(
            {"x": [t for t, _ in data["changes"]], "y": [4.22] * len(data["changes"]),
             "text": [text for _, text in data["changes"]]}, ["x", "y"], "text").opts(
            text_color=EVENT_COLOR, text_font_size="9pt", text_align="left", text_baseline="top", xoffset=0.5),
            streams=[self.series])
        now = hv.DynamicMap(lambda data: hv.VLine(float(data) / 60.0 if np.ndim(data) == 0 else 0.0).opts(
            color="black", line_width=1), streams=[self.now])
        return (predicted * true * measured * cutoff * marks * changes * now).opts(
            title="voltage: measured vs predicted, and the cut-off", ylim=(lo, 4.25),
            xlim=(0, float(r.time_s[-1]) / 60.0 * 1.02), **legend)

    # ------------------------------------------------------------------ updates
    def _on_record(self, *_: Any) -> None:
        s = self.state
        self.download.disabled = s.record is None
        self.clock.end = max(1.0, s.end_s)
        self.map_pane.object = self._map()
        self.volt_pane.object = self._voltage()
        self._on_time()
        self._ensure_timer()

    def _on_time(self, *_: Any) -> None:
        s = self.state
        if s.record is None:
            return
        self.clock.value = min(s.t_s, self.clock.end)
        x, y, leg = s.position()
        m = s.mission_flown
        nodes = [VERTIPORT] + list(s.record.route)
        path = [(m.node(n).x_km, m.node(n).y_km) for n in nodes[: max(leg, 0) + 1]] + [(x, y)]
        self.seen.send([path])
        self.leg_labels.send(_leg_labels(path, s.record.altitudes_m, m))
        self.pos.send([(x, y)])
        self.series.send(s.series_until())
        self.now.send(float(s.t_s))
        rows = s.decisions_until()
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
        if self._callback is None and pn.state.curdoc is not None and pn.state.curdoc.session_context is not None:
            self._callback = pn.state.add_periodic_callback(lambda: self.state.tick(TICK_MS / 1000.0),
                                                            period=TICK_MS)

    def close(self) -> None:
        """Stop the playback timer."""
        if self._callback is not None:
            self._callback.stop()
            self._callback = None

    def __panel__(self) -> pn.viewable.Viewable:
        return self._layout


__all__ = ["FlyView"]
