"""The geometry of the Planner map's route, free of Panel: the legs of a plan with their charging-cycle
colours, leg labels and where they go beside their legs, and the legs' arrowheads.

Distances and sizes are in km on the map (text sizes at the map's default zoom); angles in rad.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from uam_studio.planning.missions.mission import VERTIPORT

CYCLE_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22")
FAILED_COLOR = "#d62728"


def cycle_color(k: int) -> str:
    """Colour of charging cycle ``k`` (1-based)."""
    return CYCLE_COLORS[(k - 1) % len(CYCLE_COLORS)]


def leg_label(number: int, altitude_m: float) -> str:
    """A leg's map label: its number in flying order (1-based) and its cruise altitude (m), ``"#2 500 m"``."""
    return f"#{number} {altitude_m:g} m"


LEG_COLUMNS = ("leg", "from", "to", "x0", "y0", "x1", "y1", "altitude_m", "cycle", "color", "completed", "label",
               "legend")
FAILED_LABEL = "would not make it (physics)"


def place_label(name: str, priority: int) -> str:
    """A destination's name as the maps draw it: the name and its priority in stars (``"Napa **"``)."""
    return f"{name} {'*' * int(priority)}"


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


def altitude_labels(legs: dict[str, list], nodes: Sequence[tuple[float, float]] = (),
                    names: Sequence[str] = ()) -> dict[str, list]:
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


def label_overlaps(labels: dict[str, list], nodes: list[tuple[float, float]],
                   names: list[str]) -> list[tuple[str, str]]:
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
