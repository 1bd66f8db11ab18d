"""The Fleet tab: a fleet's days under three dispatchers, side by side, one button per day.

Controls: aircraft, vertiports, demand (requests per hour), the packs' age spread, seed, and *Run the next day*.
Figures: the last day's flights per aircraft (health-aware), each pack's belief band against its
truth, and the served priority per day for the three dispatchers. The numbers come from
:class:`~uam_studio.app.fleet.state.FleetState`, which calls the library's
:func:`~uam_studio.fleet.day.simulate_day`.
"""

from __future__ import annotations

import html
from typing import Any, cast

import holoviews as hv
import pandas as pd
import panel as pn
import param

from uam_studio.app.fleet.state import LABELS, FleetState
from uam_studio.app.session import ensure_bokeh_backend
from uam_studio.app.style import NOTE_STYLE, PHYSICS_COLOR, PREDICTED_COLOR, heading, intro, no_scroll_zoom
from uam_studio.fleet.dispatch import DISPATCHERS

COLORS = {"aware": PHYSICS_COLOR, "blind": PREDICTED_COLOR, "hindsight": "#555555"}
# Line width (px) and marker size (px) per dispatcher, widest first: the dispatchers often serve the same
# stars, and a narrower line drawn later over a wider one leaves both in sight.
WIDTHS = {"aware": (5.0, 12), "blind": (3.0, 8), "hindsight": (1.5, 5)}
BREACH_COLOR = "#d62728"


class FleetView(pn.viewable.Viewer):
    """Settings, the next-day button and the three figures of a :class:`FleetState`."""

    # a required argument of __init__: never None once built (param types it Optional, as it has no default)
    state = cast("param.ClassSelector[FleetState]", param.ClassSelector(class_=FleetState))

    def __init__(self, state: FleetState, **params: Any) -> None:
        ensure_bokeh_backend()
        super().__init__(state=state, **params)
        s, w = state, 250
        self.widgets = {
            "aircraft": pn.widgets.IntSlider(name="Aircraft", start=1, end=12, value=s.aircraft, width=w),
            "vertiports": pn.widgets.IntSlider(name="Vertiports (2 chargers each)", start=1, end=4,
                                               value=s.vertiports, width=w),
            "rate_per_h": pn.widgets.FloatSlider(name="Requests per hour", start=0.5, end=20, step=0.5,
                                                 value=s.rate_per_h, width=w),
            "age_spread_efc": pn.widgets.FloatSlider(name="Packs' age spread (equivalent full cycles)", start=0,
                                                     end=150, step=2, value=s.age_spread_efc, width=w),
            "seed": pn.widgets.IntInput(name="Seed", value=s.seed, start=0, width=w),
        }
        for key, widget in self.widgets.items():
            widget.param.watch(lambda e, k=key: setattr(s, k, e.new), "value_throttled"
                               if hasattr(widget, "value_throttled") else "value")
        self.run = pn.widgets.Button(name="Run the next day", button_type="primary", width=w,
                                     css_classes=["uam-fleet-run"])
        self.run.on_click(lambda _e: s.next_day())
        self.status = pn.pane.HTML("", css_classes=["uam-fleet-status"], sizing_mode="stretch_width")
        self.error = pn.pane.Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width")
        self.timeline_pane = pn.pane.HoloViews(self._timeline(), sizing_mode="stretch_width",
                                               css_classes=["uam-fleet-timeline"])
        self.packs_pane = pn.pane.HoloViews(self._packs(), sizing_mode="stretch_width", css_classes=["uam-fleet-packs"])
        self.days_pane = pn.pane.HoloViews(self._days(), sizing_mode="stretch_width", css_classes=["uam-fleet-days"])
        s.param.watch(self._on_days, ["days", "last"])
        s.param.watch(self._on_text, ["status", "error", "running"])
        self._on_text()

    def __panel__(self) -> pn.viewable.Viewable:
        text = intro(
            "A small fleet at one or more vertiports through operating days of 12 h. Each request is a round "
            "trip from its vertiport, flown by an aircraft based there; the "
            "packs (the paper's NASA cell) age with every flight by a law fitted to NASA's cells cycled to their "
            "end of life, a pack below 80% is replaced overnight, and each "
            "aircraft learns its own pack from its flights. **Health-aware** dispatching uses that belief, "
            "**health-blind** takes every pack as new with a fixed reserve, **hindsight** knows the truth. "
            "The same requests and packs for all three. The dotted line is the most any dispatcher could "
            "serve each day, knowing the whole day's demand and the truth (an upper bound).")
        controls = pn.Column(heading("Fleet"), *self.widgets.values(), self.run,
                             pn.pane.HTML("Changing a setting starts new fleets.", styles=NOTE_STYLE, width=250),
                             width=270)
        figures = pn.Column(self.error, self.status, self.days_pane, pn.Row(self.timeline_pane, self.packs_pane,
                                                                             sizing_mode="stretch_width"),
                            sizing_mode="stretch_width", min_width=560, styles={"flex": "1 1 560px"})
        return pn.Column(text, pn.FlexBox(controls, figures, flex_wrap="wrap", gap="10px",
                                           sizing_mode="stretch_width"), sizing_mode="stretch_width",
                         css_classes=["uam-fleet"])

    # ------------------------------------------------------------------ figures
    def _timeline(self) -> hv.Overlay:
        rows = self.state.timeline("aware")
        n = self.state.aircraft
        df = pd.DataFrame(rows, columns=["aircraft", "start_h", "end_h", "request", "breached"])
        y = [int(a[1:]) for a in df["aircraft"]]
        seg = hv.Segments((df["start_h"], y, df["end_h"], y, df["request"],
                           [BREACH_COLOR if b else PHYSICS_COLOR for b in df["breached"]]),
                          ["start (h)", "aircraft", "end (h)", "aircraft_end"], ["request", "color"]).opts(
            color="color", line_width=8, tools=["hover"])
        return seg.opts(title="Last day, health-aware: each aircraft's flights (red: breached)", height=260,
                        responsive=True, xlim=(0, 13), ylim=(0.5, n + 0.5),
                        yticks=[(k, f"#{k}") for k in range(1, n + 1)],
                        xlabel="hour of the day", ylabel="aircraft", hooks=[no_scroll_zoom], show_grid=True)

    def _packs(self) -> hv.Overlay:
        rows = self.state.packs("aware")
        x = list(range(1, len(rows) + 1))
        band = hv.ErrorBars([(k, r["belief_q_max"], r["belief_q_max"] - r["low"], r["high"] - r["belief_q_max"])
                             for k, r in zip(x, rows)], "pack", ["q_max (C)", "neg", "pos"],
                            label="belief (90% band)").opts(color=PHYSICS_COLOR, line_width=2)
        belief = hv.Scatter([(k, r["belief_q_max"]) for k, r in zip(x, rows)], "pack", "q_max (C)",
                            label="belief").opts(color=PHYSICS_COLOR, size=7)
        truth = hv.Scatter([(k, r["true_q_max"]) for k, r in zip(x, rows)], "pack", "q_max (C)",
                           label="truth (hidden)").opts(color="black", marker="x", size=10)
        return (band * belief * truth).opts(title="Each pack after the days flown: belief vs truth", height=260,
                                            responsive=True, legend_position="right", xlim=(0.5, len(rows) + 0.5),
                                            xticks=[(k, f"#{k}") for k in x], hooks=[no_scroll_zoom], show_grid=True)

    def _days(self) -> hv.Overlay:
        series = self.state.per_day()
        curves = [hv.Curve(series[d], "day", "stars served", label=LABELS[d]).opts(
                  color=COLORS[d], line_width=WIDTHS[d][0], line_dash="dashed" if d == "hindsight" else "solid") *
                  hv.Scatter(series[d], "day", "stars served").opts(color=COLORS[d], size=WIDTHS[d][1])
                  for d in sorted(DISPATCHERS, key=lambda d: -WIDTHS[d][0])]
        curves.append(hv.Curve(series["bound"], "day", "stars served", label="upper bound").opts(
            color="black", line_width=1, line_dash="dotted") *
            hv.Scatter(series["bound"], "day", "stars served").opts(color="black", marker="dash", size=14))
        n = max(1, len(self.state.days))
        return hv.Overlay(curves).opts(title="Served priority (stars) per day", height=240, responsive=True,
                                       legend_position="right", xlim=(0.5, n + 0.5), hooks=[no_scroll_zoom],
                                       show_grid=True)

    # ------------------------------------------------------------------ updates
    def _on_days(self, *_: Any) -> None:
        self.timeline_pane.object = self._timeline()
        self.packs_pane.object = self._packs()
        self.days_pane.object = self._days()

    def _on_text(self, *_: Any) -> None:
        s = self.state
        self.run.disabled = s.running
        self.status.object = f"<p>{html.escape(s.status)}</p>"
        self.error.object = html.escape(s.error)
        self.error.visible = bool(s.error)


__all__ = ["FleetView"]
