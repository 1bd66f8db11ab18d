"""Exact reference planner ("oracle") over the discrete action space, with the physics battery.

The decisions are the environment's: which destination next (or the vertiport) and at which
of the four levels :data:`~uam_studio.planning.legs.ALTITUDES_M` to fly each leg. The battery
is the ground-truth electrochemistry model with the mission's q_max, r0 and cut-off.

Method
------
1. **Feasible sorties.** A sortie is vertiport -> destinations in some order, each leg at some
   level -> vertiport, never below the cut-off. :func:`feasible_sorties` finds, for every set S
   of destinations, whether some sortie visits exactly S, by a label-setting search: a label is
   (visited set, current node, battery state, time, minimum voltage, path). Level k holds the
   labels after k destinations; all children of a level (every unvisited destination and the
   return home, at every feasible level) are flown in one batched integration of the battery
   model (:func:`~uam_studio.planning.episode.fly_batch`). Labels are pruned when

   a. the voltage fell below the cut-off on the leg (exact: the aircraft is lost), or
   b. another label at the same (visited set, node) *dominates* them: at least as much charge
      in each electrode store (``qnb``, ``qns`` >= and ``qpb``, ``qps`` <=; the negative stores
      empty and the positive ones fill during discharge) and no larger overpotentials
      (``vo``, ``vsn``, ``vsp`` <=).

   **Monotonicity assumption** behind (b): a cell with more charge and smaller overpotentials
   stays at a higher voltage under any future current, so whatever the dominated label can still
   fly, the dominating one can too. It is not a theorem of the model: the Butler-Volmer exchange
   current depends on the surface charge (so a fuller surface can raise the overpotential
   target slightly), and the cell temperature ``tb`` is left out of the comparison (its effect on
   the voltage is below about 1 mV per K and changes sign during a discharge). The tests check
   it against brute-force enumeration without dominance (same feasible sets, same optimum).
2. **Scenarios.**

   * single_charge: the feasible sortie with the largest total priority (ties: shorter flight
     time, then higher minimum voltage);
   * multi_charge: the fewest sorties that together visit every destination any sortie can
     visit, each destination once as in the environment (exact set-partition dynamic programme
     over subsets, 3^n steps; ties: shorter total time); the route puts ``"vertiport"`` (a
     recharge) after each sortie;
   * single_flight: the level that reaches ``destinations[0]`` with the highest minimum voltage.

Exactness: for missions of up to ``N_MAX = 8`` destinations over the 4 levels, the answer is
optimal for the priority (single_charge) and the number of charging cycles (multi_charge) under
the monotonicity assumption above. The tie-breaks (time, minimum voltage) are taken among the
labels that survive pruning, so they are best-effort. The oracle plans with the true cell; it
is a bound on what any policy can reach, not a policy that could be flown without knowing the
health.

Cost: ``stats["time_s"]`` of each plan; it grows with the feasible sets (a fresh cell with 8
destinations close by flies tens of thousands of legs) and is almost all battery integration. The
measured times are in ``benchmarks/RESULTS.md``, "The oracle's reference beyond 8 destinations" (``bench_reference.py``)
and "Flying the mission" (``bench_fly.py speed``).

The dominance assumption was also checked outside the tests on 44 random 5-destination missions
over all 4 levels (the default random cells, 8-45 km): the feasible sets with and without pruning
were identical in every case.

Larger missions: :func:`oracle_plan` is exact up to :data:`EXACT_MAX` (``N_MAX = 8``)
destinations (``stats["exact"] = True``). For 9-20 it returns the plan of the reference solver,
OR-Tools routing re-checked on the physics model (:mod:`~uam_studio.planning.solvers.reference`),
with ``stats["exact"] = False`` and a message saying so: the label search grows about tenfold a
destination (benchmarks/RESULTS.md, "The oracle's reference beyond 8 destinations", has the times).
single_flight is one leg, exact at any size.
:func:`feasible_sorties` and the cover work on a :class:`LegTable` of any number of slots
(``legs.slots`` bits in the masks).

Hard missions never raise: no destinations, more than 20 (the first 20 are planned), destinations
no level can reach, a cell that cannot even finish the take-off all give a :class:`Plan` with an
empty or partial route and one message per problem.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from uam_studio.battery.parameters import CellParameters
from uam_studio.errors import InputError
from uam_studio.planning.episode import Episode
from uam_studio.planning.legs import (
    ALTITUDES_M,
    DT_S,
    N_ALTITUDES,
    N_MAX,
    LegTable,
)
from uam_studio.planning.missions.check import Plan, make_plan
from uam_studio.planning.missions.mission import VERTIPORT, Mission
from uam_studio.planning.solvers.reference import reference_from_setup
from uam_studio.planning.solvers.setup import (
    prepare_mission,
    single_flight_plan,
    too_close,
)

EXACT_MAX = N_MAX  # the most destinations oracle_plan solves exactly; more go to the reference solver

# +1: more is better, -1: less is better, 0: ignored; order of uam_studio.battery.STATE_NAMES
# (tb, vo, vsn, vsp, qnb, qns, qpb, qps).
DOMINANCE_SIGN = np.array([0.0, -1.0, -1.0, -1.0, 1.0, 1.0, -1.0, -1.0])
# ----------------------------------------------------------------------------- sorties


@dataclass(frozen=True)
class Sortie:
    """A feasible sortie: ``nodes`` (destination slots in visiting order), ``alts`` (altitude indices,
    one per leg, the last for the return), ``mask`` (bit k set for slot k), ``time_s`` (take-off to
    landing home, dwell included) and ``min_voltage_v`` (V)."""

    nodes: tuple[int, ...]
    alts: tuple[int, ...]
    mask: int
    time_s: float
    min_voltage_v: float


def _better(a: Sortie, b: Sortie | None) -> bool:
    return b is None or (a.time_s, -a.min_voltage_v) < (b.time_s, -b.min_voltage_v)


def _dominated(keys: np.ndarray, good: np.ndarray) -> np.ndarray:
    """True for labels dominated by another label with the same key (``good``: larger is better)."""
    out = np.zeros(keys.size, dtype=bool)
    order = np.argsort(keys, kind="stable")
    sk = keys[order]
    bounds = np.flatnonzero(np.diff(sk)) + 1
    for grp in np.split(order, bounds):
        m = grp.size
        if m < 2:
            continue
        g = good[grp]
        ge = cast(np.ndarray, (g[:, None, :] >= g[None, :, :]).all(axis=-1))  # ge[j, i]: j at least as good as i
        np.fill_diagonal(ge, False)
        # strict dominance, or equal with a smaller index (keeps one of identical labels)
        beats = ge & (~ge.T | (np.arange(m)[:, None] < np.arange(m)[None, :]))
        out[grp] = beats.any(axis=0)
    return out


def feasible_sorties(
    episode: Episode,
    alt_indices: Iterable[int] = range(N_ALTITUDES),
    dominance: bool = True,
    allowed: np.ndarray | None = None,
    stats: dict[str, Any] | None = None,
    start: tuple[int, np.ndarray, int] | None = None,
    first_moves: np.ndarray | None = None,
    reserve: Episode | None = None,
) -> dict[int, Sortie]:
    """Every set of destinations one charge can visit and bring the aircraft home, with its best sortie.

    :param episode: the mission's :class:`~uam_studio.planning.episode.Episode` (its leg table, the cell
        flown, and rules with a way home: not ``single_flight``). Every present destination is
        considered, those too close to the vertiport to fly to directly included (a sortie may reach
        them through another destination).
    :param alt_indices: levels allowed (indices into ``ALTITUDES_M``).
    :param dominance: prune dominated labels (see the module docstring); False enumerates every
        order and level (for testing; exponential).
    :param allowed: bool [slots], destination slots that may be visited (default: all present).
    :param stats: filled with ``labels``, ``legs_flown``, ``pruned_eod``, ``pruned_dominated``.
    :param start: ``(node slot, battery state [8], visited mask)`` to continue a sortie already under
        way (default: the vertiport, a full charge, nothing visited). The sorties found then continue
        from that node and state; their ``mask`` includes the visited bits and ``time_s`` counts from
        the start.
    :param first_moves: bool [slots + 1, N_ALTITUDES], the (target, level) pairs the first leg
        may take (default: all; target ``episode.home`` is the vertiport).
    :param reserve: the same mission under the winds of a take-off check (same nodes, same cell): a
        move to a destination is searched only if, from the state it starts in, that leg and then the
        way home (its cheapest level) end above the cut-off on this episode's legs; default: no check.
    :return: ``{mask: Sortie}``, bit k of ``mask`` for slot k.
    """
    if episode.rules.one_leg:
        raise InputError("episode", f"{episode.rules.name} has no way home: no sortie to search")
    legs = episode.legs
    alts = np.array(sorted(set(int(a) for a in alt_indices)), dtype=int)
    slots, home = legs.slots, legs.home
    n_targets = slots + 1
    ok_slot = legs.present[:slots].copy() if allowed is None else np.asarray(allowed, bool) & legs.present[:slots]
    bit = 1 << np.arange(slots, dtype=np.int64)
    good_sign = DOMINANCE_SIGN

    if start is None:
        mask = np.zeros(1, dtype=np.int64)
        node = np.full(1, home)
        state = episode.fresh()[None, :]
    else:
        mask = np.full(1, int(start[2]), dtype=np.int64)
        node = np.full(1, int(start[0]))
        state = np.asarray(start[1], dtype=float).reshape(1, -1)
    t_s = np.zeros(1)
    vmin = np.full(1, np.inf)
    paths: list[tuple[tuple[int, ...], tuple[int, ...]]] = [((), ())]
    found: dict[int, Sortie] = {}
    st = {"labels": 1, "legs_flown": 0, "pruned_eod": 0, "pruned_dominated": 0}

    first_leg = True
    while mask.size:
        visited = (mask[:, None] & bit[None, :]) != 0
        cand = episode.moves(node, visited, among=ok_slot)[:, :, alts]
        if first_moves is not None and first_leg:
            cand &= np.asarray(first_moves, dtype=bool)[None, :, alts]
        first_leg = False
        li, ti, ai = np.nonzero(cand)
        if reserve is not None and li.size:
            keep = reserve.there_and_home(list(zip(node[li], ti, alts[ai])), state[li])
            li, ti, ai = li[keep], ti[keep], ai[keep]
        if li.size == 0:
            break
        levels = alts[ai]
        currents = [legs.current(int(node[a]), int(b), int(c)) for a, b, c in zip(li, ti, levels)]
        ok, x_end, v_leg = episode.fly_currents(currents, state[li])
        st["legs_flown"] += li.size
        st["pruned_eod"] += int((~ok).sum())
        dur = np.fromiter((c.size for c in currents), dtype=float, count=li.size) * DT_S
        t_new = t_s[li] + dur
        v_new = np.minimum(vmin[li], v_leg)

        landed = ok & (ti == home)
        for k in np.flatnonzero(landed):
            nodes, path_alts = paths[li[k]]
            s = Sortie(nodes, path_alts + (int(levels[k]),), int(mask[li[k]]), float(t_new[k]), float(v_new[k]))
            if _better(s, found.get(s.mask)):
                found[s.mask] = s

        fwd = np.flatnonzero(ok & (ti != home))
        new_mask = mask[li[fwd]] | bit[ti[fwd]]
        new_node = ti[fwd]
        new_state = x_end[fwd]
        if dominance and fwd.size > 1:
            dom = _dominated(new_mask * n_targets + new_node, new_state * good_sign[None, :])
            st["pruned_dominated"] += int(dom.sum())
            fwd, new_mask, new_node, new_state = fwd[~dom], new_mask[~dom], new_node[~dom], new_state[~dom]
        paths = [(paths[li[k]][0] + (int(ti[k]),), paths[li[k]][1] + (int(levels[k]),)) for k in fwd]
        mask, node, state, t_s, vmin = new_mask, new_node, new_state, t_new[fwd], v_new[fwd]
        st["labels"] += int(mask.size)
    if stats is not None:
        stats.update(st)
    return found


def sortie_cover_table(found: dict[int, Sortie], universe: int) -> dict[int, tuple[int, float, int]]:
    """For every subset of ``universe`` (a bitmask) that sorties of ``found`` can partition: the fewest
    sorties, their total time (s) and the set of one of them, ``{subset: (sorties, time_s, first set)}``.

    Exact dynamic programme over the subsets of ``universe`` (3^n); ties: less time.
    """
    subsets = []
    sub = universe
    while True:
        subsets.append(sub)
        if sub == 0:
            break
        sub = (sub - 1) & universe
    best: dict[int, tuple[int, float, int]] = {0: (0, 0.0, 0)}  # mask -> (sorties, time, chosen set)
    for mset in sorted(subsets)[1:]:
        low = mset & -mset
        cand = None
        s = mset
        while s:
            if s & low and s in found and (mset ^ s) in best:
                n, t, _ = best[mset ^ s]
                c = (n + 1, t + found[s].time_s, s)
                if cand is None or c[:2] < cand[:2]:
                    cand = c
            s = (s - 1) & mset
        if cand is not None:
            best[mset] = cand
    return best


def min_sortie_cover(found: dict[int, Sortie], universe: int,
                     value: Callable[[int], int] | None = None) -> list[Sortie]:
    """Fewest sorties from ``found`` whose sets partition ``universe`` (a bitmask); ties: less time.

    Exact dynamic programme over the subsets of ``universe`` (3^n). Where no partition covers all of
    ``universe`` (two destinations each reachable only in a sortie through the same others), the
    partitionable subset of the largest ``value`` (default: the number of destinations), then the
    fewest sorties and less time. [] only if no sortie is in ``found``.
    """
    best = sortie_cover_table(found, universe)
    mset = universe
    if universe not in best:
        score = value or (lambda m: m.bit_count())
        mset = max(best, key=lambda m: (score(m), -best[m][0], -best[m][1]))
    out = []
    while mset:
        s = best[mset][2]
        out.append(found[s])
        mset ^= s
    return out


def coverable_mask(found: dict[int, Sortie]) -> int:
    """The destinations (bitmask) that some sortie of ``found`` visits."""
    mask = 0
    for m in found:
        mask |= m
    return mask


def mask_priority(legs: LegTable, mask: int) -> int:
    """Total priority of the destinations in ``mask`` (bit k: slot k of ``legs``)."""
    return int(sum(int(legs.priority[k]) for k in range(legs.slots) if mask >> k & 1))


def best_single_sortie(found: dict[int, Sortie], legs: LegTable) -> Sortie:
    """The single_charge choice among ``found`` (not empty): the most priority of its set, then less
    flight time, then a higher minimum voltage."""
    return max(found.values(), key=lambda s: (mask_priority(legs, s.mask), -s.time_s, s.min_voltage_v))


# ----------------------------------------------------------------------------- planner


def oracle_plan(mission: Mission, scenario: str | None = None, alt_indices: Iterable[int] = range(N_ALTITUDES),
                dominance: bool = True, params: CellParameters | None = None) -> Plan:
    """The exact optimal plan of ``mission`` (see the module docstring) as a :class:`Plan`; past
    :data:`EXACT_MAX` destinations (up to 20), the reference solver's plan
    (:mod:`~uam_studio.planning.solvers.reference`), not proven optimal. ``stats["exact"]`` says which.

    :param mission: the mission (a dict in the JSON format is validated first).
    :param scenario: overrides ``mission.scenario``.
    :param alt_indices: allowed levels (indices into ``ALTITUDES_M``).
    :param dominance: label pruning (False: exhaustive, for tests on small missions).
    :param params: the cell's parameter set (default: the mission's); the hindsight reference passes a pack's own.
    """
    t0 = time.perf_counter()
    setup = prepare_mission(mission, scenario, "oracle", params)
    if setup.early is not None:  # nothing to plan: the empty answer is exact
        return dataclasses.replace(setup.early, stats={**setup.early.stats, "exact": True})
    assert (setup.mission is not None and setup.full_mission is not None and setup.episode is not None
            and setup.legs is not None)
    mission, full_mission, msgs, stats, legs = (setup.mission, setup.full_mission, setup.messages, setup.stats,
                                                setup.legs)
    rules, dests = setup.episode.rules, mission.destinations
    if not rules.one_leg and len(dests) > EXACT_MAX:
        return reference_from_setup(setup, "oracle", alt_indices, t0)
    if rules.one_leg:
        return single_flight_plan(setup, "oracle", alt_indices, t0)
    stats["exact"] = True

    def done(route: list[str], alts: list[float]) -> Plan:
        stats["time_s"] = round(time.perf_counter() - t0, 4)
        return make_plan(full_mission, "oracle", route, alts, msgs, stats)

    found = feasible_sorties(setup.episode, alt_indices, dominance, stats=stats)
    stats["feasible_sets"] = len(found)
    coverable = coverable_mask(found)
    for k in range(len(dests)):
        if not coverable >> k & 1:
            msgs.append(too_close(legs, k) or
                        f"cannot reach {dests[k].name} at any altitude and return to the vertiport "
                        "with this battery")
    if not found:
        return done([], [])

    def names(s: Sortie) -> tuple[list[str], list[float]]:
        return ([legs.names[k] for k in s.nodes] + [VERTIPORT], [ALTITUDES_M[a] for a in s.alts])

    if rules.one_sortie:
        best = best_single_sortie(found, legs)
        left = [legs.names[k] for k in range(len(dests)) if coverable >> k & 1 and not best.mask >> k & 1]
        if left:
            msgs.append(f"not visited on this charge: {', '.join(left)} (no safe single-charge route adds them)")
        route, alts = names(best)
        return done(route, alts)

    cover = min_sortie_cover(found, coverable, lambda m: mask_priority(legs, m))
    covered = 0
    for s in cover:
        covered |= s.mask
    left = [legs.names[k] for k in range(len(dests)) if coverable >> k & 1 and not covered >> k & 1]
    if left:
        msgs.append(f"not visited: {', '.join(left)} (each reachable only in a sortie through destinations "
                    "that another sortie needs; the cover keeps the most priority)")
    stats["sorties"] = len(cover)
    route, alts = [], []
    for s in cover:
        r, a = names(s)
        route += r
        alts += a
    return done(route, alts)


__all__ = [
    "DOMINANCE_SIGN",
    "best_single_sortie",
    "coverable_mask",
    "mask_priority",
    "Sortie",
    "feasible_sorties",
    "min_sortie_cover",
    "oracle_plan",
    "sortie_cover_table",
]
