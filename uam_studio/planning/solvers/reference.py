"""Reference planner for large missions (9-20 destinations) from an established routing solver.

The exact oracle (:mod:`.oracle`) enumerates sorties and partitions them; past ``N_MAX = 8``
destinations that grows out of reach (9 destinations already take about 10 s on 2 cores for a
fresh cell). This module gives a *reference* instead: a good plan from Google OR-Tools' vehicle
routing solver (``ortools.constraint_solver``), re-checked on the physics battery, **not proven
optimal** (``stats["exact"] = False``).

Model
-----
* Nodes: the vertiport (the depot) and every destination that a fresh cell can reach and leave
  again for the vertiport on its own (vertiport -> k -> vertiport flown on the physics model).
* Legs: every leg i -> j is flown at its lowest-charge level (:meth:`LegTable.cheapest_level`,
  among ``alt_indices``); its charge (C, :meth:`LegTable.cheapest_charge`, the dwell at j
  included) is the arc cost and the resource: a dimension "charge" with a capacity per sortie
  (``budget``) and a cap on the charge given before each take-off from a destination
  (``takeoff``: a take-off and climb draw about 2.9 A, so with a large r0 it is the next take-off
  that meets the cut-off, not the end of the charge). Legs that no allowed level can fly are closed.
* single_charge: one vehicle (one sortie); each destination may be dropped at a penalty of its
  priority (a prize-collecting route): the solver maximises the priority, then saves charge.
* multi_charge: one vehicle per sortie, each with a large fixed cost (the solver minimises the
  number of sorties, then the charge); every reachable destination is required (dropping one costs
  more than any number of sorties; one the solver drops anyway flies alone, a sortie that is safe).

The battery is a nonlinear model, so no charge budget is exact (the cut-off depends on the order of
the currents and on r0). :func:`reference_plan` therefore *finds* the budgets: the first estimates
come from the physics model at the mission's cruise current (the charge to the cut-off, and the most
charge after which a take-off stays above it); then a bisection on a factor of both: each solver
answer is flown sortie by sortie on the physics model
(:func:`~uam_studio.planning.episode.fly_batch`, the numbers of
:func:`~uam_studio.planning.missions.check.check_plan`); if every sortie stays above the cut-off
the budgets grow, else they shrink (and the unsafe answer is repaired: a destination dropped, or a
sortie split, wherever the physics says it becomes safe). Every other solve starts from the best
safe plan so far, the first one being the greedy baseline's plan (:func:`.greedy.greedy_plan`
flies the same legs; so the reference never plans worse than greedy). The best safe plan over all
budgets is kept (most priority, or fewest sorties, then least flight time), then polished on the physics model
(single_charge: add a destination or swap one in for a lower priority; multi_charge: empty a sortie into the others)
while the route stays safe. Every solve has a time limit (``REFERENCE_TIME_S`` over ``BISECTION_STEPS`` solves for 20
destinations, proportionally less for fewer), so that a 20-destination mission plans in a few seconds.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence

import numpy as np

from uam_studio.battery.simulate import simulate_cell
from uam_studio.planning.episode import Episode
from uam_studio.planning.legs import ALTITUDES_M, DT_S, N_ALTITUDES, LegTable, takeoff_current
from uam_studio.planning.missions.check import Plan, make_plan
from uam_studio.planning.missions.mission import MAX_DESTINATIONS, VERTIPORT, Mission
from uam_studio.planning.solvers.greedy import greedy_plan
from uam_studio.planning.solvers.setup import (
    PlanSetup,
    prepare_mission,
    single_flight_plan,
    too_close,
)

REFERENCE_TIME_S = 3.0  # solver time (s) of one 20-destination plan, over all budgets tried
BISECTION_STEPS = 7  # solves per plan (budgets tried)
MIN_SOLVE_S = 0.05  # shortest time limit of one solve
_SCALE = 10.0  # solver units per coulomb (integer arc costs: 0.1 C)
_INFEASIBLE = 10**9  # transit of a leg no allowed level can fly (> any budget)
_SORTIE_COST = 10**9  # fixed cost of one sortie (multi_charge), > any total charge cost
_PRIORITY_PRIZE = 10**8  # drop penalty per priority point (single_charge), > any route's charge cost
_REQUIRED = 10**12  # drop penalty of a multi_charge destination, > any number of sorties
# local-search moves off by default that swap visited and dropped destinations (prize collecting: without
# them guided local search often stays on a route one priority point short of the exact optimum)
_EXTRA_OPERATORS = ("use_extended_swap_active", "use_inactive_lns", "use_path_lns", "use_relocate_and_make_active",
                    "use_exchange_and_make_active", "use_node_pair_swap_active")


def _levels(legs: LegTable, alts: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Per leg i -> j: the charge (C) at its lowest-charge allowed level and that level (-1: none)."""
    n = legs.slots + 1
    charge = np.full((n, n), np.inf)
    level = np.full((n, n), -1, dtype=int)
    every = alts == tuple(range(N_ALTITUDES))
    for i in range(n):
        for j in range(n):
            if every:
                a = legs.cheapest_level(i, j)
                if a is not None:
                    charge[i, j], level[i, j] = legs.cheapest_charge(i, j), a
                continue
            for a in alts:
                c = legs.charge(i, j, a)
                if c < charge[i, j]:
                    charge[i, j], level[i, j] = c, a
    return charge, level


def _sortie_current(legs: LegTable, level: np.ndarray, nodes: list[int]) -> np.ndarray:
    path = [legs.home, *nodes, legs.home]
    return np.concatenate([legs.current(i, j, int(level[i, j])) for i, j in zip(path[:-1], path[1:])])


def _fly_sorties(ep: Episode, level: np.ndarray, sorties: list[list[int]]) -> tuple[np.ndarray, np.ndarray]:
    """``(ok, time_s)`` of each sortie flown from a fresh cell on the physics model. A sortie with a leg
    that no allowed level can fly (two destinations closer than any climb and descent) is not flown:
    not ok, time inf."""
    legs = ep.legs
    paths = [[legs.home, *s, legs.home] for s in sorties]
    flyable = np.array([all(level[i, j] >= 0 for i, j in zip(p[:-1], p[1:])) for p in paths], dtype=bool)
    ok = np.zeros(len(sorties), dtype=bool)
    times = np.full(len(sorties), np.inf)
    currents = [_sortie_current(legs, level, s) for s, f in zip(sorties, flyable) if f]
    if currents:
        ok[flyable], _, _ = ep.fly_currents(currents, ep.fresh())
        times[flyable] = [c.size * DT_S for c in currents]
    return ok, times


def _first_budgets(ep: Episode, level: np.ndarray, nodes: list[int]) -> tuple[float, float]:
    """First estimates (C) of the two budgets: the charge a fresh cell gives before its cut-off at the
    mission's cruise current, and the most charge it may have given before it takes off again (the
    take-off and climb draw about 2.9 A: with a large r0 they reach the cut-off first)."""
    legs = ep.legs
    cell = ep.cell
    one = np.concatenate([_sortie_current(legs, level, [k]) for k in nodes])
    mid = one[(one > 0.5) & (one < 2.5)]  # the cruise samples dominate (take-off and climb: ~2.9 A)
    cruise = float(np.median(mid)) if mid.size else float(one[one > 0].mean())
    steps = int(2.0 * cell.q_max / cruise / DT_S)
    res = simulate_cell(np.full(steps, cruise), cell, DT_S)
    total = cruise * (float(res.eod_s) if res.eod_reached else steps * DT_S)
    climb = takeoff_current()
    before = np.linspace(0.0, total, 41)[1:]  # charge given before the take-off (C)
    pre = np.ceil(before / cruise / DT_S).astype(int)
    rows = np.zeros((pre.size, int(pre.max()) + climb.size))
    for b, k in enumerate(pre):
        rows[b, :k] = cruise
        rows[b, k:k + climb.size] = climb
    ok = ~np.asarray(simulate_cell(rows, cell, DT_S).eod_reached)
    takeoff = float(before[ok].max()) if ok.any() else 0.0
    return total, takeoff


def _repair(ep: Episode, level: np.ndarray, sorties: list[list[int]], flown: np.ndarray,
            multi: bool) -> tuple[list[list[int]], np.ndarray]:
    """A safe plan near an unsafe solver answer, and its sortie times (s), or ``([], [])``.

    single_charge: the sortie without the one destination whose removal leaves the most priority
    (then the least time) and is safe. multi_charge: each unsafe sortie split in two where both parts
    are safe (least time), else into its single destinations (each safe on its own)."""
    legs = ep.legs
    prio = legs.priority
    if not multi:
        s = sorties[0]
        cands = [s[:i] + s[i + 1:] for i in range(len(s))]
        cands = [c for c in cands if c]
        ok, times = _fly_sorties(ep, level, cands)
        good = [k for k in range(len(cands)) if ok[k]]
        if not good:
            return [], np.zeros(0)
        k = max(good, key=lambda k: (int(prio[cands[k]].sum()), -times[k]))
        return [cands[k]], times[k:k + 1]
    out: list[list[int]] = []
    for s, ok_s in zip(sorties, flown):
        if ok_s:
            out.append(s)
            continue
        halves = [p for i in range(1, len(s)) for p in (s[:i], s[i:])]
        ok, times = _fly_sorties(ep, level, halves)
        both = [i for i in range(0, len(halves), 2) if ok[i] and ok[i + 1]]
        if both:
            i = min(both, key=lambda i: times[i] + times[i + 1])
            out += [halves[i], halves[i + 1]]
        else:
            out += [[k] for k in s]
    return out, _fly_sorties(ep, level, out)[1]


def _polish(ep: Episode, level: np.ndarray, sorties: list[list[int]], reachable: list[int],
            multi: bool) -> list[list[int]]:
    """Local search on the physics model around the solver's best safe plan (the charge budget is only
    a proxy of the cut-off). single_charge: add an unvisited destination, or swap one in for a
    visited one of lower priority, wherever the route stays safe (most priority gained, then least
    time), until nothing improves. multi_charge: empty the smallest sorties into the others where every
    changed sortie stays safe (one sortie fewer each time), until none can be."""
    legs = ep.legs
    prio = legs.priority
    if not multi:
        route = list(sorties[0])
        while True:
            out = [k for k in reachable if k not in route]
            cands = [route[:p] + [k] + route[p:] for k in out for p in range(len(route) + 1)]
            cands += [r[:p] + [k] + r[p:] for j in range(len(route)) for r in [route[:j] + route[j + 1:]]
                      for k in out if prio[k] > prio[route[j]] for p in range(len(r) + 1)]
            if not cands:
                return [route]
            ok, times = _fly_sorties(ep, level, cands)
            good = [i for i in range(len(cands)) if ok[i]]
            if not good:
                return [route]
            i = max(good, key=lambda i: (int(prio[cands[i]].sum()), -times[i]))
            route = cands[i]
    plan = [list(s) for s in sorties]
    for s in sorted(plan, key=len):
        if len(plan) < 2 or s not in plan:
            continue
        rest = [r for r in plan if r is not s]
        placed = True
        for k in s:
            spots = [(r, p) for r in range(len(rest)) for p in range(len(rest[r]) + 1)]
            trial = [rest[r][:p] + [k] + rest[r][p:] for r, p in spots]
            ok, times = _fly_sorties(ep, level, trial)
            good = [i for i in range(len(trial)) if ok[i]]
            if not good:
                placed = False
                break
            i = min(good, key=lambda i: times[i])
            rest[spots[i][0]] = trial[i]
        if placed:
            plan = rest
    return plan


def _solve(charge: np.ndarray, nodes: list[int], home: int, prio: np.ndarray, multi: bool,
           budget_c: float, takeoff_c: float, time_s: float,
           starts: Sequence[list[list[int]]] = ()) -> list[list[int]] | None:
    """One OR-Tools solve: the sorties (table node lists, visiting order), or None if it found nothing.
    ``starts``: plans (lists of sorties) to start the search from, the first that fits the budgets
    (else the solver's own first solution)."""
    from ortools.constraint_solver import pywrapcp, routing_enums_pb2
    from ortools.util import optional_boolean_pb2

    idx = [home, *nodes]  # solver node k is table node idx[k]; 0 is the depot
    cost = np.where(np.isfinite(charge[np.ix_(idx, idx)]), np.ceil(charge[np.ix_(idx, idx)] * _SCALE),
                    _INFEASIBLE).astype(np.int64)
    np.fill_diagonal(cost, 0)
    n_vehicles = len(nodes) if multi else 1
    manager = pywrapcp.RoutingIndexManager(len(idx), n_vehicles, 0)
    routing = pywrapcp.RoutingModel(manager)
    table = cost.tolist()

    def transit(a: int, b: int) -> int:
        return table[manager.IndexToNode(a)][manager.IndexToNode(b)]

    cb = routing.RegisterTransitCallback(transit)
    routing.SetArcCostEvaluatorOfAllVehicles(cb)
    routing.AddDimension(cb, 0, int(budget_c * _SCALE), True, "charge")
    dim = routing.GetDimensionOrDie("charge")
    for k in range(1, len(idx)):  # the charge given before each take-off from a destination
        dim.CumulVar(manager.NodeToIndex(k)).SetMax(int(takeoff_c * _SCALE))
    if multi:
        routing.SetFixedCostOfAllVehicles(_SORTIE_COST)
    for k in range(1, len(idx)):
        penalty = _REQUIRED if multi else int(prio[idx[k]]) * _PRIORITY_PRIZE
        routing.AddDisjunction([manager.NodeToIndex(k)], penalty)
    params = pywrapcp.DefaultRoutingSearchParameters()
    params.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.PATH_CHEAPEST_ARC
    params.local_search_metaheuristic = routing_enums_pb2.LocalSearchMetaheuristic.GUIDED_LOCAL_SEARCH
    ops = params.local_search_operators
    for name in _EXTRA_OPERATORS:
        if name in ops.DESCRIPTOR.fields_by_name:  # not every OR-Tools release has every operator
            setattr(ops, name, optional_boolean_pb2.BOOL_TRUE)
    params.time_limit.FromMilliseconds(max(1, int(time_s * 1000)))
    initial = None
    if starts:
        routing.CloseModelWithParameters(params)
        pos = {node: k for k, node in enumerate(idx)}
    for start in starts:
        routes = [[manager.NodeToIndex(pos[node]) for node in s] for s in start]
        initial = routing.ReadAssignmentFromRoutes(routes + [[]] * (n_vehicles - len(routes)), True)
        if initial is not None:
            break
    if initial is not None:
        sol = routing.SolveFromAssignmentWithParameters(initial, params)
    else:
        sol = routing.SolveWithParameters(params)
    if sol is None:
        return None
    out = []
    for v in range(n_vehicles):
        i = sol.Value(routing.NextVar(routing.Start(v)))
        s = []
        while not routing.IsEnd(i):
            s.append(idx[manager.IndexToNode(i)])
            i = sol.Value(routing.NextVar(i))
        if s:
            out.append(s)
    return out


def reference_from_setup(setup: PlanSetup, policy: str, alt_indices: Iterable[int], t0: float,
                         time_limit_s: float = REFERENCE_TIME_S) -> Plan:
    """The reference plan of a prepared mission (``setup.early`` is None; not single_flight), labelled
    ``policy``; ``t0`` (:func:`time.perf_counter`) is when planning began (``stats["time_s"]``)."""
    mission, full_mission, msgs, stats, ep = (setup.mission, setup.full_mission, setup.messages, setup.stats,
                                              setup.episode)
    assert mission is not None and full_mission is not None and ep is not None
    legs = ep.legs
    dests = mission.destinations
    n = len(dests)
    alts = tuple(sorted({int(a) for a in alt_indices}))
    charge, level = _levels(legs, alts)
    home = legs.home
    stats["exact"] = False
    stats["solver"] = "ortools"
    msgs.append(f"plan from the reference solver (OR-Tools routing, {n} destinations, each leg at its "
                "lowest-charge level): re-checked on the physics model, not proven optimal")

    def done(route: list[str], alt_m: list[float]) -> Plan:
        stats["time_s"] = round(time.perf_counter() - t0, 4)
        return make_plan(full_mission, policy, route, alt_m, msgs, stats)

    # the destinations a fresh cell can reach and leave again on its own
    cand = [k for k in range(n) if level[home, k] >= 0 and level[k, home] >= 0]
    ok, t_alone = _fly_sorties(ep, level, [[k] for k in cand])
    reachable = [k for k, good in zip(cand, ok) if good]
    for k in range(n):
        if k not in reachable:
            msgs.append(too_close(legs, k) or f"cannot reach {dests[k].name} at its lowest-charge level and "
                                              "return to the vertiport with this battery")
    if not reachable:
        return done([], [])
    multi = ep.rules.recharges
    prio = legs.priority

    def score(sorties: list[list[int]], times: np.ndarray) -> tuple:
        if multi:
            return (-len(sorties), -float(times.sum()))
        return (int(sum(prio[k] for s in sorties for k in s)), -float(times.sum()))

    # a first safe plan: every destination alone (multi_charge) / the best single destination
    alone = dict(zip(reachable, t_alone[[cand.index(k) for k in reachable]]))
    if multi:
        best = [[k] for k in reachable]
    else:
        best = [[max(reachable, key=lambda k: (prio[k], -alone[k]))]]
    best_score = score(best, np.array([alone[s[0]] for s in best]))
    best_budget = 0.0

    def consider(sorties: list[list[int]], times: np.ndarray, budget: float) -> None:
        nonlocal best, best_score, best_budget
        if sorties and score(sorties, times) > best_score:
            best, best_score, best_budget = sorties, score(sorties, times), budget

    if alts == tuple(range(N_ALTITUDES)):  # the greedy plan flies the same legs: a start never to fall below
        node = {legs.name(k): k for k in reachable}
        greedy: list[list[int]] = []  # the greedy plan's sorties
        cur: list[int] = []
        for name in greedy_plan(mission, ep.rules.name).route:
            if name == VERTIPORT:
                greedy, cur = greedy + [cur], []
            else:
                cur.append(node.get(name, -1))
        if greedy and not cur and all(k >= 0 for s in greedy for k in s):
            if multi:  # and the destinations greedy left out alone
                greedy += [[k] for k in reachable if all(k not in s for s in greedy)]
            flown, times = _fly_sorties(ep, level, greedy)
            if flown.all():
                consider(greedy, times, 0.0)

    total, takeoff = _first_budgets(ep, level, reachable)
    lo, hi = 0.0, 2.0  # scale of both budgets: safe at lo so far, unsafe at hi
    scale = 1.0
    steps = 0
    last_safe: list[list[int]] | None = None  # fits every budget tried after it
    per_solve = max(MIN_SOLVE_S, time_limit_s * min(1.0, len(reachable) / MAX_DESTINATIONS) / BISECTION_STEPS)
    while steps < BISECTION_STEPS:
        steps += 1
        # every other solve starts from the best safe plan (or the last raw safe answer, which fits every
        # budget tried after it); the others from the solver's own first solution (less often stuck)
        starts = [best] + ([last_safe] if last_safe is not None else []) if steps % 2 == 0 else []
        sorties = _solve(charge, reachable, home, prio, multi, scale * total, scale * takeoff, per_solve, starts)
        safe = True  # nothing found: the budget is not the problem; try more
        if sorties is not None:
            served = {k for s in sorties for k in s}
            if multi:  # destinations the solver dropped fly alone (safe on their own)
                sorties = sorties + [[k] for k in reachable if k not in served]
            flown, times = _fly_sorties(ep, level, sorties)
            safe = bool(flown.all())
            if safe:
                last_safe = sorties
                consider(sorties, times, scale * total)
            else:
                consider(*_repair(ep, level, sorties, flown, multi), scale * total)
        if safe:
            lo = scale
        else:
            hi = scale
        if hi - lo < 0.002:
            break
        scale = (lo + hi) / 2.0
    best = _polish(ep, level, best, reachable, multi)
    stats["budget_c"] = round(best_budget, 1)
    stats["solves"] = steps
    if multi:
        stats["sorties"] = len(best)
    else:
        left = [dests[k].name for k in reachable if k not in best[0]]
        if left:
            msgs.append(f"not visited on this charge: {', '.join(left)} (the reference found no safe "
                        "single-charge route that adds them)")
    route: list[str] = []
    alt_m: list[float] = []
    for s in best:
        path = [home, *s, home]
        route += [legs.name(j) for j in path[1:]]
        alt_m += [ALTITUDES_M[int(level[i, j])] for i, j in zip(path[:-1], path[1:])]
    return done(route, alt_m)


def reference_plan(mission: Mission, scenario: str | None = None,
                   alt_indices: Iterable[int] = range(N_ALTITUDES),
                   time_limit_s: float = REFERENCE_TIME_S, policy: str = "reference") -> Plan:
    """The OR-Tools reference plan of ``mission`` (1-20 destinations; see the module docstring).

    ``stats``: ``exact`` (False), ``solver`` (``"ortools"``), ``budget_c`` (the charge budget of the
    solve that gave the kept plan, C), ``solves``, ``sorties`` (multi_charge), ``time_s`` and the
    physics check's numbers. single_flight has one leg: the exact answer (the level with the highest
    minimum voltage, :func:`~uam_studio.planning.solvers.setup.single_flight_plan`), ``exact`` True.

    :param mission: the mission (a dict in the JSON format is validated first).
    :param scenario: overrides ``mission.scenario``.
    :param alt_indices: allowed levels (indices into ``ALTITUDES_M``); each leg flies the one of them
        that uses the least charge.
    :param time_limit_s: solver time (s) over all the budgets tried, for 20 reachable destinations
        (fewer get proportionally less, at least ``MIN_SOLVE_S`` a solve); physics checks come on top.
    :param policy: the plan's ``policy`` label.
    """
    t0 = time.perf_counter()
    setup = prepare_mission(mission, scenario, policy)
    if setup.early is not None:
        return setup.early
    assert setup.episode is not None  # a setup with no early plan has its episode
    if setup.episode.rules.one_leg:  # one leg: exact at any size
        return single_flight_plan(setup, policy, alt_indices, t0)
    return reference_from_setup(setup, policy, alt_indices, t0, time_limit_s)


__all__ = ["REFERENCE_TIME_S", "reference_from_setup", "reference_plan"]
