"""The exact oracle: against brute-force enumeration, against greedy, and on hard missions."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from uam_studio.battery import simulate
from uam_studio.errors import InputError
from uam_studio.planning.episode import Episode, fly_batch
from uam_studio.planning.legs import N_MAX, VERTIPORT_SLOT, LegTable
from uam_studio.planning.missions.check import check_plan
from uam_studio.planning.missions.generate import held_out_missions, random_mission
from uam_studio.planning.missions.mission import (
    MAX_DESTINATIONS,
    Battery,
    Destination,
    Mission,
    Vertiport,
    mission_to_dict,
)
from uam_studio.planning.solvers.greedy import greedy_plan
from uam_studio.planning.solvers.oracle import feasible_sorties, min_sortie_cover, oracle_plan
from uam_studio.planning.solvers.setup import prepare_mission

V = VERTIPORT_SLOT


def brute_force_sets(legs: LegTable, levels: tuple[int, ...]) -> set[int]:
    """Every (order, levels) sortie flown as ONE simulate call on its concatenated current."""
    m = legs.mission
    sorties, currents = [], []
    n = legs.n
    for k in range(1, n + 1):
        for order in itertools.permutations(range(n), k):
            path = (V, *order, V)
            for alts in itertools.product(levels, repeat=k + 1):
                if all(legs.feasible[i, j, a] for i, j, a in zip(path, path[1:], alts)):
                    sorties.append(sum(1 << d for d in order))
                    currents.append(np.concatenate([legs.current(i, j, a) for i, j, a in zip(path, path[1:], alts)]))
    lengths = np.array([c.size for c in currents])
    feasible = set()
    for s in range(0, len(currents), 400):  # zero-padded batches; feasible = valid at the last real sample
        block = currents[s:s + 400]
        cur = np.zeros((len(block), max(c.size for c in block)))
        for r, c in enumerate(block):
            cur[r, :c.size] = c
        res = simulate(cur, 1.0, m.battery.q_max, m.battery.r0, m.eod_v)
        ok = res.valid[np.arange(len(block)), lengths[s:s + 400] - 1]
        feasible.update(sorties[s + r] for r in np.flatnonzero(ok))
    return feasible


def small_mission(seed: int, n: int) -> Mission:
    rng = np.random.default_rng(seed)
    return random_mission(rng, n, "single_charge", r0_range=(0.1, 0.3), q_range=(5000.0, 6000.0),
                          radius_km=(12.0, 35.0))


# seeds chosen so that some, but not all, visit sets are feasible
@pytest.mark.parametrize("seed, n, levels", [(1, 3, (0, 1, 2, 3)), (2, 3, (0, 1, 2, 3)), (4, 3, (0, 1, 2, 3)),
                                              (5, 4, (0, 1)), (6, 4, (0, 2))])
def test_oracle_equals_brute_force(seed, n, levels):
    m = small_mission(seed, n)
    legs = LegTable(m)
    brute = brute_force_sets(legs, levels)
    stats = {}
    found = feasible_sorties(Episode.of(legs), levels, dominance=True, stats=stats)
    assert set(found) == brute  # same feasible visit sets: the dominance assumption held
    assert 0 < len(brute) < 2 ** n - 1, "instance should be neither trivial nor hopeless"
    assert set(feasible_sorties(Episode.of(legs), levels, dominance=False)) == brute
    prio = [d.priority for d in m.destinations]
    best_brute = max(sum(p for k, p in enumerate(prio) if s >> k & 1) for s in brute)
    plan = oracle_plan(m, "single_charge", alt_indices=levels)
    assert plan.reached_priority == best_brute and plan.stats["safe"]
    universe = 0
    for s in brute:
        universe |= s
    cover = min_sortie_cover(found, universe)
    assert sum(s.mask for s in cover) == universe  # disjoint sets covering every reachable destination
    # the fewest sorties over the brute-force family, by plain enumeration of partitions
    fewest = min(len(c) for c in _partitions(universe, brute))
    assert oracle_plan(m, "multi_charge", alt_indices=levels).charging_cycles == fewest == len(cover)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dominance_pruning_changes_nothing_on_five_destinations(seed):
    rng = np.random.default_rng(100 + seed)
    m = random_mission(rng, 5, "single_charge", r0_range=(0.05, 0.2), q_range=(5500.0, 7000.0),
                       radius_km=(12.0, 35.0))
    legs = LegTable(m)
    stats = {}
    pruned = feasible_sorties(Episode.of(legs), dominance=True, stats=stats)
    full = feasible_sorties(Episode.of(legs), dominance=False)
    assert set(pruned) == set(full) and stats["pruned_dominated"] > 0
    assert 0 < len(full) < 2 ** 5 - 1


def _partitions(universe: int, family: set[int]):
    if universe == 0:
        yield []
        return
    low = universe & -universe
    for s in family:
        if s & low and s & universe == s:
            for rest in _partitions(universe ^ s, family):
                yield [s, *rest]


def test_fly_batch_matches_simulate_leg_by_leg():
    m = small_mission(0, 3)
    legs = LegTable(m)
    q, r0 = m.battery.q_max, m.battery.r0
    mid = simulate(legs.current(V, 0, 0), 1.0, q, r0).final_state
    currents = [legs.current(0, 1, 0), legs.current(0, V, 1), legs.current(0, 2, 0)]
    ok, x_end, vmin = fly_batch(currents, np.repeat(mid.as_array(), 3, axis=0), m.cell)
    for k, c in enumerate(currents):
        ref = simulate(c, 1.0, q, r0, m.eod_v, initial_state=mid)
        assert ok[k] == (not ref.eod_reached)
        assert vmin[k] == pytest.approx(ref.min_voltage_v, abs=1e-9)
        if ok[k]:
            np.testing.assert_allclose(x_end[k], ref.final_state.as_array()[0], rtol=1e-10, atol=1e-9)


@pytest.mark.parametrize("scenario", ["single_flight", "single_charge", "multi_charge"])
def test_oracle_at_least_greedy_and_plans_are_safe(scenario):
    for m in held_out_missions(3, 2024, n_dest=(4, 6), scenario=scenario):
        o, g = oracle_plan(m), greedy_plan(m)
        for p in (o, g):
            c = check_plan(m, p.route, p.altitudes_m)
            assert c.safe and p.stats["safe"], (p.policy, c.message)
        assert o.reached_priority >= g.reached_priority
        if scenario == "multi_charge":
            assert set(o.reached) >= set(g.reached)
            if set(o.reached) == set(g.reached):
                assert o.charging_cycles <= g.charging_cycles
        if scenario == "single_flight":
            assert o.stats["min_voltage_v"] >= g.stats["min_voltage_v"] - 1e-12


def test_multi_charge_route_shape():
    m = held_out_missions(1, 99, n_dest=(5, 5), scenario="multi_charge")[0]
    p = oracle_plan(m)
    assert p.route[-1] == "vertiport" and p.charging_cycles == p.route.count("vertiport")
    assert len(p.route) == len(p.altitudes_m) and sorted(p.reached) == sorted(set(p.reached))


def _mission(dests, battery=None, scenario="single_charge") -> Mission:
    return Mission("hard", Vertiport(0.0, 0.0, 0.0), tuple(dests), scenario, battery or Battery(7600.0, 0.05))


@pytest.mark.parametrize("planner", [oracle_plan, greedy_plan])
def test_hard_missions_give_messages_not_errors(planner):
    p = planner(_mission([]))
    assert p.route == () and "no destinations" in p.messages[0]

    near = Destination("Near", 3.0, 0.0, 2)
    far = Destination("Far", 160.0, 0.0, 3, 39.0)
    ok = Destination("Ok", 15.0, 0.0, 1)
    p = planner(_mission([near, far, ok]))
    assert p.route == ("Ok", "vertiport") and p.reached == ("Ok",)
    text = " | ".join(p.messages)
    assert "cannot reach Near at any altitude" in text and "3.0 km" in text
    assert "Far" in text

    p = planner(_mission([ok], Battery(6000.0, 0.45)))
    assert p.route == () and "the battery cannot finish takeoff" in p.messages[0]

    many = [Destination(f"P{k}", 10.0 + 8 * k, 0.0, 1) for k in range(MAX_DESTINATIONS + 2)]
    with pytest.raises(InputError, match=r"^destinations: 22 destinations; allowed 1 to 20$"):
        _mission(many, Battery(5500.0, 0.25), "multi_charge")  # a Mission holds at most 20
    twenty = _mission(many[:MAX_DESTINATIONS], Battery(5500.0, 0.25), "multi_charge")
    p = planner(twenty)
    assert p.stats["safe"] and p.reached and set(p.reached) <= {f"P{k}" for k in range(MAX_DESTINATIONS)}
    assert any("P19" in m for m in p.messages)  # planned (out of reach)
    d = mission_to_dict(twenty)
    d["destinations"] += [dict(d["destinations"][0], name=f"P{k}") for k in (20, 21)]
    p = planner(d)  # more than a mission holds, as a dict: a message naming the limit, not an error
    assert p.route == () and p.messages[0] == "invalid mission: destinations: 22 destinations; allowed 1 to 20"
    dqn = prepare_mission(_mission(many[:N_MAX + 2]), None, "dqn")  # a planner's own, smaller cap
    assert "the planner handles at most 8 destinations; not planned: P8, P9" in dqn.messages[0]
    assert len(dqn.mission.destinations) == N_MAX and len(dqn.full_mission.destinations) == N_MAX + 2

    bad = mission_to_dict(_mission([ok]))
    bad["destinations"].append(dict(bad["destinations"][0]))  # duplicate name
    p = planner(bad)
    assert p.route == () and p.messages[0].startswith("invalid mission: destinations[1].name")


def test_oracle_names_unreachable_destination_and_single_flight_failure():
    far = Destination("Far", 160.0, 0.0, 3, 39.0)
    p = oracle_plan(_mission([far, Destination("Ok", 15.0, 0.0, 1)]))
    assert any(msg.startswith("cannot reach Far at any altitude") for msg in p.messages)
    p = oracle_plan(_mission([far], scenario="single_flight"))
    assert p.route == () and p.messages[0].startswith("cannot reach Far at any altitude")


def test_leg_table_charges_match_the_flight_model_exactly():
    """The vectorised per-mission charge table equals leg_charge_c on every feasible leg; the
    cheapest level and charge follow from it; infeasible legs are inf / None."""
    from uam_studio.flight import leg_charge_c
    from uam_studio.planning.legs import ALTITUDES_M, N_ALTITUDES, N_TARGETS

    n = 0
    for m in held_out_missions(6, 77, n_dest=(1, N_MAX), scenario="single_charge"):
        legs = LegTable(m)
        for i in range(N_TARGETS):
            for j in range(N_TARGETS):
                ok = [a for a in range(N_ALTITUDES) if legs.feasible[i, j, a]]
                for a in range(N_ALTITUDES):
                    if a in ok:
                        want = leg_charge_c(legs.dist[i, j], ALTITUDES_M[a], legs.wind[j], legs.dwell[j])
                        assert legs.charge(i, j, a) == want
                        n += 1
                    else:
                        assert legs.charge(i, j, a) == float("inf")
                if ok:
                    assert legs.cheapest_level(i, j) == min(ok, key=lambda a: legs.charge(i, j, a))
                    assert legs.cheapest_charge(i, j) == legs.charge(i, j, ok[0])
                else:
                    assert legs.cheapest_level(i, j) is None and legs.cheapest_charge(i, j) == float("inf")
    assert n > 100


def test_multi_charge_cover_when_not_every_reachable_destination_fits_one_partition():
    """Regression (hypothesis, tests/test_properties.py): D1 and D2 sit on the vertiport, each reachable
    only in a sortie D3 -> Dk -> D4. No set of disjoint sorties covers all four, and the exact oracle
    returned an empty plan while the other policies flew two destinations. It now keeps the partition
    with the most priority and names the destination it leaves."""
    from uam_studio.planning import plan_mission
    from uam_studio.planning.missions.mission import Battery, Destination, Mission, Vertiport

    dests = tuple(Destination(n, x, y, 1, 0.0) for n, x, y in (("D1", 0, 0), ("D2", 0, 0), ("D3", 0, 7),
                                                               ("D4", 7, 0)))
    mission = Mission("on the vertiport", Vertiport(0.0, 0.0, 0.0), dests, "multi_charge", Battery(5000.0, 0.25), 3.0)
    res = plan_mission(mission, policy="oracle")
    assert res.exact and res.safe and res.reached_priority == 3
    assert any(m.startswith("not visited: D") for m in res.messages)
    for policy in ("attention", "greedy"):
        assert plan_mission(mission, policy=policy).reached_priority <= res.reached_priority
