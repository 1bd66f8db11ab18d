"""The paper's qualitative findings, as functions that measure them on our physics.

Each function returns plain rows (lists of dicts) so the benchmark, the notebooks and the tests
print the same numbers. The findings (paper, section "Results"):

1. :func:`altitude_by_distance`: which cruise altitude is best for a single leg as it gets longer
   (the paper: 1000 m for the longer flight). We score each altitude by the charge (C) one cell
   gives and by the lowest voltage (V) on the leg.
2. :func:`fixed_altitude_reach`: in a 39 kt headwind, flying every leg at 1000 m reaches more
   destinations than at 3000 m. Scored with the exact oracle restricted to one level.
3. :func:`reward_sweep` over ``gamma``: a larger EOD penalty gives fewer EOD breaches and a more
   conservative agent (fewer destinations, more voltage margin).
4. :func:`reward_sweep` over ``beta`` in multi charge: with ``beta = 0`` the agent returns to charge
   after every destination (charging cycles per destination near 1).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np

from uam_studio.battery import DEFAULT_EOD_V, DEFAULT_Q_MAX, DEFAULT_R0, simulate
from uam_studio.errors import InputError
from uam_studio.flight import leg_feasible, leg_profile
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning.env.environment import REWARD_DEFAULTS
from uam_studio.planning.legs import ALTITUDES_M
from uam_studio.planning.missions.mission import Mission
from uam_studio.planning.missions.scenario import DEFAULT_SCENARIO

__all__ = [
    "altitude_by_distance",
    "fixed_altitude_reach",
    "reward_sweep",
    "with_wind",
]


def altitude_by_distance(
    distances_km: Iterable[float],
    wind_kts: float = 0.0,
    altitudes_m: Sequence[float] = ALTITUDES_M,
    q_max: float = DEFAULT_Q_MAX,
    r0: float = DEFAULT_R0,
    eod_v: float = DEFAULT_EOD_V,
) -> list[dict[str, Any]]:
    """One leg from a full cell, at every altitude, for every distance.

    :param distances_km: leg lengths (km)
    :param wind_kts: head (+) or tail (-) wind on the leg (kt)
    :param altitudes_m: cruise altitudes to compare (m)
    :param q_max: cell capacity (C); ``r0``: internal resistance (ohm); ``eod_v``: cut-off (V)
    :return: one row per distance: ``distance_km``, ``by_altitude`` (``{altitude_m: {"charge_c",
        "duration_s", "min_voltage_v", "safe"}}``, feasible altitudes only), ``least_charge_m`` (the
        altitude that uses the least charge) and ``best_voltage_m`` (the highest minimum voltage), both
        None when no altitude is feasible and safe
    """
    rows = []
    for d in distances_km:
        by_alt: dict[float, dict[str, Any]] = {}
        for alt in altitudes_m:
            if not leg_feasible(float(d), float(alt)):
                continue
            prof = leg_profile(float(d), float(alt), wind_kts)
            res = simulate(prof.current_a, dt_s=1.0, q_max=q_max, r0=r0, eod_v=eod_v)
            by_alt[float(alt)] = {
                "charge_c": float(np.sum(prof.current_a)),
                "duration_s": float(prof.duration_s),
                "min_voltage_v": float(res.min_voltage_v),
                "safe": not bool(res.eod_reached),
            }
        safe = {a: r for a, r in by_alt.items() if r["safe"]}
        rows.append({
            "distance_km": float(d),
            "wind_kts": float(wind_kts),
            "by_altitude": by_alt,
            "least_charge_m": min(safe, key=lambda a: safe[a]["charge_c"]) if safe else None,
            "best_voltage_m": max(safe, key=lambda a: safe[a]["min_voltage_v"]) if safe else None,
        })
    return rows


def with_wind(mission: Mission, wind_kts: float) -> Mission:
    """A copy of ``mission`` with the same wind (kt, + = headwind) on every leg, the return included."""
    dests = tuple(dataclasses.replace(d, wind_kts=wind_kts) for d in mission.destinations)
    return dataclasses.replace(mission, destinations=dests,
                               vertiport=dataclasses.replace(mission.vertiport, wind_kts=wind_kts))


def fixed_altitude_reach(
    missions: Iterable[Mission],
    altitudes_m: Sequence[float] = (1000.0, 3000.0),
    wind_kts: float | None = WIND_RANGE_KTS[1],
) -> list[dict[str, Any]]:
    """How much each single fixed altitude can reach, with the exact oracle restricted to it.

    :param missions: missions (their scenario is used: single_charge counts destinations on one
        charge, multi_charge counts charging cycles too)
    :param altitudes_m: altitudes, each one of ``ALTITUDES_M`` (m)
    :param wind_kts: wind on every leg (kt, + = headwind), or None to keep the missions' winds
    :return: one row per mission: ``mission``, and per altitude ``reached``/``priority``/``cycles``
        (dicts keyed by altitude in m)
    """
    from uam_studio.planning.missions.check import check_plan
    from uam_studio.planning.solvers.oracle import oracle_plan

    idx = []
    for a in altitudes_m:
        if float(a) not in ALTITUDES_M:
            raise InputError("altitudes_m", f"{a!r} is not a planning level; allowed: {ALTITUDES_M}")
        idx.append(ALTITUDES_M.index(float(a)))
    rows = []
    for m in missions:
        m = with_wind(m, wind_kts) if wind_kts is not None else m
        row: dict[str, Any] = {"mission": m.name, "reached": {}, "priority": {}, "cycles": {}}
        for a, i in zip(altitudes_m, idx):
            plan = oracle_plan(m, alt_indices=[i])
            check = check_plan(m, plan.route, plan.altitudes_m)
            assert check.safe, "the oracle returned an unsafe plan"
            row["reached"][float(a)] = len(plan.reached)
            row["priority"][float(a)] = int(plan.reached_priority)
            row["cycles"][float(a)] = int(plan.charging_cycles)
        rows.append(row)
    return rows


def reward_sweep(
    name: str,
    values: Sequence[float],
    scenario: str = DEFAULT_SCENARIO,
    steps: int = 60_000,
    eval_missions: Sequence[Mission] | None = None,
    n_eval: int = 100,
    eval_seed: int = 4242,
    seed: int = 0,
    on_episode: Callable[[float, Any], Any] | None = None,
    **weights: float,
) -> list[dict[str, Any]]:
    """Train one agent per value of a reward weight and measure how it plans under physics.

    :param name: ``"alpha"``, ``"beta"`` or ``"gamma"``
    :param values: the weights to try (>= 0)
    :param scenario: ``single_charge`` or ``multi_charge``
    :param steps: env transitions per agent (about 500 per second on one CPU core)
    :param eval_missions: evaluation missions (default: ``held_out_missions(n_eval, eval_seed)`` of
        ``scenario``, 6-8 destinations)
    :param on_episode: called as ``on_episode(value, EpisodeStats)`` during training (learning curves)
    :param weights: the other reward weights (defaults alpha 1, beta 1, gamma 5)
    :return: one row per value: ``value``, ``eod_breach_rate`` (greedy plans that fall below the
        cut-off under physics), ``mean_reached``, ``mean_priority``, ``mean_cycles``,
        ``cycles_per_destination``, ``mean_margin_v`` (min voltage - cut-off over safe plans),
        ``train_eod_rate`` (share of the last 20% of training episodes that ended at EOD), ``episodes``
    """
    from uam_studio.planning.agents.rollout import rollout_agent
    from uam_studio.planning.agents.training import DQNTrainConfig, train_dqn
    from uam_studio.planning.env import make_env
    from uam_studio.planning.missions.generate import held_out_missions
    from uam_studio.planning.missions.route import simulate_route

    if name not in ("alpha", "beta", "gamma"):
        raise InputError("name", f"{name!r} is not a reward weight; allowed: alpha, beta, gamma")
    missions = list(eval_missions) if eval_missions is not None else held_out_missions(
        n_eval, eval_seed, scenario=scenario)
    rows = []
    for v in values:
        w = {**REWARD_DEFAULTS, **weights, name: float(v)}
        cfg = DQNTrainConfig(scenario=scenario, steps=steps, seed=seed, **w)
        episodes: list[Any] = []

        def cb(ep, v=v, episodes=episodes):
            episodes.append(ep)
            if on_episode is not None:
                on_episode(v, ep)

        model = train_dqn(cfg, make_env(scenario=scenario, backend="physics", **w), callback=cb)
        breaches, reached, prio, cycles, margins = [], [], [], [], []
        for m in missions:
            plan = rollout_agent(m, model, shield=False)  # the agent alone: breaches count
            if not plan.route:
                breaches.append(False)
                reached.append(0)
                prio.append(0)
                cycles.append(0)
                continue
            sim = simulate_route(m, plan.route, plan.altitudes_m)
            safe = sim.eod_s is None
            breaches.append(not safe)
            names = sim.reached if safe else ()
            pr = {d.name: d.priority for d in m.destinations}
            reached.append(len(names))
            prio.append(sum(pr[n] for n in names))
            cycles.append(int(sim.charging_cycles) if safe else 0)  # an unsafe plan counts nothing
            if safe:
                margins.append(float(sim.min_voltage_v) - m.eod_v)
        tail = episodes[int(0.8 * len(episodes)):] or episodes
        rows.append({
            name: float(v),
            "value": float(v),
            "eod_breach_rate": float(np.mean(breaches)),
            "mean_reached": float(np.mean(reached)),
            "mean_priority": float(np.mean(prio)),
            "mean_cycles": float(np.mean(cycles)),
            "cycles_per_destination": float(np.sum(cycles) / max(1, np.sum(reached))),
            "mean_margin_v": float(np.mean(margins)) if margins else 0.0,
            "train_eod_rate": float(np.mean([e.eod_breach for e in tail])) if tail else 0.0,
            "episodes": len(episodes),
        })
    return rows
