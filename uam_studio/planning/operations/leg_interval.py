"""The operator's interval of a chosen leg's lowest voltage: what it believes before it flies the leg, to hold
against what the world gives; and the take-off belief a flight record keeps
(:class:`~uam_studio.planning.operations.fly.FlightRecord`'s ``takeoff_belief``)."""

from __future__ import annotations

from typing import Any

import numpy as np

from uam_studio.battery.health.belief import ModelError, error_share
from uam_studio.planning.operations.decision import Decision
from uam_studio.planning.operations.operator import Operator

__all__ = ["leg_load", "leg_lowest_voltage", "takeoff_belief"]


def leg_load(op: Operator, d: Decision, first: bool, wind_kts: float) -> tuple[np.ndarray, np.ndarray]:
    """The load (A, 1 s samples) of the leg that ``op``'s decision ``d`` chose, in ``wind_kts`` (kt): ``(this
    charge's readings' current so far, clipped to +-50 A; the leg's planned current after them)``. ``first``: the
    leg continues the take-off check (its first samples already flown)."""
    assert d.next_to is not None and d.next_altitude_m is not None  # a decision with a next leg
    cur, _ = op.health_belief.segment.arrays()
    skip = cur.size if first else 0
    return np.clip(cur, -50, 50), op.leg_current(d.node, d.next_to, d.next_altitude_m, wind_kts)[skip:]


def leg_lowest_voltage(op: Operator, d: Decision, first: bool, level: float = 0.9) -> tuple[float, float, float]:
    """The ``level`` interval (low, median, high; V) of the lowest voltage on the leg that ``op``'s decision ``d``
    chose, on its belief now (:meth:`~uam_studio.battery.health.belief.HealthBelief.lowest_voltage`: the health,
    the leg's predicted wind one std either side, the model-error term). ``first``: the leg continues the take-off
    check (its first samples already flown)."""
    assert d.next_to is not None  # a decision with a next leg
    mean, sd = op.winds.predict(d.next_to)
    loads = [leg_load(op, d, first, w) for w in (mean, mean - sd, mean + sd)]
    return op.health_belief.lowest_voltage([np.concatenate(x) for x in loads], loads[0][0].size, level)


def takeoff_belief(first: Decision, op: Operator, leg: tuple[float, float, float, ModelError] | None
                   ) -> dict[str, Any]:
    """The belief the first decision planned on, with where it started and the logbook's length; where it chose a
    leg (``leg``: the interval's low, median and high, V, and the model-error term then), its model-error term
    (its std above the median and below it, V, and its share of the interval's variance) and its 90% interval of
    that leg's lowest voltage."""
    out = {"q_max_c": round(first.q_max_c, 3), "q_max_sd_c": round(first.q_max_sd_c, 3),
           "r0_ohm": round(first.r0_ohm, 6), "r0_sd_ohm": round(first.r0_sd_ohm, 6),
           "source": op.health_belief.source, "flights": len(op.health_belief.logbook)}
    if leg is not None:
        lo, med, hi, err = leg
        out["model_error_v"] = round(err.sd_v, 6)
        out["model_error_low_v"] = round(err.below_v, 6)
        out["model_error_share"] = round(error_share((lo, med, hi), err), 4)
        out["first_leg_min_voltage_90_v"] = [round(lo, 5), round(hi, 5)]
        out["first_leg_min_voltage_median_v"] = round(med, 5)
    return out
