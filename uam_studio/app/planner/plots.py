"""The Planner tab's plots as holoviews elements: the map's places and route, the altitude per leg, the
voltage against EOD and the health estimate, each built from its data (km, m, minutes, V) by
:class:`PlannerPlots`, which :class:`~uam_studio.app.planner.view.PlannerView` extends.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import pandas as pd
from bokeh.core.properties import field, value
from bokeh.models import (
    ColumnDataSource,
    FixedTicker,
    HoverTool,
    PointDrawTool,
    Range1d,
)

# = bokeh.models.ColorBar, Legend, LegendItem: re-exports mypy misses (bokeh's stubs lack __all__)
from bokeh.models.annotations import ColorBar, Legend, LegendItem
from bokeh.palettes import Viridis256
from bokeh.transform import linear_cmap

from uam_studio.app.planner.map_geometry import (
    FAILED_COLOR,
    altitude_labels,
    leg_arrows,
    place_label,
    route_legs,
)
from uam_studio.app.services import population
from uam_studio.app.style import (
    NAME_OFFSET_PX,
    PHYSICS_COLOR,
    PREDICTED_COLOR,
    derived_looks,
    legend_above,
    page_figure,
)
from uam_studio.planning.missions.mission import VERTIPORT

if TYPE_CHECKING:
    from bokeh.models.mappers import LinearColorMapper

    from uam_studio.app.planner.state import PlannerState

VOLTAGE_POINTS = 800  # samples per series drawn in the voltage plot (its lowest points always kept)
WIDE_MIN_PX = 440  # narrowest width of the plan column and of the extra plots' column
VOLTAGE_HEIGHT_PX = 326  # the voltage plot: over a third of the tab's height at 1366x768 and 1920x1080,
# below the planners' comparison and above the fold at 1366x768 with the example mission


def _display_index(values: np.ndarray, limit: int) -> np.ndarray:
    """At most about ``limit`` indices of ``values``, evenly spread, with the first, the last and the
    lowest sample (what a plot needs to show the minimum against EOD)."""
    n = values.size
    if n <= limit:
        return np.arange(n)
    idx = np.linspace(0, n - 1, limit).round().astype(int)
    return np.unique(np.append(idx, int(np.argmin(values))))


class PlannerPlots:
    """The plots of :class:`~uam_studio.app.planner.view.PlannerView`: each plot's data from the view's
    ``state`` (a :class:`~uam_studio.app.planner.state.PlannerState`), and each plot a Bokeh figure
    built once (``_*_figure``) whose sources its ``_draw_*`` method replaces with that data."""

    # the view's, declared for the type checker (PlannerView sets them)
    state: PlannerState
    altitude_fig: Any
    voltage_fig: Any
    _on_points_edit: Callable[[str, Any, dict[str, Any]], None]

    def _route_data(self) -> dict[str, list]:
        """:func:`route_legs` of the plan, plus ``nodes``: every place on the map (x, y km)."""
        s = self.state
        rows = s.destination_rows()
        data = route_legs(s.plan, rows, (s.vertiport_x_km, s.vertiport_y_km))
        data["nodes"] = [(float(s.vertiport_x_km), float(s.vertiport_y_km))] + \
            [(float(r["x_km"]), float(r["y_km"])) for r in rows]
        data["names"] = [VERTIPORT] + [place_label(r["name"], r["priority"]) for r in rows]  # as drawn
        return data

    def _map_figure(self, half_km: float, frame_px: int) -> Any:
        """The map as a plain Bokeh figure, built once: the route (a segment per leg, coloured by
        charging cycle, dashed red where the physics check fails, an arrowhead and an altitude label
        per leg, a legend of the cycles), the places' names, the vertiport and the destinations, which
        a ``PointDrawTool`` adds, drags and deletes (its edits reach :meth:`_on_points_edit`).
        :meth:`_draw_points` and :meth:`_draw_map_route` put the state in it."""
        fig = page_figure(frame_width=frame_px, frame_height=frame_px,
                          x_range=Range1d(start=-half_km, end=half_km),
                          y_range=Range1d(start=-half_km, end=half_km),
                          x_axis_label="x (km)", y_axis_label="y (km)",
                          min_border_left=10, min_border_right=10,
                          title="Map (km): click to add, drag to move, select + Backspace to delete")
        fig.title.text_font_size = "9.5pt"
        leg_cols = ("x0", "y0", "x1", "y1", "color", "leg", "altitude_m")
        self._legs_src = ColumnDataSource({c: [] for c in (*leg_cols, "legend")})
        self._lost_src = ColumnDataSource({c: [] for c in (*leg_cols, "failed")})
        self._arrows_src = ColumnDataSource({"x": [], "y": [], "angle": [], "color": []})
        self._alt_src = ColumnDataSource({"x": [], "y": [], "text": []})
        legs = fig.segment("x0", "y0", "x1", "y1", source=self._legs_src, color="color", line_width=4, alpha=0.85)
        lost = fig.segment("x0", "y0", "x1", "y1", source=self._lost_src, color=FAILED_COLOR, line_width=3,
                           line_dash="dashed")
        fig.scatter("x", "y", source=self._arrows_src, marker="triangle", angle="angle", color="color", size=13,
                    line_color="white", line_width=1)
        fig.text("x", "y", text="text", source=self._alt_src, text_font_size="8pt", text_color="#333333",
                 text_align="center", text_baseline="middle", background_fill_color="white",
                 background_fill_alpha=0.85)
        # one legend entry per value of the legs' legend column (cycle 1, cycle 2...; failed), grouped by
        # BokehJS from the data, so the legend follows every plan without a new figure
        self._route_legend = Legend(items=[LegendItem(label=field("legend"), renderers=[legs]),
                                           LegendItem(label=field("failed"), renderers=[lost])],
                                    name="uam-route-legend", location="top_left", label_text_font_size="8pt",
                                    # bokeh's stubs type padding as a Property (bokeh/core/property_aliases.pyi)
                                    padding=4,  # type: ignore[arg-type]
                                    spacing=0, background_fill_alpha=0.8, visible=False)
        fig.add_layout(self._route_legend)
        fig.add_tools(HoverTool(renderers=[legs, lost], tooltips=[("leg", "@leg"), ("altitude (m)", "@altitude_m")]))
        self._names_src = ColumnDataSource({"x": [], "y": [], "text": []})
        self._vp_src = ColumnDataSource({"x": [], "y": []})
        fig.text("x", "y", text="text", source=self._names_src, text_font_size="9pt", text_font_style="bold",
                 text_color="#222222", text_align="center", text_baseline="bottom", y_offset=-NAME_OFFSET_PX)
        fig.scatter("x", "y", source=self._vp_src, marker="square", size=16, color="#d62728")
        fig.text("x", "y", text=value("vertiport"), source=self._vp_src, text_font_size="9pt", text_color="#d62728",
                 text_align="center", text_baseline="top", y_offset=NAME_OFFSET_PX)
        self._points_src = ColumnDataSource({c: [] for c in ("x_km", "y_km", "name", "priority", "wind_kts",
                                                               "dwell_s")})
        points = fig.scatter("x_km", "y_km", source=self._points_src, size=14, color="#444444", line_color="white",
                             line_width=2)
        draw = PointDrawTool(renderers=[points], add=True, drag=True, empty_value=0,
                             description="Click to add a destination, drag to move, select + Backspace to delete")
        fig.add_tools(draw, HoverTool(renderers=[points], tooltips=[
            ("name", "@name"), ("priority", "@priority"), ("wind (kt)", "@wind_kts"), ("dwell (s)", "@dwell_s")]))
        fig.toolbar.active_tap = draw
        fig.toolbar.active_drag = draw
        self._points_src.on_change("data", self._on_points_edit)
        return derived_looks(fig)

    def _draw_points(self, frame: pd.DataFrame) -> None:
        """The destinations (``frame``: the table's rows), their names and the vertiport on the map."""
        s = self.state
        self._points_src.data = {c: list(frame[c]) for c in self._points_src.data}
        self._names_src.data = {"x": list(frame["x_km"]), "y": list(frame["y_km"]),
                                "text": [place_label(n, p) for n, p in zip(frame["name"], frame["priority"])]}
        self._vp_src.data = {"x": [float(s.vertiport_x_km)], "y": [float(s.vertiport_y_km)]}

    def _draw_map_route(self, data: dict[str, list]) -> None:
        """:meth:`_route_data`'s legs on the map: flown legs by cycle, the failed ones dashed, an
        arrowhead and an altitude label per leg; the legend shown only where there are legs."""
        done = np.asarray(data["completed"], dtype=bool)
        cols = ("x0", "y0", "x1", "y1", "color", "leg", "altitude_m", "legend")

        def pick(mask: np.ndarray) -> dict[str, Any]:
            return {c: [v for v, k in zip(data[c], mask) if k] for c in cols}

        failed = pick(~done)
        failed["failed"] = failed.pop("legend")
        self._legs_src.data = pick(done)
        self._lost_src.data = failed
        self._arrows_src.data = leg_arrows(data)
        self._alt_src.data = altitude_labels(data, data.get("nodes", []), data.get("names", []))
        self._route_legend.visible = bool(len(done))

    def _altitude_figure(self) -> Any:
        """The cruise altitude per leg as a plain Bokeh figure, built once: a bar per leg (colour =
        charging cycle) with its altitude above it, the legs' names as the x axis' tick labels.
        :meth:`_draw_altitude` puts a route in it."""
        self._altitude_bars = ColumnDataSource({c: [] for c in ("left", "right", "top", "bottom", "color", "leg",
                                                                "altitude_m")})
        self._altitude_text = ColumnDataSource({"x": [], "y": [], "text": []})
        fig = page_figure(width=WIDE_MIN_PX, height=240,
                          x_range=Range1d(start=0.4, end=1.6), y_range=Range1d(start=0.0, end=3300.0),
                          y_axis_label="altitude (m)", title="Cruise altitude per leg (colour = charging cycle)")
        bars = fig.quad(left="left", right="right", top="top", bottom="bottom", source=self._altitude_bars,
                        fill_color="color", line_color="white")
        fig.text("x", "y", text="text", source=self._altitude_text, text_font_size="8pt", text_color="#222222",
                 text_align="center", text_baseline="middle")
        fig.add_tools(HoverTool(renderers=[bars], tooltips=[("leg", "@leg"), ("altitude (m)", "@altitude_m")]))
        fig.xaxis.ticker = FixedTicker(ticks=[1.0])
        fig.xaxis.major_label_orientation = np.radians(30)
        return derived_looks(fig)

    def _draw_altitude(self, data: dict[str, list]) -> None:
        """Put :meth:`_route_data`'s legs in the altitude figure (or say that nothing is flown)."""
        # Numeric x (leg number) with tick labels: categorical axes do not survive empty -> full updates.
        n = len(data["leg"])
        idx = np.arange(1, n + 1, dtype=float)
        alt = np.asarray(data["altitude_m"], dtype=float)
        self._altitude_bars.data = {"left": idx - 0.38, "right": idx + 0.38, "top": alt, "bottom": np.zeros(n),
                                    "color": list(data["color"]), "leg": list(data["leg"]), "altitude_m": alt}
        self._altitude_text.data = {"x": idx, "y": alt + 120, "text": [f"{a:g}" for a in alt]} if n else \
            {"x": [1.0], "y": [1650.0], "text": ["no route: nothing is flown"]}
        fig = self.altitude_fig
        fig.xaxis.ticker.ticks = [float(i) for i in idx] if n else [1.0]
        fig.xaxis.major_label_overrides = {float(i): str(lbl) for i, lbl in zip(idx, data["leg"])} if n else {1.0: ""}
        fig.x_range.update(start=0.4, end=max(n, 1) + 0.6)

    def _voltage_data(self) -> dict[str, Any]:
        """The voltage plot's series (minutes, V): physics (the plan's, or the failed take-off's),
        Dynaformer, its band, and the EOD line; each leg's take-off (min) and name (``legs``); with
        the axis ranges, which always include EOD.
        Each series is drawn with at most :data:`VOLTAGE_POINTS` samples, its lowest ones kept."""
        s = self.state
        plan = s.plan or {}
        eod = s.plan_request.mission.eod_v if s.plan_request is not None else s.eod_v
        phys = s.takeoff or plan.get("physics") or {"time_s": [], "voltage_v": []}
        pred = plan.get("predicted") or {"time_s": [], "voltage_v": []}
        band = s.band or {"time_s": [], "low_v": [], "high_v": [], "level": 0.9}
        t = np.asarray(phys["time_s"], float) / 60.0
        v = np.asarray(phys["voltage_v"], float)
        tp, vp = np.asarray(pred["time_s"], float) / 60.0, np.asarray(pred["voltage_v"], float)
        tb = np.asarray(band["time_s"], float) / 60.0
        lo, hi = np.asarray(band["low_v"], float), np.asarray(band["high_v"], float)
        values = np.concatenate([v, vp, lo, hi, [eod]])
        t_end = float(t[-1]) if t.size and t[-1] > 0 else 1.0
        i, ip, ib = (_display_index(x, VOLTAGE_POINTS) for x in (v, vp, lo))
        starts = [] if s.takeoff else list(plan.get("physics", {}).get("leg_start_s", []))
        route = list(plan.get("route", []))
        legs = ([round(float(t0) / 60.0, 3) for t0 in starts],
                [f"#{k} {to}" for k, to in enumerate(route[:len(starts)], 1)])
        y0, y1 = float(values.min()) - 0.05, float(values.max()) + 0.05
        return {"physics": (t[i], v[i]), "predicted": (tp[ip], vp[ip]), "band": (tb[ib], lo[ib], hi[ib]),
                "level": float(band["level"]), "eod": float(eod), "xlim": (0.0, t_end), "legs": legs,
                "ylim": (y0, y1 + 0.08 * (y1 - y0))}  # headroom for the legs' names

    def _voltage_figure(self) -> Any:
        """The voltage figure as plain Bokeh models, built once: a band, the physics and Dynaformer
        series, the EOD line, each leg's take-off (a dotted line and its name), and a legend above.
        :meth:`_draw_voltage` puts a frame's data in it (a new plan costs replacing some sources' data,
        not a new figure)."""
        # cast: the empty columns' lists give mypy no element type to infer
        src = {key: ColumnDataSource(cols) for key, cols in cast("tuple[tuple[str, dict[str, list]], ...]", (
            ("band", {"t": [], "low": [], "high": []}), ("physics", {"t": [], "v": []}),
            ("predicted", {"t": [], "v": []}), ("eod", {"t": [], "v": []}),
            ("legs", {"x": [], "y0": [], "y1": []}), ("leg_names", {"x": [], "y": [], "text": []})))}
        fig = page_figure(height=VOLTAGE_HEIGHT_PX, width=None, sizing_mode="stretch_width", align="start",
                          min_border_left=10, min_border_right=10, min_border_bottom=10, min_border_top=0,
                          x_range=Range1d(start=0.0, end=1.0), y_range=Range1d(start=2.9, end=4.3),
                          x_axis_label="time (min)",
                          y_axis_label="voltage (V)", title="Voltage: physics (what happens) vs Dynaformer (predicted)")
        fig.title.text_font_size = "10pt"
        band = fig.varea("t", "low", "high", source=src["band"], fill_color="#ff7f0e", fill_alpha=0.35)
        for edge in ("low", "high"):
            fig.line("t", edge, source=src["band"], color="#ff7f0e", line_alpha=0.8, line_width=1)
        phys = fig.line("t", "v", source=src["physics"], color=PHYSICS_COLOR, line_width=2)
        pred = fig.line("t", "v", source=src["predicted"], color=PREDICTED_COLOR, line_width=2, line_dash="dashed")
        eod = fig.line("t", "v", source=src["eod"], color=FAILED_COLOR, line_width=1.5, line_dash="dotted")
        fig.segment("x", "y0", "x", "y1", source=src["legs"], color="#777777", line_dash="dotted", line_width=1)
        fig.text("x", "y", text="text", source=src["leg_names"], text_font_size="8pt", text_color="#444444",
                 text_align="left", text_baseline="top")
        items = {key: LegendItem(label=value(key), renderers=[r]) for key, r in
                 (("band", band), ("physics", phys), ("predicted", pred), ("eod", eod))}
        fig.add_layout(Legend(items=list(items.values()), orientation="horizontal", label_text_font_size="8pt",
                              margin=0, padding=4), "above")  # type: ignore[arg-type]  # padding: as above
        self._voltage_src, self._voltage_items = src, items
        return derived_looks(fig)

    def _draw_voltage(self, data: dict[str, Any]) -> None:
        """Put :meth:`_voltage_data`'s frame in the voltage figure: its series, the axes' ranges (which
        include EOD), the legs' take-offs, and a legend entry for each series that has data."""
        src, items, fig = self._voltage_src, self._voltage_items, self.voltage_fig
        x0, x1 = data["xlim"]
        y0, y1 = data["ylim"]
        starts, names = data["legs"]
        tb, lo, hi = data["band"]
        src["band"].data = {"t": np.asarray(tb, float), "low": np.asarray(lo, float), "high": np.asarray(hi, float)}
        for key in ("physics", "predicted"):
            t, v = data[key]
            src[key].data = {"t": np.asarray(t, float), "v": np.asarray(v, float)}
        src["eod"].data = {"t": [x0, x1], "v": [data["eod"]] * 2}
        src["legs"].data = {"x": list(starts), "y0": [y0] * len(starts), "y1": [y1] * len(starts)}
        src["leg_names"].data = {"x": [x + 0.004 * (x1 - x0) for x in starts], "y": [y1] * len(starts),
                                 "text": list(names)}
        fig.x_range.update(start=x0, end=x1)
        fig.y_range.update(start=y0, end=y1)
        # a series with no data gets no legend entry (a failed take-off has no prediction)
        labels = {"band": f"Dynaformer {100 * data['level']:.0f}%", "physics": "physics", "predicted": "Dynaformer",
                  "eod": f"EOD {data['eod']:g} V"}
        shown = {"band": len(tb), "physics": len(data["physics"][0]), "predicted": len(data["predicted"][0]),
                 "eod": 1}
        for key, item in items.items():
            item.update(label=value(labels[key]), visible=bool(shown[key]))

    def _health_data(self) -> tuple[float, float] | None:
        return self.state.health

    def _health_figure(self) -> Any:
        """The health estimate against the training population as a plain Bokeh figure, built once:
        the population's cells (Dynaformer PCs, coloured by R0) and this cell's star, which
        :meth:`_draw_health` moves."""
        pop = population()
        cols = {"PC1": [], "PC2": [], "r0": [], "q_max": []} if pop is None else \
            {"PC1": pop.pc1, "PC2": pop.pc2, "r0": pop.r0, "q_max": pop.q_max}
        pc2 = np.asarray(cols["PC2"], float)
        lo, hi = (float(pc2.min()), float(pc2.max())) if pc2.size else (-1.0, 1.0)
        pc1 = np.asarray(cols["PC1"], float)
        x0, x1 = (float(pc1.min()), float(pc1.max())) if pc1.size else (-1.0, 1.0)
        fig = page_figure(width=WIDE_MIN_PX, height=280,
                          x_range=Range1d(start=x0 - 0.05 * (x1 - x0), end=x1 + 0.05 * (x1 - x0)),
                          y_range=Range1d(start=lo - 0.05 * (hi - lo), end=hi + 0.05 * (hi - lo)),
                          x_axis_label="PC1 (tracks R0)", y_axis_label="PC2 (tracks q_max)",
                          title="Health estimate (Dynaformer PCs) vs population")
        r0 = np.asarray(cols["r0"], float)
        mapper = linear_cmap("r0", Viridis256, float(r0.min()) if r0.size else 0.0, float(r0.max()) if r0.size else 1.0)
        dots = fig.scatter("PC1", "PC2", source=ColumnDataSource(cols), size=5, alpha=0.6, color=mapper,
                           legend_label="training population")
        self._health_src = ColumnDataSource({"PC1": [], "PC2": []})
        fig.scatter("PC1", "PC2", source=self._health_src, marker="star", size=22, color="#d62728",
                    line_color="black", legend_label="this cell")
        # linear_cmap's transform is a LinearColorMapper (bokeh's stubs type it as any Transform, or unset)
        fig.add_layout(ColorBar(color_mapper=cast("LinearColorMapper", mapper.transform), title="R0 (ohm)", width=12),
                       "right")
        fig.add_tools(HoverTool(renderers=[dots], tooltips=[("PC1", "@PC1{0.00}"), ("PC2", "@PC2{0.00}"),
                                                             ("R0 (ohm)", "@r0{0.000}"), ("q_max (C)", "@q_max{0}")]))
        legend_above(fig)
        return derived_looks(fig)

    def _draw_health(self, data: tuple[float, float] | None) -> None:
        """Put this cell's estimate (PC1, PC2) on the health figure (none: no star)."""
        self._health_src.data = {"PC1": [] if data is None else [float(data[0])],
                                 "PC2": [] if data is None else [float(data[1])]}
