"""The Planner tab: edit a mission on a map and in a table, and see the plan update live.

View only: everything it shows comes from a :class:`~uam_studio.app.planner_state.PlannerState`. The map's
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

from uam_studio.app.comparison import comparison_table
from uam_studio.app.planner_state import PlannerState, mission_digest
from uam_studio.app.services import APP_EOD_RANGE, APP_Q_RANGE, APP_R0_RANGE, population
from uam_studio.app.session import (
    ensure_bokeh_backend,
    in_server_session,
    respond_at_once,
    session_dispatcher,
)
from uam_studio.app.style import (
    NAME_OFFSET_PX,
    NOTE_STYLE,
    heading,
    label_background,
    leg_label,
    no_scroll_zoom,
    pixel_offset,
)
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning import plan_csv
from uam_studio.planning.missions.mission import COORD_RANGE_KM, SCENARIOS, VERTIPORT

CYCLE_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22")
FAILED_COLOR = "#d62728"
COLUMNS = ["name", "x_km", "y_km", "priority", "wind_kts", "dwell_s"]
MAP_HALF_KM = 80.0


def cycle_color(k: int) -> str:
    """Colour of charging cycle ``k`` (1-based)."""
    return CYCLE_COLORS[(k - 1) % len(CYCLE_COLORS)]


# ----------------------------------------------------------------------------- pure helpers


LEG_COLUMNS = ("leg", "from", "to", "x0", "y0", "x1", "y1", "altitude_m", "cycle", "color", "completed", "label",
               "legend")
FAILED_LABEL = "would not make it (physics)"


def route_legs(plan: dict[str, Any] | None, state_rows: list[dict[str, Any]], vertiport: tuple[float, float]) \
        -> dict[str, list]:
    """The legs of ``plan`` as columns (one entry per leg): from/to names and coordinates, altitude,
    charging cycle (1-based), colour, whether it was completed (physics check), a label and the
    map legend's entry (``"cycle k"`` or :data:`FAILED_LABEL`)."""
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
               "completed": not failed, "label": leg_label(i, alt),
               "legend": FAILED_LABEL if failed else f"cycle {cycle}"}
        for c in LEG_COLUMNS:
            out[c].append(row[c])
        if to == VERTIPORT:
            cycle += 1
        prev = to
    return out


ALT_LABEL_GAP_KM = 1.5  # the gap between a leg and the near edge of its label (km, at the default zoom)
ALT_LABEL_ALONG = (0.5, 0.35, 0.65, 0.25, 0.75, 0.1, 0.9)  # where along its leg a label may sit, in order of preference
ALT_LABEL_STEPS = (1.0, 2.5, 4.5, 7.0)  # how far from the leg, in gaps (farther only where the near spots are taken)


NAME_CHAR_KM = 2.6  # width of one character of a map name (9 pt bold) in km, at the map's default zoom
LABEL_CHAR_KM = 2.1  # width of one character of a leg label (8 pt) in km, at the map's default zoom
TEXT_HEIGHT_KM = 3.4  # height of a line of map text in km, at the map's default zoom
NAME_RISE_KM = 3.6  # a name's edge from its place (NAME_OFFSET_PX at the default zoom, ~2.75 px per km)
MARKER_KM = 2.0  # half the size of a place's marker in km


Box = tuple[float, float, float, float]  # x0, y0, x1, y1 (km)


def _overlap(a: Box, b: Box) -> float:
    """Area (km^2) shared by two boxes."""
    return max(0.0, min(a[2], b[2]) - max(a[0], b[0])) * max(0.0, min(a[3], b[3]) - max(a[1], b[1]))


def text_boxes(nodes: list[tuple[float, float]], names: list[str]) -> list[Box]:
    """The boxes the places' markers and names take on the map at its default zoom: a marker's box per
    place, and a name's above it (the vertiport's, named :data:`VERTIPORT`, below it; its whole width;
    an empty name takes none)."""
    out: list[Box] = [(x - MARKER_KM, y - MARKER_KM, x + MARKER_KM, y + MARKER_KM) for x, y in nodes]
    for (x, y), name in zip(nodes, names):
        if name:
            half = 0.5 * NAME_CHAR_KM * len(name)
            y0 = y - NAME_RISE_KM - TEXT_HEIGHT_KM if name == VERTIPORT else y + NAME_RISE_KM
            out.append((x - half, y0, x + half, y0 + TEXT_HEIGHT_KM))
    return out


def label_box(x: float, y: float, text: str) -> Box:
    """The box a leg label centred at (x, y) km takes at the map's default zoom."""
    half_w, half_h = 0.5 * LABEL_CHAR_KM * len(text), 0.5 * TEXT_HEIGHT_KM
    return x - half_w, y - half_h, x + half_w, y + half_h


def altitude_labels(legs: dict[str, list], nodes: list[tuple[float, float]] = (),
                    names: list[str] = ()) -> dict[str, list]:
    """One map label per pair of places the route flies between: the legs' numbers and altitudes in
    flying order (``"#1 500 m"``, or ``"#1/#2 1000/500 m"`` out and back), so out-and-back legs
    share one label.

    Each label goes beside its leg, clear of the leg by :data:`ALT_LABEL_GAP_KM` (its whole box, at
    any angle of the leg), at the spot (:data:`ALT_LABEL_ALONG` x either side x
    :data:`ALT_LABEL_STEPS`) that overlaps least the places' markers of ``nodes`` (x, y km), the
    names drawn above them (``names``, aligned with ``nodes``; their whole width) and the labels
    placed before it; ties go to the earlier spot. Sizes are those at the map's default zoom
    (:func:`text_boxes`, :func:`label_box`). Columns ``x``, ``y``, ``text``.
    """
    groups: dict[tuple[str, str], list[int]] = {}
    for i, (a, b) in enumerate(zip(legs["from"], legs["to"])):
        groups.setdefault(tuple(sorted((a, b))), []).append(i)
    taken = text_boxes(list(nodes), list(names))
    out: dict[str, list] = {"x": [], "y": [], "text": []}
    for idx in groups.values():
        i = idx[0]
        alts = [legs["altitude_m"][k] for k in idx]
        numbers = "/".join(f"#{k + 1}" for k in idx)
        text = f"{numbers} " + (f"{alts[0]:g} m" if len(set(alts)) == 1 else "/".join(f"{a:g}" for a in alts) + " m")
        x0, y0, x1, y1 = (float(legs[c][i]) for c in ("x0", "y0", "x1", "y1"))
        dx, dy = x1 - x0, y1 - y0
        norm = float(np.hypot(dx, dy)) or 1.0
        nx, ny = -dy / norm, dx / norm
        w, h = label_box(0.0, 0.0, text)[2:]
        reach = abs(nx) * w + abs(ny) * h  # the box's half-extent across the leg
        best, best_cost = None, np.inf
        for step in ALT_LABEL_STEPS:
            for t in ALT_LABEL_ALONG:
                for side in (1, -1):
                    d = side * (reach + step * ALT_LABEL_GAP_KM)
                    cx, cy = x0 + t * dx + d * nx, y0 + t * dy + d * ny
                    box = label_box(cx, cy, text)
                    cost = round(sum(_overlap(box, b) for b in taken), 2)
                    if cost < best_cost:
                        best, best_cost = (cx, cy), cost
            if best_cost == 0.0:
                break
        assert best is not None
        out["x"].append(best[0])
        out["y"].append(best[1])
        out["text"].append(text)
        taken.append(label_box(*best, text))
    return out


def label_overlaps(labels: dict[str, list], nodes: list[tuple[float, float]], names: list[str]) -> list[tuple[str, str]]:
    """Where leg labels (:func:`altitude_labels`' columns) cover another label, or a place's marker or
    name (``nodes``, ``names`` as there), at the map's default zoom: ``(label, what it covers)`` pairs
    (``"a place or its name"`` for the latter); empty when nothing overlaps."""
    boxes = [label_box(x, y, t) for x, y, t in zip(labels["x"], labels["y"], labels["text"])]
    others = text_boxes(list(nodes), list(names))
    texts = labels["text"]
    found = [(texts[i], texts[j]) for i in range(len(boxes)) for j in range(i + 1, len(boxes))
             if _overlap(boxes[i], boxes[j]) > 0]
    return found + [(texts[i], "a place or its name") for i, b in enumerate(boxes)
                    if any(_overlap(b, o) > 0 for o in others)]


ARROW_AT = 0.6  # arrowheads sit this far along their leg


def leg_arrows(legs: dict[str, list]) -> dict[str, list]:
    """An arrowhead per leg, :data:`ARROW_AT` of the way along it and pointing the way it is flown:
    columns ``x``, ``y`` (km), ``angle`` (rad, counter-clockwise from pointing up, Bokeh's
    triangle marker) and ``color``."""
    out: dict[str, list] = {"x": [], "y": [], "angle": [], "color": []}
    for x0, y0, x1, y1, color in zip(legs["x0"], legs["y0"], legs["x1"], legs["y1"], legs["color"]):
        if x0 == x1 and y0 == y1:
            continue
        out["x"].append(x0 + ARROW_AT * (x1 - x0))
        out["y"].append(y0 + ARROW_AT * (y1 - y0))
        out["angle"].append(float(np.arctan2(y1 - y0, x1 - x0) - np.pi / 2))
        out["color"].append(color)
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


def _display_index(values: np.ndarray, limit: int) -> np.ndarray:
    """At most about ``limit`` indices of ``values``, evenly spread, with the first, the last and the
    lowest sample (what a plot needs to show the minimum against EOD)."""
    n = values.size
    if n <= limit:
        return np.arange(n)
    idx = np.linspace(0, n - 1, limit).round().astype(int)
    return np.unique(np.append(idx, int(np.argmin(values))))


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


VERDICT_STYLE = {  # level -> (background, border)
    "safe": ("#e8f5e9", "#2e7d32"),
    "uncertain": ("#fff4e5", "#ed6c02"),
    "disagree": ("#fff4e5", "#ed6c02"),
    "unsafe": ("#fdecea", "#d32f2f"),
    "none": ("#f0f0f0", "#9e9e9e"),
}


def summary_html(state: PlannerState) -> str:
    """The summary pane (``<div class="uam-plan-summary">``): the planner (:meth:`PlannerState.plan_label`)
    and cell, route with altitudes, what it reaches, the safety verdict by source (``<div
    class="uam-verdict" data-level=...>``, :meth:`PlannerState.verdict`) and the planner's notes.

    Attributes: ``data-busy`` ("true" while a newer plan is being computed) and ``data-inputs``
    (:func:`request_digest` of the request the shown plan was computed for)."""
    req = state.plan_request
    inputs = "" if req is None else request_digest(req)
    return (f"<div class='uam-plan-summary' data-busy='{str(bool(state.busy)).lower()}' "
            f"data-inputs='{html.escape(inputs, quote=True)}' style='font-size:13px;line-height:1.35'>"
            f"{_summary_body(state)}</div>")


def request_digest(req: Any) -> str:
    """What a plan was computed for, compactly (the summary's ``data-inputs`` attribute): policy,
    scenario, cell, EOD, return wind and ``name:priority:wind`` of each destination. Lets a test or a
    script wait for the plan of a given edit."""
    return f"{req.policy};{mission_digest(req.mission)}"


def _p(body: str, cls: str = "") -> str:
    c = f" class='{cls}'" if cls else ""
    return f"<p{c} style='margin:0 0 5px 0'>{body}</p>"


def _summary_body(state: PlannerState) -> str:
    plan, req = state.plan, state.plan_request
    e = html.escape
    if state.plan_error:
        return f"<p class='uam-plan-error'><b>Planning error:</b> {e(state.plan_error)}</p>"
    if plan is None or req is None:
        return "<p>planning...</p>"
    m = req.mission
    parts = [_p(f"<b>Policy:</b> {e(state.plan_label())} &middot; <b>scenario:</b> {e(m.scenario)} "
                f"&middot; q_max {m.battery.q_max:g} C, R0 {m.battery.r0:g} ohm, EOD {m.eod_v:g} V")]
    if plan["route"]:
        legs = []
        cycle = 1
        for to, alt in zip(plan["route"], plan["altitudes_m"]):
            legs.append(f"<span style='color:{cycle_color(cycle)}'>{e(to)}</span> ({alt:g} m)")
            if to == VERTIPORT:
                cycle += 1
        parts.append(_p("<b>Route:</b> vertiport &rarr; " + " &rarr; ".join(legs), "uam-route"))
        parts.append(_p(f"<b>Reached:</b> {len(plan['reached'])} of {len(m.destinations)} "
                        f"(priority {plan['reached_priority']}) &middot; <b>charging cycles:</b> "
                        f"{plan['charging_cycles']}"))
    else:
        parts.append(_p("<b>Route:</b> none (nothing is flown)", "uam-route"))
    v = state.verdict()
    bg, border = VERDICT_STYLE[v["level"]]
    detail = f"<br>{e(v['text'])}" if v["text"] else ""
    parts.append(f"<div class='uam-verdict' data-level='{v['level']}' style='background:{bg};border-left:4px solid "
                 f"{border};padding:4px 8px;margin:0 0 5px 0'><b>{e(v['headline'])}</b>{detail}</div>")
    if plan.get("messages"):
        # at most about 3 lines tall (scrolls inside), so the voltage plot stays above the fold
        parts.append("<ul class='uam-notes' style='margin:0;padding-left:18px;color:#444;max-height:4.2em;"
                     "overflow-y:auto'>"
                     + "".join(f"<li>{e(msg)}</li>" for msg in plan["messages"]) + "</ul>")
    return "\n".join(parts)


def comparison_html(state: PlannerState) -> str:
    """The planner comparison (``<div class="uam-plan-compare">``): for the shown plan's mission, the
    learned planner, the paper's DQN beside it (marked where it cannot run: more than 8 destinations),
    greedy and the oracle (exact up to 8 destinations, the reference solver's plan
    beyond, which the heading then says), each planned by ``plan_mission``: priority reached, places
    reached, charging cycles, lowest physics voltage and the gap to the oracle
    (:func:`~uam_studio.app.comparison.comparison_table`). The row of the selected policy is bold.

    Attributes: ``data-pending`` ("true" while a row is being computed) and ``data-inputs`` (the
    mission it compares, as in the summary's ``data-inputs`` without the policy)."""
    c = state.comparison
    e = html.escape
    pending = str(state.comparison_pending()).lower()
    inputs = html.escape(c["inputs"], quote=True) if c else ""
    head = (f"<div class='uam-plan-compare' data-pending='{pending}' data-inputs='{inputs}' "
            "style='font-size:13px'>")
    if c is None:
        return head + "<p style='margin:0;color:#666'>Planner comparison: off.</p></div>"
    shown = state.plan_request.policy if state.plan_request is not None else ""
    th = "style='text-align:{};padding:1px 8px 1px 0;border-bottom:1px solid #ccc;white-space:nowrap'"
    td = "style='text-align:{};padding:1px 8px 1px 0;white-space:nowrap'"
    cols = [("Planner", "left"), ("Priority", "right"), ("Reached", "right"), ("Cycles", "right"),
            ("Min V", "right"), ("Gap to oracle", "left")]
    rows = ["<tr>" + "".join(f"<th {th.format(al)}>{name}</th>" for name, al in cols) + "</tr>"]
    table = comparison_table(c)
    reference = any(r["key"] == "oracle" and r.get("exact") is False for r in table)
    for r in table:
        weight = "font-weight:bold;" if r["policy"] == shown else ""
        label = f"<td {td.format('left')}>{e(r['label'])}</td>"
        if r.get("status") == "pending":
            rows.append(f"<tr class='uam-compare-{r['key']}' style='{weight}'>{label}"
                        f"<td colspan='5' style='color:#666'>computing...</td></tr>")
        elif r.get("status") == "unavailable":  # cannot run on this mission: a note, not a failure
            rows.append(f"<tr class='uam-compare-{r['key']}' style='{weight}'>{label}"
                        f"<td colspan='5' style='color:#666'>{e(r['error'])}</td></tr>")
        elif r.get("status") == "error":
            rows.append(f"<tr class='uam-compare-{r['key']}' style='{weight}'>{label}"
                        f"<td colspan='5' style='color:#b71c1c'>{e(r['error'] or 'failed')}</td></tr>")
        else:
            vmin = "-" if r["min_voltage_v"] is None else f"{r['min_voltage_v']:.3f}"
            if not r["safe"]:
                vmin += " (below EOD)"
            cells = [(str(r["priority"]), "right"), (f"{r['reached']} of {r['of']}", "right"),
                     (str(r["cycles"]), "right"), (vmin, "right"), (e(r["gap"]), "left")]
            rows.append(f"<tr class='uam-compare-{r['key']}' style='{weight}'>{label}"
                        + "".join(f"<td {td.format(al)}>{text}</td>" for text, al in cells) + "</tr>")
    note = "; oracle: the reference solver's plan, not proven optimal" if reference else ""
    return (head + "<b>Planners on this mission</b> <span style='color:#555'>(<code>plan_mission</code>, as "
            f"the CLI; Min V: physics{note})</span>"
            "<table style='border-collapse:collapse;margin-top:2px'>" + "".join(rows) + "</table></div>")


# ----------------------------------------------------------------------------- the view


BUSY_AFTER_MS = 150  # served: a plan taking longer than this shows the busy state
VOLTAGE_POINTS = 800  # samples per series drawn in the voltage plot (its lowest points always kept)
CONTROLS_WIDTH = 260
MAP_FRAME_PX = 440  # the map's square frame (data area)
WIDE_MIN_PX = 440  # narrowest width of the plan column and of the extra plots' column
VOLTAGE_HEIGHT_PX = 340  # the voltage plot: over a third of the tab's height at 1366x768 and 1920x1080


def _route_legend(plot: Any, element: Any) -> None:
    """Bokeh hook of the map's route segments: one legend entry per value of the legs' ``legend``
    column (``cycle 1``, ``cycle 2``...; ``failed`` for the legs that would not make it), grouped by
    BokehJS from the data (the hover tool puts the columns in the data source), so the legend
    follows every new plan without a new figure."""
    from bokeh.models import Legend, LegendItem

    fig = plot.state
    renderer = plot.handles.get("glyph_renderer")
    if renderer is None:
        return
    legend = next((lg for lg in fig.legend if getattr(lg, "name", None) == "uam-route-legend"), None)
    if legend is None:
        legend = Legend(items=[], name="uam-route-legend", location="top_left", label_text_font_size="8pt",
                        padding=4, spacing=0, background_fill_alpha=0.8)
        fig.add_layout(legend)
    if not any(renderer in item.renderers for item in legend.items):
        # one column name per renderer: BokehJS reads a field label from its item's first renderer only
        field = "failed" if "failed" in [d.name for d in element.vdims] else "legend"
        legend.items.append(LegendItem(label={"field": field}, renderers=[renderer]))


class PlannerView(pn.viewable.Viewer):
    """Map, table, controls, plots, summary and planner comparison of a :class:`PlannerState`.

    Layout (a wrapping flex row, sized for 1366 px wide screens and up): the controls, the map with
    the table under it, the plan (summary, comparison, voltage against EOD) and the other plots
    (altitude per leg, health estimate), which wrap below on narrow screens and stand beside the
    plan on wide ones.
    """

    state = param.ClassSelector(class_=PlannerState)

    def __init__(self, state: PlannerState, **params: Any) -> None:
        ensure_bokeh_backend()
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

        self._route_tpl = self._route_templates()
        self._voltage_tpl = self._voltage_templates()
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
            hv.opts.Overlay(frame_width=MAP_FRAME_PX, frame_height=MAP_FRAME_PX, show_grid=True,
                            title="Map (km): click to add, drag to move, select + Backspace to delete",
                            xlim=(-h, h), ylim=(-h, h), xlabel="x (km)", ylabel="y (km)", fontsize={"title": "9.5pt"})),
            css_classes=["uam-map"], linked_axes=False, margin=(0, 5))
        self.altitude_plot = pn.pane.HoloViews(
            hv.DynamicMap(self._altitude_element, streams=[self._route_pipe]), linked_axes=False)
        self.voltage_plot = pn.pane.HoloViews(
            hv.DynamicMap(self._voltage_element, streams=[self._voltage_pipe]),
            linked_axes=False, sizing_mode="stretch_width", css_classes=["uam-voltage"])
        self.health_plot = pn.pane.HoloViews(self._population_element() * hv.DynamicMap(
            self._health_element, streams=[self._health_pipe]), linked_axes=False)
        # The class sits on the content (inside the pane's shadow root), so that a locator for
        # ".uam-plan-summary" finds exactly one element whose text is the summary.
        self.summary = pn.pane.HTML(summary_html(s), sizing_mode="stretch_width", margin=(0, 10))
        self.compare = pn.pane.HTML(comparison_html(s), sizing_mode="stretch_width", margin=(0, 10))
        self.busy = pn.indicators.LoadingSpinner(value=s.busy, size=18, name="planning..." if s.busy else "",
                                                 css_classes=["uam-busy"], margin=(0, 5))
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
        table = pn.panel(lambda: self.table, defer_load=True, height=230, sizing_mode="stretch_width") \
            if in_server_session() else self.table
        center = pn.Column(self.map, hint, self.table_error, table, width=MAP_FRAME_PX + 100,
                           css_classes=["uam-map-column"])
        # Served, the plots that are not above the fold load right after the page (defer_load): the
        # map, the table, the summary, the comparison and the voltage come first.
        extras = (self.altitude_plot, self.health_plot)
        if in_server_session():
            extras = tuple(pn.panel(lambda p=p: p, defer_load=True) for p in extras)
        results = pn.Column(pn.Row(heading("Plan"), self.busy), self.summary,
                            self.voltage_plot, self.compare, min_width=WIDE_MIN_PX, sizing_mode="stretch_width",
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
            self._points_pipe.send(df)
        finally:
            self._syncing = False

    def _on_destinations(self, *events: param.parameterized.Event) -> None:
        with pn.io.hold():
            self._sync_destinations()
            self._send("route", self._route_pipe, self._route_data())

    def _on_plan(self, *events: param.parameterized.Event) -> None:
        with pn.io.hold():  # one batch of model changes per plan: each costs the browser a page layout
            self.summary.object = summary_html(self.state)
            self.compare.object = comparison_html(self.state)  # the bold row follows the policy
            self._send("route", self._route_pipe, self._route_data())
            self._send("voltage", self._voltage_pipe, self._voltage_data())
            self._send("health", self._health_pipe, self._health_data())

    def _on_comparison(self, event: param.parameterized.Event) -> None:
        self.compare.object = comparison_html(self.state)

    def _send(self, key: str, pipe: hv.streams.Pipe, data: Any) -> None:
        """Send ``data`` on ``pipe`` unless it equals the last data sent there (re-rendering a plot
        costs tens of ms)."""
        if key in self._sent and _equal(self._sent[key], data):
            return
        self._sent[key] = data
        pipe.send(data)

    def _on_busy(self, event: param.parameterized.Event) -> None:
        """Served, the busy state is shown only once a plan has taken :data:`BUSY_AFTER_MS`: every
        change sent to the browser costs it a page layout (about 0.15 s on a 2-core laptop), which a
        fast plan would otherwise pay twice."""
        if event.new:
            self._busy_later(self._show_busy)
        elif self._busy_shown:
            self._busy_shown = False
            self.summary.object = summary_html(self.state)  # data-busy
            self.busy.value = False
            self.busy.name = ""

    def _show_busy(self) -> None:
        if self.state.busy and not self._busy_shown:
            self._busy_shown = True
            self.summary.object = summary_html(self.state)  # data-busy
            self.busy.value = True
            self.busy.name = "planning..."

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

    # ------------------------------------------------------------------ plots

    def _route_data(self) -> dict[str, list]:
        """:func:`route_legs` of the plan, plus ``nodes``: every place on the map (x, y km)."""
        s = self.state
        rows = s.destination_rows()
        data = route_legs(s.plan, rows, (s.vertiport_x_km, s.vertiport_y_km))
        data["nodes"] = [(float(s.vertiport_x_km), float(s.vertiport_y_km))] + \
            [(float(r["x_km"]), float(r["y_km"])) for r in rows]
        data["names"] = [VERTIPORT] + [f"{r['name']} {'*' * int(r['priority'])}" for r in rows]  # as drawn
        return data

    @staticmethod
    def _points_element(data: pd.DataFrame) -> hv.Points:
        return hv.Points(data, kdims=["x_km", "y_km"], vdims=["name", "priority", "wind_kts", "dwell_s"]).opts(
            size=14, color="#444444", line_color="white", line_width=2, tools=["hover"],
            active_tools=["point_draw"], hooks=[no_scroll_zoom],
        )

    def _names_element(self, data: pd.DataFrame) -> hv.Overlay:
        s = self.state
        rows = s.destination_rows()
        names = hv.Labels({"x": [r["x_km"] for r in rows], "y": [r["y_km"] for r in rows],
                           "text": [f"{r['name']} {'*' * int(r['priority'])}" for r in rows]},
                          kdims=["x", "y"], vdims="text").opts(text_font_size="9pt", text_font_style="bold",
                                                               text_color="#222222", text_baseline="bottom",
                                                               hooks=[pixel_offset(-NAME_OFFSET_PX)])
        vp = hv.Points([(s.vertiport_x_km, s.vertiport_y_km)], kdims=["x_km", "y_km"]).opts(
            marker="square", size=16, color="#d62728")
        vp_label = hv.Labels([(s.vertiport_x_km, s.vertiport_y_km, "vertiport")], kdims=["x", "y"],
                             vdims="text").opts(text_font_size="9pt", text_color="#d62728", text_baseline="top",
                                                hooks=[pixel_offset(NAME_OFFSET_PX)])
        return names * vp * vp_label

    @staticmethod
    def _route_templates() -> dict[str, Any]:
        """Styled empty elements of the route; each frame clones them with new data, keeping their
        styles without an ``.opts`` call (which costs milliseconds) per frame."""
        kd = ["x0", "y0", "x1", "y1"]
        empty = {c: [] for c in ("x0", "y0", "x1", "y1", "color", "leg", "altitude_m")}
        return {
            "legs": hv.Segments({**empty, "legend": []}, kd, ["color", "leg", "altitude_m", "legend"]).opts(
                color="color", line_width=4, alpha=0.85, tools=["hover"], hooks=[_route_legend]),
            "lost": hv.Segments({**empty, "failed": []}, kd, ["color", "leg", "altitude_m", "failed"]).opts(
                color=FAILED_COLOR, line_width=3, line_dash="dashed", tools=["hover"], hooks=[_route_legend]),
            "labels": hv.Labels({"x": [], "y": [], "text": []}, ["x", "y"], "text").opts(
                text_font_size="8pt", text_color="#333333", text_align="center", text_baseline="middle",
                hooks=[label_background]),
            "arrows": hv.Points({"x": [], "y": [], "angle": [], "color": []}, ["x", "y"], ["angle", "color"]).opts(
                marker="triangle", angle="angle", color="color", size=13, line_color="white", line_width=1),
        }

    def _route_element(self, data: dict[str, list]) -> hv.Overlay:
        done = np.asarray(data["completed"], dtype=bool)
        cols = ("x0", "y0", "x1", "y1", "color", "leg", "altitude_m", "legend")

        def pick(mask: np.ndarray) -> dict[str, Any]:
            return {c: [v for v, k in zip(data[c], mask) if k] for c in cols}

        failed = pick(~done)
        failed["failed"] = failed.pop("legend")
        tpl = self._route_tpl
        return (tpl["legs"].clone(pick(done)) * tpl["lost"].clone(failed) * tpl["arrows"].clone(leg_arrows(data))
                * tpl["labels"].clone(altitude_labels(data, data.get("nodes", []), data.get("names", []))))

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
        ).opts(width=WIDE_MIN_PX, height=240, title="Cruise altitude per leg (colour = charging cycle)")

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

    @staticmethod
    def _voltage_templates() -> dict[str, Any]:
        """Styled empty elements of the voltage plot (cloned with each frame's data, as the route's);
        each frame's axes follow its data, which include the EOD line (framewise)."""
        kd, vd = "time (min)", "voltage (V)"
        empty = ([0.0], [0.0])
        band = hv.Area(([0.0], [0.0], [0.0]), kd, [vd, "high"], label="Dynaformer 90%").opts(
            color="#ff7f0e", alpha=0.35, line_color="#ff7f0e", line_alpha=0.8, line_width=1, framewise=True)
        leg_lines = hv.VLines([], kd).opts(color="#777777", line_dash="dotted", line_width=1)
        leg_names = hv.Labels({"x": [], "y": [], "text": []}, ["x", "y"], "text").opts(
            text_font_size="8pt", text_color="#444444", text_align="left", text_baseline="top", xoffset=0.0)
        phys = hv.Curve(empty, kd, vd, label="physics").opts(color="#1f77b4", line_width=2, framewise=True)
        pred = hv.Curve(empty, kd, vd, label="Dynaformer").opts(color="#ff7f0e", line_width=2, line_dash="dashed",
                                                               framewise=True)
        eod = hv.Curve(empty, kd, vd, label="EOD").opts(color=FAILED_COLOR, line_width=1.5, line_dash="dotted",
                                                        framewise=True)
        overlay = (band * phys * pred * eod * leg_lines * leg_names).opts(
            responsive=True, height=VOLTAGE_HEIGHT_PX, legend_position="top", legend_cols=4, show_grid=True,
            fontsize={"legend": "8pt", "title": "10pt"},
            title="Voltage: physics (what happens) vs Dynaformer (predicted)")
        return {"overlay": overlay, "band": band, "physics": phys, "predicted": pred, "eod": eod,
                "leg_lines": leg_lines, "leg_names": leg_names}

    def _voltage_element(self, data: dict[str, Any]) -> hv.Overlay:
        tpl = self._voltage_tpl
        x0, x1 = data["xlim"]
        starts, names = data["legs"]
        tb, lo, hi = data["band"]
        # a series with no data gets no legend entry (a failed take-off has no prediction)
        return tpl["overlay"].clone([
            tpl["band"].clone((tb, lo, hi), label=f"Dynaformer {100 * data['level']:.0f}%" if len(tb) else ""),
            tpl["physics"].clone(data["physics"], label="physics" if len(data["physics"][0]) else ""),
            tpl["predicted"].clone(data["predicted"], label="Dynaformer" if len(data["predicted"][0]) else ""),
            tpl["eod"].clone(([x0, x1], [data["eod"]] * 2), label=f"EOD {data['eod']:g} V"),
            tpl["leg_lines"].clone(list(starts)),
            tpl["leg_names"].clone({"x": [x + 0.004 * (x1 - x0) for x in starts], "y": [data["ylim"][1]] * len(starts),
                                    "text": list(names)}),
        ])

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
            width=WIDE_MIN_PX, height=280, title="Health estimate (Dynaformer PCs) vs population", show_grid=True,
            legend_position="top", legend_cols=2, xlabel="PC1 (tracks R0)", ylabel="PC2 (tracks q_max)")

    @staticmethod
    def _health_element(data: tuple[float, float] | None) -> hv.Points:
        pts = [] if data is None else [tuple(data)]
        return hv.Points(pts, ["PC1", "PC2"], label="this cell").opts(
            color="#d62728", marker="star", size=22, line_color="black")
