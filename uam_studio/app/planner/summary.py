"""The Planner tab's HTML panes: the plan's summary (planner, route, reach, safety verdict, notes) and the
planner comparison table, with the digest of what a plan was computed for (their ``data-inputs``).
Voltages in V.
"""

from __future__ import annotations

import html
from typing import Any

from uam_studio.app.planner.comparison import comparison_table
from uam_studio.app.planner.map_geometry import cycle_color
from uam_studio.app.planner.mission import mission_digest
from uam_studio.app.planner.state import PlannerState
from uam_studio.planning.missions.mission import VERTIPORT
from uam_studio.planning.planners import REFERENCE_PLANNER


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
                f"&middot; q_max {m.battery.q_max:.0f} C, R0 {m.battery.r0:.4g} ohm, EOD {m.eod_v:g} V")]
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
    (:func:`~uam_studio.app.planner.comparison.comparison_table`). The row of the selected policy is bold.

    Attributes: ``data-pending`` ("true" while a row is being computed) and ``data-inputs`` (the
    mission it compares, as in the summary's ``data-inputs`` without the policy)."""
    c = state.comparison
    e = html.escape
    pending = str(state.comparison_pending()).lower()
    inputs = html.escape(c["inputs"], quote=True) if c else ""
    head = (f"<div class='uam-plan-compare' data-pending='{pending}' data-inputs='{inputs}' "
            "style='font-size:12px;line-height:1.25'>")
    if c is None:
        return head + "<p style='margin:0;color:#666'>Planner comparison: off.</p></div>"
    shown = state.plan_request.policy if state.plan_request is not None else ""
    th = "style='text-align:{};padding:1px 8px 1px 0;border-bottom:1px solid #ccc;white-space:nowrap'"
    td = "style='text-align:{};padding:1px 8px 1px 0;white-space:nowrap'"
    cols = [("Planner", "left"), ("Priority", "right"), ("Reached", "right"), ("Cycles", "right"),
            ("Min V", "right"), ("Gap to oracle", "left")]
    rows = ["<tr>" + "".join(f"<th {th.format(al)}>{name}</th>" for name, al in cols) + "</tr>"]
    table = comparison_table(c)
    reference = any(r["key"] == REFERENCE_PLANNER and r.get("exact") is False for r in table)
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
