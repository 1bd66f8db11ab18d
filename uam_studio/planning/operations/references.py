"""The references a flight is measured against, flown in the operator's world (same true cell, same actual winds,
same events; each in a fresh :class:`~uam_studio.planning.operations.world.World` with the flight's seed):

* the **blind** plan: the operator's pre-flight plan (after the take-off check) flown to the end with no
  re-planning;
* the **hindsight** reference: the best plan knowing the true cell and the actual winds as they were at each
  leg's time. With no scripted event it is the exact oracle's plan; with events, the best of the exact plans
  for each period of constant winds and the route flown, each flown in the same world (:func:`hindsight`).

A reference that breaches the cut-off scores 0 priority. :func:`fly_references` flies both; ``fly_mission``
calls it, or a caller that showed the flight first (the Fly tab) calls it afterwards through
:func:`~uam_studio.planning.operations.fly.with_references`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import cast

import numpy as np

from uam_studio.planning.missions.mission import VERTIPORT, Destination, Mission
from uam_studio.planning.operations.world import World, actual_winds_mission
from uam_studio.planning.solvers.oracle import oracle_plan


@dataclass
class ReferenceFlight:
    """A reference flown in the same world as the operator (a flight record's ``static`` and ``hindsight``):
    ``route`` (nodes in order; ``"vertiport"`` is a recharge), ``altitudes_m`` (m) of each
    leg, ``priority`` (the priority it served; 0 when it breached), ``breached`` (the cell fell below the
    cut-off), ``exact`` (the exact oracle's plan of the true cell and the actual winds; False for the
    pre-flight plan, and for hindsight when scripted events make it the best of several candidate plans)."""

    route: list[str] = field(default_factory=list)
    altitudes_m: list[float] = field(default_factory=list)
    priority: int = 0
    breached: bool = False
    exact: bool = False


def fly_fixed(world: World, route: Sequence[str], alts: Sequence[float],
               takeoff: np.ndarray) -> tuple[bool, list[str]]:
    """Fly ``route`` blind in ``world``; returns (breached, destinations reached)."""
    reached: list[str] = []
    if not route:
        return False, reached
    world.takeoff_check(takeoff)
    if world.breached:
        return True, reached
    for to, alt in zip(route, alts):
        r = world.fly_leg(to, alt)
        if not r.landed:
            return True, reached
        if to != VERTIPORT:
            reached.append(to)
    return False, reached


def hindsight(mission: Mission, scenario: str, new_world: Callable[[], World], takeoff: np.ndarray,
               flown: tuple[Sequence[str], Sequence[float]]) -> tuple[list[str], list[float], int]:
    """The hindsight reference: (route, altitudes (m), priority) of the best plan knowing the true
    cell and the actual winds as they were when each leg was flown.

    With no scripted event the winds never change, and it is the exact oracle's plan for the true
    cell and the actual winds. With events, a leg's wind depends on when it is flown, which the
    oracle's search does not model. The candidates are then the exact plan for each period of
    constant winds (before the first event, after each event) and the route flown; each is flown
    blind in a fresh world with the same seed (the winds change at the events' times), and the best
    priority wins (a breach scores 0). It is the best of those plans, not a proven optimum.
    """
    world = new_world()
    times = sorted({0.0, *(e.start_s for e in world.events)})
    plans = []
    for t in times:
        plan = oracle_plan(actual_winds_mission(mission, {n: world.wind(n, t) for n in mission.node_names}), scenario,
                           params=world.cell.params)
        plans.append((list(plan.route), list(plan.altitudes_m)))
    if not world.events:
        route, alts = plans[0]
        return route, alts, priority_of(mission, route)
    best: tuple[list[str], list[float], int] | None = None
    for route, alts in [*plans, (list(flown[0]), list(flown[1]))]:
        breached, reached = fly_fixed(new_world(), route, alts, takeoff)
        priority = 0 if breached else priority_of(mission, reached)
        if best is None or priority > best[2]:
            best = (route, alts, priority)
    assert best is not None
    return best


def priority_of(mission: Mission, reached: Sequence[str]) -> int:
    """The stars of the destinations in ``reached`` (the vertiport counts none)."""
    return int(sum(cast(Destination, mission.node(n)).priority for n in reached if n != VERTIPORT))


def fly_references(mission: Mission, scenario: str, new_world: Callable[[], World], takeoff: np.ndarray,
                   planned: tuple[Sequence[str], Sequence[float]],
                   flown: tuple[Sequence[str], Sequence[float]]) -> tuple[ReferenceFlight, ReferenceFlight, float]:
    """``(blind, hindsight, the blind flight's end (s))``: the pre-flight plan ``planned`` (route, altitudes in m)
    flown blind in ``new_world()``, and the hindsight reference (:func:`hindsight`; ``flown`` is the operator's
    route and altitudes, one of its candidates when the weather changes)."""
    route, alts = list(planned[0]), list(planned[1])
    blind = new_world()
    breached, reached = fly_fixed(blind, route, alts, takeoff)
    static = ReferenceFlight(route, alts, 0 if breached else priority_of(mission, reached), breached)
    h_route, h_alts, h_priority = hindsight(mission, scenario, new_world, takeoff, flown)
    exact = not blind.events
    return static, ReferenceFlight(h_route, h_alts, h_priority, exact=exact), blind.time_s


__all__ = ["ReferenceFlight", "fly_fixed", "fly_references", "hindsight", "priority_of"]
