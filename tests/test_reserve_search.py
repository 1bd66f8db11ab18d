"""The plan searches' take-off check (``reserve=``): every later move of a planned route passes, from the
state it starts in, the check that the operator will ask at that take-off."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning.episode import Episode
from uam_studio.planning.legs import LegTable
from uam_studio.planning.missions.generate import random_mission
from uam_studio.planning.missions.mission import Mission
from uam_studio.planning.operations.world import actual_winds_mission
from uam_studio.planning.solvers.oracle import feasible_sorties


def _mission(seed: int, n: int) -> Mission:
    return random_mission(np.random.default_rng(seed), n, "single_charge", r0_range=(0.1, 0.3),
                          q_range=(5000.0, 7000.0), radius_km=(12.0, 40.0))


def _headwind(m: Mission, extra_kt: float) -> Mission:
    """``m`` with ``extra_kt`` more headwind at every node (clipped to the tables' range)."""
    return actual_winds_mission(m, {n: float(np.clip(m.node(n).wind_kts + extra_kt, *WIND_RANGE_KTS))
                                    for n in m.node_names})


def _passes(reserve: Episode, i: int, j: int, a: int, state: np.ndarray) -> bool:
    legs, home = reserve.legs, reserve.legs.home
    back = legs.cheapest_level(j, home)
    if back is None or not legs.feasible[i, j, a]:
        return False
    row = np.concatenate([legs.current(i, j, a), legs.current(j, home, back)])
    ok, _, _ = reserve.fly_currents([row], state[None, :])
    return bool(ok[0])


def _replay_checked(episode: Episode, reserve: Episode, nodes: tuple[int, ...], alts: tuple[int, ...]) -> bool:
    """Fly a sortie (destination slots ``nodes``, then home; a level per leg) on ``episode`` and ask the
    check of every move to a destination from the state it starts in."""
    home = episode.legs.home
    state, here = episode.fresh(), home
    for to, a in zip(nodes, alts):
        if not _passes(reserve, here, int(to), int(a), state):
            return False
        ok, x_end, _ = episode.fly([(here, int(to), int(a))], state)
        assert ok[0]
        state, here = x_end[0], int(to)
    return True


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(2, 5), extra_kt=st.floats(0.0, 40.0))
def test_every_move_of_a_checked_sortie_passes_the_check(seed: int, n: int, extra_kt: float) -> None:
    m = _mission(seed, n)
    episode = Episode.of(LegTable(m))
    reserve = Episode.of(LegTable(_headwind(m, extra_kt)), cell=episode.cell)
    plain, checked = feasible_sorties(episode), feasible_sorties(episode, reserve=reserve)
    assert set(checked) <= set(plain)  # the check only removes
    for s in checked.values():
        assert _replay_checked(episode, reserve, s.nodes, s.alts), s


def test_the_check_binds_on_a_mission_that_it_cuts_short() -> None:
    """Under 39 kt more headwind a far sortie that the plain search finds is cut: the two searches differ."""
    differ = 0
    for seed in range(8):
        m = _mission(seed, 4)
        episode = Episode.of(LegTable(m))
        reserve = Episode.of(LegTable(_headwind(m, 39.0)), cell=episode.cell)
        differ += set(feasible_sorties(episode)) != set(feasible_sorties(episode, reserve=reserve))
    assert differ > 0


def test_the_learned_search_keeps_every_move_within_the_check() -> None:
    """The attention planner's search, continued from the vertiport with ``reserve``: each move of the route
    to a destination passes the check from the state it starts in, and the check changes some route."""
    from uam_studio.planning.agents.attention.decode import continue_route

    changed = 0
    for seed in range(4):
        m = _mission(100 + seed, 6)
        episode = Episode.of(LegTable(m))
        reserve = Episode.of(LegTable(_headwind(m, 39.0)), cell=episode.cell)
        home, visited = episode.legs.home, np.zeros(episode.legs.n, dtype=bool)
        plain = continue_route(episode, home, episode.fresh(), visited, 0)
        res = continue_route(episode, home, episode.fresh(), visited, 0, reserve=reserve)
        changed += plain != res
        if res is None:
            continue
        nodes, levels = res
        dests = [k for k in nodes if k != home]
        assert nodes[-1] == home and len(dests) == len(nodes) - 1
        assert _replay_checked(episode, reserve, tuple(dests), tuple(levels[:-1])), res
    assert changed > 0
