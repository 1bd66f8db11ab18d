"""HoloViews figures shared by the classroom notebooks (bokeh backend).

Call ``hv.extension("bokeh")`` (or ``pn.extension()``) in the notebook first. Every function returns a
HoloViews object that a notebook displays or combines with ``+`` and ``*``.

Importing this module makes HoloViews draw on a 2D canvas (:func:`draw_on_canvas`): with its default,
WebGL, a student's browser without a GPU draws the axes and legends but no line.

- :func:`mission_map`: vertiport, destinations with their priority stars, and optionally a route,
  coloured by charging cycle (the paper's mission maps).
- :func:`curves`: several labelled (x, y) series in one overlay, with an optional horizontal line
  (e.g. the EOD cut-off).
- :func:`flight_voltage`: one flown mission's measured, predicted and true voltage against the
  cut-off, with the operator's decisions marked on the timeline.
- :func:`price_of_safety_figure`: the breach rate against the declared risk, and the priority served, of
  :func:`~uam_studio.planning.operations.safety_price.risk_levels`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import holoviews as hv
import holoviews.plotting.bokeh  # noqa: F401  (registers the bokeh backend, so .opts() works before hv.extension)
import numpy as np

from uam_studio.battery import DEFAULT_EOD_V
from uam_studio.planning.missions.mission import VERTIPORT, Mission
from uam_studio.planning.operations import FlightRecord
from uam_studio.planning.operations.safety_price import RATE_FLOOR, RiskLevel

__all__ = ["curves", "draw_on_canvas", "flight_voltage", "mission_map", "price_of_safety_figure", "sorties"]


def draw_on_canvas() -> None:
    """Make every HoloViews figure of this kernel draw on a 2D canvas, not with WebGL (HoloViews' default,
    which draws no line or marker in a browser without a GPU). Called when this module is imported."""
    from holoviews.plotting.bokeh import BokehRenderer

    BokehRenderer.webgl = False


draw_on_canvas()

PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")


def sorties(route: Sequence[str]) -> list[list[str]]:
    """Split a route into sorties: each starts at the vertiport and ends at the next landing there
    (the last one may end elsewhere). ``["A", "B", "vertiport", "C"]`` -> ``[["vertiport", "A", "B",
    "vertiport"], ["vertiport", "C"]]``."""
    out: list[list[str]] = []
    cur = [VERTIPORT]
    for name in route:
        cur.append(name)
        if name == VERTIPORT:
            out.append(cur)
            cur = [VERTIPORT]
    if len(cur) > 1:
        out.append(cur)
    return out


def mission_map(mission: Mission, route: Sequence[str] | None = None, title: str | None = None,
                width: int = 480, height: int = 420) -> hv.Overlay:
    """Map of ``mission`` (x, y in km): the vertiport (black square), destinations (size and label by
    priority, stars), and ``route`` as straight legs, one colour per charging cycle."""
    xs = [d.x_km for d in mission.destinations]
    ys = [d.y_km for d in mission.destinations]
    labels = [f"{d.name} {'*' * d.priority}" for d in mission.destinations]
    prio = [d.priority for d in mission.destinations]
    wind = [d.wind_kts for d in mission.destinations]
    dests = hv.Points((xs, ys, prio, wind, labels), kdims=["x_km", "y_km"],
                      vdims=["priority", "wind_kts", "name"], label="destinations").opts(
        size=hv.dim("priority") * 5 + 6, color="priority", cmap="Oranges", clim=(0, 3),
        line_color="black", tools=["hover"], show_legend=False)
    text = hv.Labels((xs, ys, labels), kdims=["x_km", "y_km"], vdims="name").opts(
        yoffset=3.0, text_font_size="9pt", text_color="black")
    vp = hv.Points([(mission.vertiport.x_km, mission.vertiport.y_km)], kdims=["x_km", "y_km"],
                   label="vertiport").opts(marker="square", size=14, color="black")
    layers: list[Any] = []
    for k, sortie in enumerate(sorties(route or [])):
        pts = [(mission.node(n).x_km, mission.node(n).y_km) for n in sortie]
        layers.append(hv.Curve(pts, "x_km", "y_km", label=f"charge {k + 1}").opts(
            color=PALETTE[k % len(PALETTE)], line_width=2.5, alpha=0.8))
    all_x = np.array(xs + [mission.vertiport.x_km])
    all_y = np.array(ys + [mission.vertiport.y_km])
    pad = 8.0
    return hv.Overlay([*layers, vp, dests, text]).opts(
        title=title or mission.name, width=width, height=height, data_aspect=1, legend_position="right",
        xlim=(all_x.min() - pad, all_x.max() + pad), ylim=(all_y.min() - pad, all_y.max() + pad))


def curves(series: Mapping[str, tuple[Sequence[float], Sequence[float]]], xlabel: str, ylabel: str,
           hline: float | None = None, title: str = "", width: int = 700, height: int = 320,
           marks: Sequence[Any] = (), **opts: Any) -> hv.Overlay:
    """One ``hv.Curve`` per labelled ``(x, y)`` series, overlaid; ``hline`` draws a dashed
    horizontal line (for example the 3.0 V cut-off); ``marks`` are more elements drawn over them (a
    ``hv.VLine`` at a phase's end). Give marks here rather than ``curves(...) * mark``: a product makes a
    new overlay, without this one's size, title and legend place."""
    items: list[Any] = [hv.Curve((np.asarray(x), np.asarray(y)), xlabel, ylabel, label=str(name)).opts(
        tools=["hover"]) for name, (x, y) in series.items()]
    if hline is not None:
        items.append(hv.HLine(hline).opts(color="gray", line_dash="dashed", line_width=1))
    items.extend(marks)
    return hv.Overlay(items).opts(title=title, width=width, height=height, legend_position="right", **opts)


def flight_voltage(rec: FlightRecord, eod_v: float = DEFAULT_EOD_V, title: str | None = None, width: int = 760,
                   height: int = 320) -> hv.Overlay:
    """A flight's voltage (V) over time (s): the sensor's readings, the operator's prediction for each leg
    (made when it chose the leg), the world's noise-free truth, the cut-off, and a dotted line at each
    decision (hover: its reason)."""
    t = rec.time_s
    items: list[Any] = [
        hv.Curve((t, rec.measured_voltage_v), "time_s", "voltage_v", label="measured (sensor)").opts(
            color="#9e9e9e", line_width=1, alpha=0.7),
        hv.Curve((t, rec.predicted_voltage_v), "time_s", "voltage_v", label="predicted by the operator").opts(
            color="#1f77b4", line_width=2, line_dash="dashed"),
        hv.Curve((t, rec.true_voltage_v), "time_s", "voltage_v", label="true (physics, hidden)").opts(
            color="#2ca02c", line_width=1.5),
        hv.HLine(eod_v, label="EOD cut-off").opts(color="#d62728", line_dash="dashed", line_width=1.5),
    ]
    marks = hv.Points([(d.time_s, eod_v, d.reason) for d in rec.events], kdims=["time_s", "voltage_v"],
                      vdims=["decision"], label="decisions").opts(
        marker="triangle", size=10, color="black", tools=["hover"])
    items += [hv.VLine(d.time_s).opts(color="black", line_dash="dotted", line_width=1) for d in rec.events]
    items.append(marks)
    lo = min(eod_v - 0.05, float(np.min(rec.true_voltage_v)) - 0.05) if t.size else eod_v - 0.05
    verdict = "BREACHED" if rec.breached else f"priority {rec.reached_priority}"
    return hv.Overlay(items).opts(title=title or f"{rec.mission}: {verdict}", width=width, height=height,
                                  legend_position="right", ylim=(lo, 4.25))


def price_of_safety_figure(levels: Sequence[RiskLevel], width: int = 380, height: int = 300) -> hv.Layout:
    """Two panels over the declared risk (log axis): the breach rate the flights realised, with its 95% interval,
    against the line "rate = declared risk" (points under it: the risk is kept); and the priority served over
    hindsight's, the operator's beside its pre-flight plan flown blind (a breach scores 0)."""
    risks = np.array([v.risk for v in levels])
    rate = np.array([v.rate for v in levels])
    lo, hi = rate - np.array([v.rate_low for v in levels]), np.array([v.rate_high for v in levels]) - rate
    span = np.array([risks.min() / 1.6, risks.max() * 1.6])
    ticks = [(float(r), f"{r:g}") for r in risks]
    floor = RATE_FLOOR
    breach = hv.Overlay([
        hv.Curve((span, span), "declared risk", "breach rate", label="rate = declared risk").opts(
            color="gray", line_dash="dashed"),
        hv.ErrorBars((risks, np.maximum(rate, floor), np.minimum(lo, rate), hi), "declared risk",
                     ["breach rate", "neg", "pos"]).opts(color=PALETTE[1]),
        hv.Scatter((risks, np.maximum(rate, floor)), "declared risk", "breach rate", label="flown (95% interval)").opts(
            color=PALETTE[1], size=9, tools=["hover"]),
    ]).opts(title="breach rate against the declared risk", logx=True, logy=True, width=width, height=height,
            legend_position="top", xlim=tuple(span), xticks=ticks, ylim=(floor / 1.5, 1.0))
    served = hv.Overlay([
        hv.Curve((risks, [v.priority_ratio for v in levels]), "declared risk", "priority / hindsight",
                 label="operator").opts(color=PALETTE[0], line_width=2),
        hv.Scatter((risks, [v.priority_ratio for v in levels]), "declared risk", "priority / hindsight").opts(
            color=PALETTE[0], size=8, tools=["hover"]),
        hv.Curve((risks, [v.blind_ratio for v in levels]), "declared risk", "priority / hindsight",
                 label="pre-flight plan flown blind").opts(color=PALETTE[2], line_dash="dashed"),
    ]).opts(title="what it serves (breach: 0)", logx=True, width=width, height=height, legend_position="top",
            xlim=tuple(span), xticks=ticks, ylim=(0.0, 1.05))
    return (breach + served).opts(shared_axes=False)
