"""The Battery lab tab: the paper's figures, live.

One leg (distance, altitude, wind) flown by one cell (q_max, R0), ``legs`` times back to back, and a
family of curves varying one factor (altitude, wind, R0 or q_max): per-cell current and voltage
(physics model) with the EOD line, on one time axis. Below, a real NASA discharge predicted before its
end (:mod:`uam_studio.app.battery_lab.nasa`). The numbers come from
:class:`~uam_studio.app.battery_lab.state.BatteryLabState`; this view only draws its ``result``. The plots are
built once per factor (their legend names the factor's values in ascending order) and a slider move
only sends new data to them.
"""

from __future__ import annotations

import functools
import html
from collections.abc import Callable
from typing import Any, cast

import holoviews as hv
import numpy as np
import panel as pn
import param

from uam_studio.app.battery_lab.nasa import NasaLabState, NasaLabView
from uam_studio.app.battery_lab.state import CELLS, VARY, BatteryLabState
from uam_studio.app.services import APP_EOD_RANGE, APP_Q_RANGE, APP_R0_RANGE
from uam_studio.app.session import ensure_bokeh_backend, respond_at_once, session_dispatcher
from uam_studio.app.style import heading, intro, no_scroll_zoom, window_height
from uam_studio.flight.tables import ALTITUDE_RANGE_M, WIND_RANGE_KTS

FAMILY_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2")
EOD_COLOR = "#d62728"
SETTING = "this setting"
BUSY_AFTER_MS = 150  # served: a change taking longer than this shows the busy indicator
# The plots share the window's height below the tab's heading (about 230 px down): 46% / 54%, at least
# 250 / 290 px (a 1366x768 screen shows both whole; a 1920x1080 one fills its height instead of a third
# of it staying empty).
CURRENT_HEIGHT_CSS = "max(250px, calc((100vh - 230px) * 0.46))"
VOLTAGE_HEIGHT_CSS = "max(290px, calc((100vh - 230px) * 0.54))"


def eod_text(curve: dict[str, Any]) -> str:
    """A curve's end of discharge: ``"71.0 min"``, or ``"not reached (lowest 3.412 V)"``."""
    if curve["eod_s"] is None:
        return f"not reached (lowest {curve['min_voltage_v']:.3f} V)"
    return f"{curve['eod_s'] / 60.0:.1f} min"


class BatteryLabView(pn.viewable.Viewer):
    """Sliders for the leg and the cell, and current/voltage plots of a :class:`BatteryLabState`."""

    # never None once built: __init__ gives a new BatteryLabState when none is given (param types it Optional)
    state = cast("param.ClassSelector[BatteryLabState]", param.ClassSelector(class_=BatteryLabState))

    def __init__(self, state: BatteryLabState | None = None, nasa: NasaLabView | None = None, **params: Any) -> None:
        ensure_bokeh_backend()
        super().__init__(state=state or BatteryLabState(), **params)
        s = self.state
        self.nasa = nasa or NasaLabView(NasaLabState(background=s.background, dispatch=s.dispatch))
        w = 250
        self.widgets = {
            "cell": pn.widgets.Select(name="Cell", options=list(CELLS), value=s.cell, width=w),
            "vary": pn.widgets.RadioButtonGroup(name="Vary", options=list(VARY), value=s.vary, width=w),
            "q_max": pn.widgets.FloatSlider(name="q_max (C)", start=APP_Q_RANGE[0], end=APP_Q_RANGE[1], step=50,
                                            value=s.q_max, width=w),
            "r0": pn.widgets.FloatSlider(name="R0 (ohm)", start=APP_R0_RANGE[0], end=APP_R0_RANGE[1], step=0.001,
                                         value=s.r0, format="0.000", width=w),
            "altitude_m": pn.widgets.FloatSlider(name="Cruise altitude (m)", start=ALTITUDE_RANGE_M[0],
                                                 end=ALTITUDE_RANGE_M[1], step=50, value=s.altitude_m, width=w),
            "wind_kts": pn.widgets.FloatSlider(name="Wind (kt, negative = tailwind)", start=WIND_RANGE_KTS[0],
                                               end=WIND_RANGE_KTS[1], step=1, value=s.wind_kts, width=w),
            "distance_km": pn.widgets.FloatSlider(name="Leg length (km)", start=10, end=150, step=0.5,
                                                  value=s.distance_km, width=w),
            "legs": pn.widgets.IntSlider(name="Legs flown back to back", start=1, end=10, value=s.legs, width=w),
            "eod_v": pn.widgets.FloatSlider(name="EOD cut-off (V)", start=APP_EOD_RANGE[0], end=APP_EOD_RANGE[1],
                                            step=0.05, value=s.eod_v, format="0.00", width=w),
        }
        for key, wd in self.widgets.items():
            wd.link(s, value=key)
        respond_at_once(self.widgets.values())
        self.message = pn.pane.Alert("", alert_type="warning", visible=False, css_classes=["uam-lab-error"],
                                     sizing_mode="stretch_width")
        self.busy = pn.indicators.LoadingSpinner(value=s.busy, size=18, css_classes=["uam-lab-busy"],
                                                 margin=(0, 5), visible=bool(s.busy))
        self.current_plot = pn.pane.HoloViews(linked_axes=False, sizing_mode="stretch_both",
                                              css_classes=["uam-lab-current"])
        self.voltage_plot = pn.pane.HoloViews(linked_axes=False, sizing_mode="stretch_both",
                                              css_classes=["uam-lab-voltage"])
        # The class sits on the content (inside the pane's shadow root), as the Planner's summary.
        self.eod_table = pn.pane.HTML(sizing_mode="stretch_width")
        self._busy_later = session_dispatcher(delay_ms=BUSY_AFTER_MS) or (lambda cb: cb())
        self._factor: tuple[str, ...] | None = None  # the plots' factor and legend labels
        self._current_pipe: hv.streams.Pipe | None = None
        self._voltage_pipe: hv.streams.Pipe | None = None
        s.param.watch(self._on_cell, "cell")
        s.param.watch(self._on_result, "result")
        s.param.watch(self._on_busy, "busy")
        self._on_result()

    def __panel__(self) -> pn.viewable.Viewable:
        text = intro(
            "One leg flown by one 18650 cell (the pack scaled to a cell), repeated without recharging: the "
            "paper's NASA cell (progpy's parameters), the same cell type identified on a real NASA cell's "
            "discharges (B0005), or a Sony VTC6 identified on the CMU eVTOL dataset's cells (same current). "
            "Pick the factor to vary: the thin curves sweep it over its range, the black dashed curve is the "
            "setting of the sliders.")
        controls = pn.Column(heading("Leg and cell"), *self.widgets.values(), width=270)
        plots = pn.Column(pn.Row(heading("Current and voltage"), self.busy),
                          window_height(self.current_plot, CURRENT_HEIGHT_CSS),
                          window_height(self.voltage_plot, VOLTAGE_HEIGHT_CSS),
                          min_width=560, sizing_mode="stretch_width",
                          styles={"flex": "1 1 560px"})
        table = pn.Column(heading("End of discharge"), self.eod_table, width=300)
        body = pn.FlexBox(controls, plots, table, flex_wrap="wrap", gap="10px", sizing_mode="stretch_width")
        return pn.Column(text, self.message, body, self.nasa, sizing_mode="stretch_width")

    def _on_cell(self, *events: Any) -> None:
        """The state's new cell set its health and ranges: the sliders follow.

        In three messages, each a valid slider: the union of the old and new ranges, the new value,
        the new range. The browser applies a message's changes one at a time, and a value outside the
        range it holds at that moment is clamped there and sent back (the NASA range ends at 8000 C,
        below the VTC6's nominal q_max), so one combined message could leave the state at the clamp.
        """
        s = self.state
        for key in ("q_max", "r0"):
            wd = cast("pn.widgets.FloatSlider", self.widgets[key])  # q_max's and R0's: float sliders
            lo, hi = s.param[key].bounds
            wd.param.update(start=min(lo, wd.start), end=max(hi, wd.end))
            wd.value = getattr(s, key)
            wd.param.update(start=lo, end=hi)

    def _on_busy(self, event: param.parameterized.Event) -> None:
        """Served, the busy indicator appears only once a change has taken :data:`BUSY_AFTER_MS`
        (each change sent to the browser costs it a page layout; a fast change would pay twice)."""
        if event.new:
            # cast: the dispatcher ignores what its callback returns (here param.update's restorer)
            self._busy_later(cast("Callable[[], None]", lambda: self.busy.param.update(value=bool(self.state.busy),
                                                                                   visible=bool(self.state.busy))))
        else:
            self.busy.param.update(value=False, visible=False)  # no idle ring beside the heading

    def _on_result(self, *events: Any) -> None:
        c = self.state.result
        if c is None:
            return
        self.message.object = html.escape(c["error"])
        self.message.visible = bool(c["error"])
        if c["error"]:
            return
        data = self._plot_data(c)
        with pn.io.hold():
            if (c["factor"], *c["labels"]) != self._factor:  # new legend: new plots
                self._factor = (c["factor"], *c["labels"])
                self._current_pipe = hv.streams.Pipe(data=data)
                self._voltage_pipe = hv.streams.Pipe(data=data)
                labels = [*c["labels"], SETTING]
                self.current_plot.object = hv.DynamicMap(
                    functools.partial(self._current_element, labels=labels, factor=c["factor"]),
                    streams=[self._current_pipe])
                self.voltage_plot.object = hv.DynamicMap(
                    functools.partial(self._voltage_element, labels=labels, factor=c["factor"]),
                    streams=[self._voltage_pipe])
            else:
                # the same legend: the pipes made with it (set together with self._factor above)
                cast("hv.streams.Pipe", self._current_pipe).send(data)
                cast("hv.streams.Pipe", self._voltage_pipe).send(data)
            me = c["setting"][0]
            rows = "".join(f"<tr><td style='padding-right:12px'>{html.escape(cv['label'])}</td>"
                           f"<td>{eod_text(cv)}</td></tr>"
                           for cv in [me, *c["family"]])
            skipped = "".join(f"<li>not drawn: {html.escape(m)}</li>" for m in c["skipped"])
            self.eod_table.object = ("<div class='uam-lab-summary'><table><tr><th style='text-align:left'>curve</th>"
                                     "<th style='text-align:left'>end of discharge</th></tr>"
                                     f"{rows}</table>" + (f"<ul>{skipped}</ul>" if skipped else "") + "</div>")

    @staticmethod
    def _plot_data(c: dict[str, Any]) -> dict[str, Any]:
        """Per legend label: (time min, current A) and (time min, voltage V); the shared time range and
        the voltage range (always including the cut-off)."""
        by_label = {cv["label"]: cv for cv in c["family"]}
        by_label[SETTING] = c["setting"][0]
        empty = (np.zeros(0), np.zeros(0))
        labels = [*c["labels"], SETTING]
        cur = {k: (by_label[k]["time_s"] / 60.0, by_label[k]["current_a"]) if k in by_label else empty
               for k in labels}
        volt = {k: (by_label[k]["voltage_time_s"] / 60.0, by_label[k]["voltage_v"]) if k in by_label else empty
                for k in labels}
        vs = np.concatenate([v for _, v in volt.values()] + [np.asarray([c["eod_v"]])])
        return {"current": cur, "voltage": volt, "xlim": (0.0, c["t_end_s"] / 60.0),
                "ylim": (float(vs.min()) - 0.05, float(vs.max()) + 0.05), "eod_v": c["eod_v"]}

    @staticmethod
    def _curves(series: dict[str, tuple], labels: list[str], ylabel: str) -> list[hv.Curve]:
        out = []
        for k, label in enumerate(labels):
            # the setting dashed, over the family: a family member equal to it shows in the gaps
            style = dict(color="black", line_width=2.5, line_dash="dashed") if label == SETTING else \
                dict(color=FAMILY_COLORS[k % len(FAMILY_COLORS)], line_width=1.2, alpha=0.8)
            out.append(hv.Curve(series[label], "time (min)", ylabel, label=label).opts(**style))
        return out

    def _current_element(self, data: dict[str, Any], labels: list[str], factor: str) -> hv.Overlay:
        return hv.Overlay(self._curves(data["current"], labels, "current (A)")).opts(
            hv.opts.Overlay(responsive=True, title=f"Per-cell current, varying {factor}", hooks=[no_scroll_zoom],
                            legend_position="right", show_grid=True, xlim=data["xlim"],
                            fontsize={"title": "10pt", "legend": "8pt"}),
            hv.opts.Curve(framewise=True))

    def _voltage_element(self, data: dict[str, Any], labels: list[str], factor: str) -> hv.Overlay:
        x0, x1 = data["xlim"]
        eod = data["eod_v"]
        line = hv.Curve(([x0, x1], [eod, eod]), "time (min)", "voltage (V)", label=f"EOD {eod:g} V").opts(
            color=EOD_COLOR, line_width=1.5, line_dash="dashed")
        return hv.Overlay([*self._curves(data["voltage"], labels, "voltage (V)"), line]).opts(
            hv.opts.Overlay(responsive=True, title=f"Voltage (physics model), varying {factor}", hooks=[no_scroll_zoom],
                            legend_position="right", show_grid=True, xlim=data["xlim"], ylim=data["ylim"],
                            fontsize={"title": "10pt", "legend": "8pt"}),
            hv.opts.Curve(framewise=True))
