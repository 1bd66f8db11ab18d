"""The Battery lab tab: the paper's figures, live.

One leg (distance, altitude, wind) flown by one cell (q_max, R0), ``legs`` times back to back, and a
family of curves varying one factor (altitude, wind, R0 or q_max): per-cell current and voltage
(physics model) with the EOD line. The numbers come from :class:`~uam_studio.app.state.BatteryLabState`.
"""

from __future__ import annotations

import html
from typing import Any

import holoviews as hv
import numpy as np
import panel as pn
import param

from uam_studio.app.session import ensure_bokeh_backend
from uam_studio.app.state import APP_EOD_RANGE, APP_Q_RANGE, APP_R0_RANGE, VARY, BatteryLabState
from uam_studio.flight.tables import ALTITUDE_RANGE_M, WIND_RANGE_KTS

FAMILY_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2")


class BatteryLabView(pn.viewable.Viewer):
    """Sliders for the leg and the cell, and current/voltage plots of a :class:`BatteryLabState`."""

    state = param.ClassSelector(class_=BatteryLabState)

    def __init__(self, state: BatteryLabState | None = None, **params: Any) -> None:
        ensure_bokeh_backend()
        super().__init__(state=state or BatteryLabState(), **params)
        s = self.state
        w = 280
        self.widgets = {
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
        self.message = pn.pane.Alert("", alert_type="warning", visible=False, css_classes=["uam-lab-error"])
        self.current_plot = pn.pane.HoloViews(linked_axes=False)
        self.voltage_plot = pn.pane.HoloViews(linked_axes=False)
        self.eod_table = pn.pane.HTML(css_classes=["uam-lab-summary"], sizing_mode="stretch_width")
        s.param.watch(self._refresh, list(self.widgets))
        self._refresh()

    def __panel__(self) -> pn.viewable.Viewable:
        intro = pn.pane.Markdown(
            "One leg flown by one 18650 cell (the pack scaled to a cell), repeated without recharging. "
            "Pick the factor to vary: the thin curves sweep it over its range, the black curve is the "
            "setting of the sliders.")
        controls = pn.Column("### Leg and cell", *self.widgets.values(), width=310)
        return pn.Column(intro, self.message, pn.Row(controls, pn.Column(self.current_plot, self.voltage_plot),
                                                     pn.Column("### End of discharge", self.eod_table, width=320)))

    def _refresh(self, *events: Any) -> None:
        c = self.state.curves()
        self.message.object = c["error"]
        self.message.visible = bool(c["error"])
        if c["error"]:
            return
        cur, volt = {}, {}
        for k, curve in enumerate(c["family"]):
            color = FAMILY_COLORS[k % len(FAMILY_COLORS)]
            t = curve["time_s"] / 60.0
            cur[curve["label"]] = hv.Curve((t, curve["current_a"]), "time (min)", "current (A)").opts(
                color=color, line_width=1.2, alpha=0.8)
            v = curve["voltage_v"]
            volt[curve["label"]] = hv.Curve((t[: v.size], v), "time (min)", "voltage (V)").opts(
                color=color, line_width=1.2, alpha=0.8)
        me = c["setting"][0]
        t = me["time_s"] / 60.0
        cur["this setting"] = hv.Curve((t, me["current_a"]), "time (min)", "current (A)").opts(
            color="black", line_width=2.5)
        volt["this setting"] = hv.Curve((t[: me["voltage_v"].size], me["voltage_v"]), "time (min)",
                                        "voltage (V)").opts(color="black", line_width=2.5)
        eod = hv.HLine(self.state.eod_v).opts(color="#d62728", line_width=1.5, line_dash="dashed")
        self.current_plot.object = hv.NdOverlay(cur, kdims="curve").opts(
            width=620, height=260, title=f"Per-cell current, varying {c['factor']}", legend_position="right",
            show_grid=True)
        self.voltage_plot.object = (hv.NdOverlay(volt, kdims="curve") * eod).opts(
            width=620, height=300, title=f"Voltage (physics model), varying {c['factor']}; EOD line dashed",
            legend_position="right", show_grid=True)
        rows = "".join(
            f"<tr><td>{cv['label']}</td><td>{_eod_text(cv)}</td></tr>" for cv in [me, *c["family"]])
        skipped = "".join(f"<li>not drawn: {html.escape(m)}</li>" for m in c["skipped"])
        self.eod_table.object = (f"<table><tr><th>curve</th><th>end of discharge</th></tr>{rows}</table>"
                                 + (f"<ul>{skipped}</ul>" if skipped else ""))


def _eod_text(curve: dict[str, Any]) -> str:
    if curve["eod_s"] is None:
        return f"not reached (min {np.min(curve['voltage_v']):.3f} V)"
    return f"{curve['eod_s'] / 60.0:.1f} min"
