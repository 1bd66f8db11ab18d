"""An upper bound on a fleet's day: the most stars any dispatcher could serve, knowing the whole day.

Each :class:`Job` is one way to serve a request: one aircraft whose true pack flies the round trip
safely in the actual winds, with its flight and recharge times. :func:`day_bound` keeps, per vertiport,
the requests some aircraft there can fly safely, and bounds how many of them the vertiport's aircraft
and chargers can turn round in the day: a linear relaxation with two capacities (a fractional
knapsack, scipy's HiGHS), each request at its shortest flight and recharge over the aircraft that can
fly it:

- chargers: every served flight but each aircraft's last recharges before the aircraft's next take-off,
  after the day's first landing and before the last window closes: the recharge times sum to at most
  ``chargers x (last close - first landing) + aircraft x longest recharge``;
- aircraft: each served flight keeps its aircraft busy for its flight and its recharge, between the first
  take-off and the simulation's end: at most ``aircraft x (end - first take-off) + aircraft x longest
  recharge``.

Why it bounds every dispatcher (the fleet's truth at the day's start, which aging only worsens later in
the day: a pack that cannot fly a trip at dawn cannot fly it at dusk, and recharges only lengthen):
every simulated day, whatever the dispatcher, serves a set of such requests within those capacities,
so the bound is at least its served stars. It ignores when requests arrive inside the day beyond these
two sums, so it can be loose where bursts of demand, not totals, limit a fleet.

Public API: :class:`Job`, :func:`day_bound`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog

from uam_studio.errors import InputError

__all__ = ["Job", "day_bound"]


@dataclass(frozen=True, kw_only=True)
class Job:
    """One way to serve request number ``request``: aircraft ``aircraft`` based at vertiport ``port``
    takes off in [``earliest_s``, ``latest_s``] (s into the day), flies ``flight_s`` (s) and recharges
    ``charge_s`` (s) on one of the port's chargers; worth ``priority`` stars."""

    request: int
    aircraft: int
    port: int
    earliest_s: float
    latest_s: float
    flight_s: float
    charge_s: float
    priority: int


def _port_bound(jobs: Sequence[Job], chargers: int, aircraft: int, horizon_s: float) -> float:
    """The relaxation's most stars at one vertiport (a real number, before rounding down)."""
    best: dict[int, list[float]] = {}  # request -> [stars, shortest flight s, shortest recharge s]
    for j in jobs:
        if j.earliest_s + j.flight_s > horizon_s:
            continue  # cannot land before the simulation ends
        b = best.setdefault(j.request, [float(j.priority), j.flight_s, j.charge_s])
        b[1], b[2] = min(b[1], j.flight_s), min(b[2], j.charge_s)
    if not best:
        return 0.0
    stars, flight, charge = (np.array(col, dtype=float) for col in zip(*best.values()))
    first_off = min(j.earliest_s for j in jobs)
    first_landing = min(j.earliest_s + j.flight_s for j in jobs)
    last_close = max(j.latest_s for j in jobs)
    longest = float(charge.max())
    plug_time = chargers * max(last_close - first_landing, 0.0) + aircraft * longest
    air_time = aircraft * max(horizon_s - first_off, 0.0) + aircraft * longest
    res = linprog(-stars, A_ub=np.vstack([charge, flight + charge]), b_ub=[plug_time, air_time],
                  bounds=(0.0, 1.0), method="highs")
    if res.status != 0:
        raise RuntimeError(f"the day's relaxation did not solve: {res.message}")
    return float(-res.fun)


def day_bound(jobs: Sequence[Job], chargers: Sequence[int], aircraft_per_port: Sequence[int],
              horizon_s: float) -> int:
    """The most stars any day of ``jobs`` serves (an upper bound, a whole number): per vertiport its
    ``chargers`` and its ``aircraft_per_port`` in service, every flight landed by ``horizon_s`` (s)."""
    ports = min(len(chargers), len(aircraft_per_port))
    if any(not 0 <= j.port < ports for j in jobs):
        raise InputError("chargers", f"a charger and an aircraft count for each job's vertiport (0-{ports - 1})")
    total = 0
    for port in sorted({j.port for j in jobs}):
        mine = [j for j in jobs if j.port == port]
        total += int(math.floor(_port_bound(mine, int(chargers[port]), int(aircraft_per_port[port]), horizon_s)
                                + 1e-6))
    return total
