"""Greedy baseline planner (physics battery, the same actions and :class:`Plan` as the oracle).

From where the aircraft is, try the unvisited destinations in order of priority / distance
(best first). Fly each leg at its lowest-charge level (of the four ``ALTITUDES_M``). Take the
first destination that the cell can reach *and* leave again for the vertiport (both legs
simulated with the physics model from the present state). When none fits: single_charge flies
home and stops; multi_charge flies home, recharges and starts a new sortie, until a fresh cell
cannot fit any remaining destination. single_flight flies to ``destinations[0]`` at its
lowest-charge level. Every move is checked before it is made, so greedy plans are always safe.
It plans 1 to ``MAX_DESTINATIONS`` (20) destinations (:func:`~.setup.prepare_mission`).
"""

from __future__ import annotations

import time

import numpy as np

from uam_studio.planning.legs import ALTITUDES_M
from uam_studio.planning.missions.check import Plan, make_plan
from uam_studio.planning.missions.mission import VERTIPORT, Mission
from uam_studio.planning.solvers.setup import prepare_mission, single_flight_note, too_close


def greedy_plan(mission: Mission, scenario: str | None = None) -> Plan:
    """Greedy plan of ``mission`` (see the module docstring). Never raises for hard missions."""
    t0 = time.perf_counter()
    setup = prepare_mission(mission, scenario, "greedy")
    if setup.early is not None:
        return setup.early
    assert setup.mission is not None and setup.full_mission is not None and setup.episode is not None
    mission, full_mission, msgs, stats, ep = (setup.mission, setup.full_mission, setup.messages, setup.stats,
                                              setup.episode)
    legs, dests = ep.legs, mission.destinations

    def fly(i: int, j: int, a: int, x: np.ndarray) -> tuple[bool, np.ndarray]:
        ok, x_end, _ = ep.fly([(i, j, a)], x)
        return bool(ok[0]), x_end[0]

    route: list[str] = []
    alts: list[float] = []
    n = len(dests)
    home = ep.home
    for k in range(n):
        reason = too_close(legs, k)
        if reason is not None:
            msgs.append(reason)
    if ep.rules.one_leg:
        msgs.extend(filter(None, [single_flight_note(mission)]))
        a = legs.cheapest_level(home, 0)
        if a is not None and fly(home, 0, a, ep.fresh())[0]:
            route, alts = [dests[0].name], [ALTITUDES_M[a]]
        elif a is not None:
            msgs.append(f"cannot reach {dests[0].name} at its lowest-charge level ({ALTITUDES_M[a]:g} m)")
        stats["time_s"] = round(time.perf_counter() - t0, 4)
        return make_plan(full_mission, "greedy", route, alts, msgs, stats)

    servable = ep.servable
    visited = np.zeros(ep.slots, dtype=bool)
    at, x = home, ep.fresh()
    while True:
        cands = legs.greedy_order(at, [int(k) for k in np.flatnonzero(ep.targets(at, visited)[0, :ep.slots])])
        moved = False
        for k in cands:
            a = legs.cheapest_level(at, k)
            b = legs.cheapest_level(k, home)
            if a is None or b is None:
                continue
            ok, x1 = fly(at, k, a, x)
            if not ok or not fly(k, home, b, x1)[0]:
                continue
            route.append(dests[k].name)
            alts.append(ALTITUDES_M[a])
            visited[k] = True
            at, x, moved = k, ep.arrive(k, x1), True
            break
        if moved:
            continue
        if at == home:  # a fresh cell fits nothing more
            break
        route.append(VERTIPORT)
        back = legs.cheapest_level(at, home)
        assert back is not None  # ``at`` was flown to only with a level home (b above)
        alts.append(ALTITUDES_M[back])
        at, x = home, ep.arrive(home, x)
        if ep.ends_after(home, visited):
            break
    left = [dests[k].name for k in range(n) if servable[k] and not visited[k]]
    if left:
        msgs.append(f"greedy found no safe place for: {', '.join(left)}")
    stats["time_s"] = round(time.perf_counter() - t0, 4)
    return make_plan(full_mission, "greedy", route, alts, msgs, stats)


__all__ = ["greedy_plan"]
