"""The operator's interval of a chosen leg's lowest voltage: what it believes before it flies the leg, to hold
against what the world gives (:class:`~uam_studio.planning.operations.fly.FlightRecord`'s ``takeoff_belief``)."""

from __future__ import annotations

import numpy as np

from uam_studio.planning.operations.decision import Decision
from uam_studio.planning.operations.operator import Operator

__all__ = ["leg_lowest_voltage"]


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
