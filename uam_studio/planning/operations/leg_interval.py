"""The operator's interval of a chosen leg's lowest voltage: what it believes before it flies the leg, to hold
against what the world gives; and the take-off belief a flight record keeps
(:class:`~uam_studio.planning.operations.fly.FlightRecord`'s ``takeoff_belief``)."""

from __future__ import annotations

from typing import Any

import numpy as np

from uam_studio.battery.health.intervals import two_sided_z
from uam_studio.planning.operations.decision import Decision
from uam_studio.planning.operations.operator import Operator

__all__ = ["leg_lowest_voltage", "takeoff_belief"]


def leg_lowest_voltage(op: Operator, d: Decision, first: bool, level: float = 0.9) -> tuple[float, float, float]:
    """The ``level`` interval (low, median, high; V) of the lowest voltage on the leg that ``op``'s decision ``d``
    chose, on its belief now (:meth:`~uam_studio.battery.health.belief.HealthBelief.lowest_voltage`: the health,
    the leg's predicted wind one std either side, the model-error term). ``first``: the leg continues the take-off
    check (its first samples already flown)."""
    assert d.next_to is not None and d.next_altitude_m is not None  # a decision with a next leg
    cur, _ = op.health_belief.segment.arrays()
    hist = np.clip(cur, -50, 50)
    mean, sd = op.winds.predict(d.next_to)
    skip = cur.size if first else 0
    loads = [np.concatenate([hist, op.leg_current(d.node, d.next_to, d.next_altitude_m, w)[skip:]])
             for w in (mean, mean - sd, mean + sd)]
    return op.health_belief.lowest_voltage(loads, hist.size, level)


def takeoff_belief(first: Decision, op: Operator, leg: tuple[float, float, float, float] | None) -> dict[str, Any]:
    """The belief the first decision planned on, with where it started and the logbook's length; where it chose a
    leg (``leg``: the interval's low, median and high, V, and the model-error term then, V), its model-error term
    and its 90% interval of that leg's lowest voltage."""
    out = {"q_max_c": round(first.q_max_c, 3), "q_max_sd_c": round(first.q_max_sd_c, 3),
           "r0_ohm": round(first.r0_ohm, 6), "r0_sd_ohm": round(first.r0_sd_ohm, 6),
           "source": op.health_belief.source, "flights": len(op.health_belief.logbook)}
    if leg is not None:
        out["model_error_v"] = round(leg[3], 6)
        sd = (leg[2] - leg[0]) / (2 * two_sided_z(0.9))  # the interval's std, V
        out["model_error_share"] = round(min(leg[3] ** 2 / sd ** 2, 1.0), 4) if sd > 0 else 0.0
        out["first_leg_min_voltage_90_v"] = [round(leg[0], 5), round(leg[2], 5)]
        out["first_leg_min_voltage_median_v"] = round(leg[1], 5)
    return out
