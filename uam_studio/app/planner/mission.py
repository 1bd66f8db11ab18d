"""The Planner's mission as plain values: the example mission it starts from, the digest of what a plan
of a mission depends on, and the destinations of the table's and the map's rows (x, y in km, wind in
kt, dwell in s).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from uam_studio.battery import DEFAULT_EOD_V, DEFAULT_Q_MAX, DEFAULT_R0
from uam_studio.errors import InputError
from uam_studio.planning.missions.mission import Destination, Mission
from uam_studio.planning.missions.scenario import DEFAULT_SCENARIO

__all__ = ["EXAMPLE_MISSION", "mission_digest", "rows_to_destinations"]

EXAMPLE_MISSION: dict[str, Any] = {
    "name": "Bay shuttle",
    "vertiport": {"x_km": 0.0, "y_km": 0.0, "wind_kts": 8.0},
    "destinations": [
        {"name": "Richmond", "x_km": 14.0, "y_km": 16.0, "priority": 2, "wind_kts": 13.0, "dwell_s": 300.0},
        {"name": "Hayward", "x_km": 27.0, "y_km": -18.0, "priority": 1, "wind_kts": -10.0, "dwell_s": 600.0},
        {"name": "Fremont", "x_km": 38.0, "y_km": -32.0, "priority": 3, "wind_kts": -5.0},
        {"name": "Napa", "x_km": 18.0, "y_km": 55.0, "priority": 2, "wind_kts": 20.0, "dwell_s": 300.0},
    ],
    "scenario": DEFAULT_SCENARIO,
    "battery": {"q_max": DEFAULT_Q_MAX, "r0": DEFAULT_R0},
    "eod_v": DEFAULT_EOD_V,
}
"""The bundled example (``assets/example_mission.json``), the app's starting mission."""


def mission_digest(m: Mission) -> str:
    """What a plan of ``m`` depends on, compactly: scenario, cell, EOD, return wind and
    ``name:priority:wind`` of each destination (the app's ``data-inputs`` attributes)."""
    dests = "|".join(f"{d.name}:{d.priority}:{d.wind_kts:g}" for d in m.destinations)
    return (f"{m.scenario};q_max={m.battery.q_max:g};r0={m.battery.r0:g};eod={m.eod_v:g};"
            f"return_wind={m.vertiport.wind_kts:g};{dests}")


def _clean_float(value: Any, default: float) -> Any:
    """NaN/None/'' -> default; numbers as float; anything else unchanged (the library names it)."""
    if value is None or (isinstance(value, str) and not value.strip()):
        return default
    if isinstance(value, (bool, np.bool_)):
        return value
    if isinstance(value, (int, float, np.integer, np.floating)):
        f = float(value)
        return default if math.isnan(f) else f
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


def rows_to_destinations(rows: list[dict[str, Any]]) -> list[Destination]:
    """The destinations of the table's or the map's rows (what ``PlannerState.set_destinations`` takes:
    a missing name becomes the first free ``D<k>``, a missing or 0 priority 1, wind and dwell 0;
    coordinates rounded to 0.1 km); raises InputError naming the row and its field."""
    used = {str(r.get("name")).strip() for r in rows if isinstance(r.get("name"), str)}
    k, dests = 1, []
    for i, r in enumerate(rows):
        name = r.get("name")
        if not isinstance(name, str) or not name.strip():
            while f"D{k}" in used:
                k += 1
            name = f"D{k}"
            used.add(name)
        prio = _clean_float(r.get("priority"), 1.0)
        if isinstance(prio, float) and prio == 0.0:
            prio = 1.0
        x = _clean_float(r.get("x_km"), float("nan"))
        y = _clean_float(r.get("y_km"), float("nan"))
        if isinstance(x, float) and math.isfinite(x):
            x = round(x, 1)
        if isinstance(y, float) and math.isfinite(y):
            y = round(y, 1)
        try:
            dests.append(Destination(name.strip(), x, y, prio, _clean_float(r.get("wind_kts"), 0.0),
                                     _clean_float(r.get("dwell_s"), 0.0)))
        except InputError as err:
            label = f"destinations[{i}] ({name.strip()})"
            raise InputError(f"{label}.{err.field}", str(err)[len(err.field) + 2:]) from None
    return dests
