"""The episode model (planning/episode.py): its moves follow the scenario's rules, its transitions are
the physics route check's, and the planners fly the battery only through it."""

import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.battery import simulate
from uam_studio.battery.parameters import DEFAULT_CELL, Cell
from uam_studio.errors import InputError
from uam_studio.planning.episode import Episode, fly_batch
from uam_studio.planning.legs import ALTITUDES_M, N_MAX, LegTable
from uam_studio.planning.missions.generate import any_valid_mission
from uam_studio.planning.missions.mission import VERTIPORT
from uam_studio.planning.missions.route import simulate_route
from uam_studio.planning.missions.scenario import SCENARIOS
from uam_studio.planning.solvers.oracle import feasible_sorties

ROOT = Path(__file__).resolve().parents[1] / "uam_studio"


def _episode(seed: int, scenarios: tuple[str, ...] = SCENARIOS, max_dest: int = N_MAX) -> Episode:
    m = any_valid_mission(np.random.default_rng(seed), max_dest=max_dest, scenarios=scenarios)
    return Episode.of(LegTable(m))


@settings(max_examples=40, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), node=st.integers(0, N_MAX), visited=st.integers(0, 2**N_MAX - 1))
def test_open_moves_follow_the_scenarios_rules(seed, node, visited):
    ep = _episode(seed)
    legs = ep.legs
    done = np.array([bool(visited >> k & 1) for k in range(ep.slots)])
    moves = ep.moves(node, done)[0]
    assert moves.shape == (ep.slots + 1, len(ALTITUDES_M))
    assert not (moves & ~legs.feasible[node]).any()  # every open move is a leg that fits its level
    assert not moves[:ep.slots][done].any()  # never a destination already served
    assert not moves[:ep.slots][~ep.servable].any()  # never one the aircraft may not fly to
    assert not (ep.servable & ~legs.present[:ep.slots]).any()
    home_open = moves[ep.home].any()
    if node == ep.home or ep.rules.one_leg:
        assert not home_open  # no leg from the vertiport to itself; no way back in a single flight
    else:
        assert home_open == legs.feasible[node, ep.home].any()
    if ep.rules.one_leg:
        assert not ep.servable[1:].any()  # a single flight goes to destinations[0] only
    # servable: a leg from the vertiport fits some level (so the way back fits it too)
    assert (ep.servable[: legs.n] == legs.feasible[ep.home, : legs.n].any(axis=1)).all() or ep.rules.one_leg


def test_where_each_scenario_ends_and_recharges():
    for name in SCENARIOS:
        ep = _episode(11, (name,))
        x = ep.fresh() * 0.5  # any state that is not a full charge
        none = np.zeros(ep.slots, dtype=bool)
        every = ep.servable.copy()
        if name == "single_flight":
            assert ep.ends_after(0, none)  # its one leg ends it
        elif name == "single_charge":
            assert ep.ends_after(ep.home, none) and not ep.ends_after(0, every)
            assert (ep.arrive(ep.home, x) == x).all()  # back home, the charge is not renewed
        else:
            assert not ep.ends_after(ep.home, none) or not ep.servable.any()
            assert ep.ends_after(ep.home, every) and not ep.ends_after(0, every)
            assert (ep.arrive(ep.home, x) == ep.fresh()).all()  # a landing at the vertiport recharges
        assert (ep.arrive(0, x) == x).all()


@settings(max_examples=25, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1), picks=st.lists(st.integers(0, 10**6), min_size=1, max_size=12),
       scenario=st.sampled_from(("single_charge", "multi_charge")))
def test_a_walk_of_open_moves_is_what_the_physics_route_check_flies(seed, picks, scenario):
    """Any walk of open moves flown by the episode (its cell, its recharge rule) gives the same legs,
    the same safe/unsafe verdicts and the same lowest voltages as simulate_route (simulate, leg by leg)."""
    ep = _episode(seed, (scenario,))
    legs = ep.legs
    at, x = ep.home, ep.fresh()
    visited = np.zeros(ep.slots, dtype=bool)
    route, alts, oks, vmins = [], [], [], []
    for p in picks:
        open_moves = np.argwhere(ep.moves(at, visited)[0])
        if open_moves.size == 0:
            break
        to, level = (int(v) for v in open_moves[p % len(open_moves)])
        ok, x_end, vmin = ep.fly([(at, to, level)], x)
        route.append(legs.name(to))
        alts.append(ALTITUDES_M[level])
        oks.append(bool(ok[0]))
        vmins.append(float(vmin[0]))
        if not ok[0]:
            break
        if to != ep.home:
            visited[to] = True
        at, x = to, ep.arrive(to, x_end[0])
        if ep.ends_after(to, visited):
            break
    if not route:
        return
    sim = simulate_route(legs.mission, route, alts)
    assert [g.to for g in sim.legs] == route
    assert [g.reached for g in sim.legs] == oks
    # the lowest voltage of each leg, a failed one's up to its first sample below the cut-off
    assert np.allclose([g.min_voltage_v for g in sim.legs], vmins, rtol=0, atol=1e-9)
    assert sim.charging_cycles == sum(r == VERTIPORT for r, ok in zip(route, oks) if ok)


def test_the_episode_flies_its_own_cell_not_the_missions():
    """The operator's episode holds a believed cell: flights use it, not the mission's battery."""
    ep = _episode(3, ("single_charge",))
    m = ep.legs.mission
    weak = Episode.of(ep.legs, cell=type(m.cell)("weak", DEFAULT_CELL, 5000.0, 0.3, m.eod_v))
    to = int(np.flatnonzero(ep.servable)[0])
    level = int(np.flatnonzero(ep.legs.feasible[ep.home, to])[0])
    cur = ep.legs.current(ep.home, to, level)
    for e in (ep, weak):
        _, _, vmin = e.fly([(ep.home, to, level)], e.fresh())
        ref = simulate(cur, 1.0, e.cell.q_max, e.cell.r0, e.cell.eod_v)
        assert vmin[0] == pytest.approx(float(ref.voltage_v[: ref.time_s.size].min()), abs=1e-9) or ref.eod_reached
    assert m.cell.q_max == m.battery.q_max and m.cell.r0 == m.battery.r0 and m.cell.eod_v == m.eod_v


def test_the_sortie_search_needs_a_way_home():
    with pytest.raises(InputError, match="episode: single_flight has no way home"):
        feasible_sorties(_episode(5, ("single_flight",)))


def test_planners_fly_the_battery_only_through_the_episode():
    """One batched battery: no planning module but episode.py integrates the cell for a search."""
    pattern = re.compile(r"\b(fly_batch|integrate_current)\(")
    allowed = {"planning/episode.py",  # the batched battery itself
               "planning/env/backends.py"}  # the env's battery (physics or Dynaformer), leg by leg with its trace
    offenders = sorted({str(p.relative_to(ROOT)) for p in (ROOT / "planning").rglob("*.py")
                        if pattern.search(p.read_text())} - allowed)
    assert offenders == [], offenders


def test_fly_batch_rows_of_many_lengths_match_simulate_with_their_split_states():
    """Rows of different lengths, some failing: per row the same verdict, lowest voltage, end state and
    split state as :func:`simulate` on that row alone (the kernel's other entry point)."""
    cell = Cell("test cell", DEFAULT_CELL, 6000.0, 0.2, 3.2)
    rng = np.random.default_rng(5)
    currents = [rng.uniform(0.5, a, n) for a, n in ((1.5, 300), (3.0, 2500), (2.0, 40), (3.5, 4000),
                                                    (1.0, 1200), (3.0, 3300))]
    x0 = simulate(np.full(200, 1.0), 1.0, cell.q_max, cell.r0).final_state.as_array()
    x0 = np.repeat(x0, len(currents), axis=0)
    split = np.array([max(1, c.size // 3) for c in currents])
    ok, x_end, v_min, x_split = fly_batch(currents, x0, cell, split=split)
    assert 0 < ok.sum() < len(currents)  # some rows reach the cut-off, some do not
    mid = simulate(np.full(200, 1.0), 1.0, cell.q_max, cell.r0).final_state
    for k, c in enumerate(currents):
        ref = simulate(c, 1.0, cell.q_max, cell.r0, cell.eod_v, initial_state=mid)
        assert ok[k] == (not ref.eod_reached), k
        assert v_min[k] == pytest.approx(ref.min_voltage_v, abs=1e-9), k
        if ok[k]:
            np.testing.assert_allclose(x_end[k], ref.final_state.as_array()[0], rtol=1e-10, atol=1e-9)
        else:
            np.testing.assert_array_equal(x_end[k], x0[k])  # a failed row keeps its start state
        part = simulate(c[: split[k]], 1.0, cell.q_max, cell.r0, cell.eod_v, initial_state=mid)
        if not part.eod_reached:
            np.testing.assert_allclose(x_split[k], part.final_state.as_array()[0], rtol=1e-10, atol=1e-9)
        else:
            np.testing.assert_array_equal(x_split[k], x0[k])
    empty = fly_batch([], np.zeros((0, 8)), cell)
    assert len(empty) == 3 and all(a.shape[0] == 0 for a in empty)
