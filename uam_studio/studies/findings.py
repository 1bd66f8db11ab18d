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
from uam_studio.engine import run_tasks
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
    "format_findings",
    "paper_findings",
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


def _reach_row(m: Mission, altitudes_m: tuple[float, ...], idx: tuple[int, ...]) -> dict[str, Any]:
    """One task of :func:`fixed_altitude_reach`: one mission, the oracle at each single altitude."""
    from uam_studio.planning.missions.check import check_plan
    from uam_studio.planning.solvers.oracle import oracle_plan

    row: dict[str, Any] = {"mission": m.name, "reached": {}, "priority": {}, "cycles": {}}
    for a, i in zip(altitudes_m, idx):
        plan = oracle_plan(m, alt_indices=[i])
        check = check_plan(m, plan.route, plan.altitudes_m)
        assert check.safe, "the oracle returned an unsafe plan"
        row["reached"][float(a)] = len(plan.reached)
        row["priority"][float(a)] = int(plan.reached_priority)
        row["cycles"][float(a)] = int(plan.charging_cycles)
    return row


def fixed_altitude_reach(
    missions: Iterable[Mission],
    altitudes_m: Sequence[float] = (1000.0, 3000.0),
    wind_kts: float | None = WIND_RANGE_KTS[1],
    workers: int | None = 0,
    address: str | None = None,
) -> list[dict[str, Any]]:
    """How much each single fixed altitude can reach, with the exact oracle restricted to it.

    :param missions: missions (their scenario is used: single_charge counts destinations on one
        charge, multi_charge counts charging cycles too)
    :param altitudes_m: altitudes, each one of ``ALTITUDES_M`` (m)
    :param wind_kts: wind on every leg (kt, + = headwind), or None to keep the missions' winds
    :param workers: one Dask task per mission (:func:`uam_studio.engine.run_tasks`): 0 (the default)
        runs them here, None on a local cluster of one worker per core, N on N workers
    :param address: a running Dask scheduler's address (``tcp://host:8786``) instead
    :return: one row per mission: ``mission``, and per altitude ``reached``/``priority``/``cycles``
        (dicts keyed by altitude in m)
    """
    idx = []
    for a in altitudes_m:
        if float(a) not in ALTITUDES_M:
            raise InputError("altitudes_m", f"{a!r} is not a planning level; allowed: {ALTITUDES_M}")
        idx.append(ALTITUDES_M.index(float(a)))
    alts = tuple(float(a) for a in altitudes_m)
    tasks = [(with_wind(m, wind_kts) if wind_kts is not None else m, alts, tuple(idx)) for m in missions]
    if not tasks:
        return []
    return run_tasks(_reach_row, tasks, workers=workers, address=address, name="fixed-altitude")


def _sweep_task(name: str, v: float, scenario: str, steps: int, seed: int, weights: dict[str, float],
                missions: list[Mission]) -> tuple[dict[str, Any], list[Any]]:
    """One task of :func:`reward_sweep`: train one agent with ``name = v`` and score it under physics;
    returns its row and its training episodes (for the learning curves)."""
    from uam_studio.planning.agents.dqn.rollout import rollout_agent
    from uam_studio.planning.agents.dqn.training import DQNTrainConfig, train_dqn
    from uam_studio.planning.env import make_env
    from uam_studio.planning.missions.route import simulate_route

    w: dict[str, Any] = {**REWARD_DEFAULTS, **weights, name: float(v)}
    cfg = DQNTrainConfig(scenario=scenario, steps=steps, seed=seed, **w)
    episodes: list[Any] = []
    model = train_dqn(cfg, make_env(scenario=scenario, backend="physics", **w), callback=episodes.append)
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
    row = {
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
    }
    return row, episodes


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
    workers: int | None = 0,
    address: str | None = None,
    **weights: float,
) -> list[dict[str, Any]]:
    """Train one agent per value of a reward weight and measure how it plans under physics.

    :param name: ``"alpha"``, ``"beta"`` or ``"gamma"``
    :param values: the weights to try (>= 0)
    :param scenario: ``single_charge`` or ``multi_charge``
    :param steps: env transitions per agent (about 500 per second on one CPU core)
    :param eval_missions: evaluation missions (default: ``held_out_missions(n_eval, eval_seed)`` of
        ``scenario``, 6-8 destinations)
    :param on_episode: called as ``on_episode(value, EpisodeStats)`` for each training episode, in
        order, once that value's agent is trained (learning curves)
    :param workers: one Dask task per value (:func:`uam_studio.engine.run_tasks`): 0 (the default)
        trains them here, one after another; None on a local cluster of one worker per core; N on N
        workers. Each agent is seeded by ``seed``: the rows are the same whatever the workers.
    :param address: a running Dask scheduler's address (``tcp://host:8786``) instead
    :param weights: the other reward weights (defaults alpha 1, beta 1, gamma 5)
    :return: one row per value: ``value``, ``eod_breach_rate`` (greedy plans that fall below the
        cut-off under physics), ``mean_reached``, ``mean_priority``, ``mean_cycles``,
        ``cycles_per_destination``, ``mean_margin_v`` (min voltage - cut-off over safe plans),
        ``train_eod_rate`` (share of the last 20% of training episodes that ended at EOD), ``episodes``
    """
    from uam_studio.planning.missions.generate import held_out_missions

    if name not in ("alpha", "beta", "gamma"):
        raise InputError("name", f"{name!r} is not a reward weight; allowed: alpha, beta, gamma")
    missions = list(eval_missions) if eval_missions is not None else held_out_missions(
        n_eval, eval_seed, scenario=scenario)
    tasks = [(name, float(v), scenario, int(steps), int(seed), dict(weights), missions) for v in values]
    if not tasks:
        return []
    rows = []
    for (row, episodes), v in zip(run_tasks(_sweep_task, tasks, workers=workers, address=address,
                                            name=f"sweep-{name}"), values):
        if on_episode is not None:
            for ep in episodes:
                on_episode(float(v), ep)
        rows.append(row)
    return rows


FINDINGS_DISTANCES_KM = (25.0, 40.0, 55.56, 80.0, 100.0)  # finding 1's leg lengths
FINDINGS_WINDS_KTS = (WIND_RANGE_KTS[0], 0.0, WIND_RANGE_KTS[1])  # finding 1's winds: tail, calm, head (kt)
HEADWIND_SEED = 2024  # finding 2's held-out missions
GAMMAS = (0.0, 5.0, 50.0)  # finding 3
BETAS = (0.0, 1.0, 5.0)  # finding 4


def paper_findings(quick: bool = False, workers: int | None = None, address: str | None = None,
                   steps: int | None = None, n_eval: int | None = None,
                   n_missions: int | None = None) -> dict[str, Any]:
    """The paper's four findings measured on our physics (module docstring), every independent part a
    Dask task (:func:`uam_studio.engine.run_tasks`): finding 2's missions and findings 3 and 4's agents.

    :param quick: 10 missions for finding 2, 20,000 steps and 30 evaluation missions per agent (else 40
        missions, 80,000 steps and 100 missions)
    :param workers: local cluster size (default: one per core); 0 runs everything here
    :param address: a running Dask scheduler's address (``tcp://host:8786``) instead
    :param steps: training steps per agent, ``n_eval``: evaluation missions per agent, ``n_missions``:
        finding 2's missions, each in place of ``quick``'s choice when given
    :return: ``altitude`` (finding 1's rows), ``headwind`` (rows, ``mean_1000``, ``mean_3000``, ``n``),
        ``gamma`` and ``beta`` (the sweeps' rows), ``steps``, ``n_eval``
    """
    from uam_studio.planning.missions.generate import held_out_missions

    out: dict[str, Any] = {"altitude": [row for wind in FINDINGS_WINDS_KTS
                                        for row in altitude_by_distance(FINDINGS_DISTANCES_KM, wind_kts=wind)]}
    n = n_missions if n_missions is not None else (10 if quick else 40)
    rows = fixed_altitude_reach(held_out_missions(n, HEADWIND_SEED), (1000.0, 3000.0), wind_kts=WIND_RANGE_KTS[1],
                                workers=workers, address=address)
    out["headwind"] = {"rows": rows, "n": n, "mean_1000": float(np.mean([r["reached"][1000.0] for r in rows])),
                       "mean_3000": float(np.mean([r["reached"][3000.0] for r in rows]))}
    out["steps"] = steps if steps is not None else (20_000 if quick else 80_000)
    out["n_eval"] = n_eval if n_eval is not None else (30 if quick else 100)
    out["gamma"] = reward_sweep("gamma", GAMMAS, "single_charge", steps=out["steps"], n_eval=out["n_eval"],
                                workers=workers, address=address)
    out["beta"] = reward_sweep("beta", BETAS, "multi_charge", steps=out["steps"], n_eval=out["n_eval"],
                               workers=workers, address=address)
    return out


def format_findings(out: dict[str, Any]) -> str:
    """:func:`paper_findings`' result as plain text, one block per finding."""
    lines = ["1. best altitude by leg length (fresh cell; charge C per altitude 500/1000/2000/3000 m)"]
    for r in out["altitude"]:
        ch = " ".join(f"{r['by_altitude'][a]['charge_c']:5.0f}" if a in r["by_altitude"] else "    -"
                      for a in ALTITUDES_M)
        lines.append(f"   wind {r['wind_kts']:+5.0f} kt, {r['distance_km']:6.2f} km: {ch}  least charge "
                     f"{r['least_charge_m']}, highest min voltage {r['best_voltage_m']}")
    h = out["headwind"]
    more = sum(r["reached"][1000.0] > r["reached"][3000.0] for r in h["rows"])
    fewer = sum(r["reached"][1000.0] < r["reached"][3000.0] for r in h["rows"])
    lines.append(f"2. 39 kt headwind, every leg at one level (oracle), {h['n']} missions: mean destinations "
                 f"1000 m {h['mean_1000']:.2f}, 3000 m {h['mean_3000']:.2f}; 1000 m reaches more on "
                 f"{more}/{h['n']}, fewer on {fewer}")
    lines.append(f"3. gamma sweep (single charge, {out['steps']} steps each, {out['n_eval']} held-out missions):")
    for r in out["gamma"]:
        lines.append(f"   gamma {r['gamma']:5.1f}: EOD breach {100 * r['eod_breach_rate']:5.1f}% (training tail "
                     f"{100 * r['train_eod_rate']:5.1f}%), mean destinations {r['mean_reached']:.2f}, "
                     f"margin {1000 * r['mean_margin_v']:.0f} mV")
    lines.append(f"4. beta sweep (multi charge, {out['steps']} steps each, {out['n_eval']} held-out missions):")
    for r in out["beta"]:
        lines.append(f"   beta {r['beta']:4.1f}: charging cycles per destination {r['cycles_per_destination']:.2f}, "
                     f"mean cycles {r['mean_cycles']:.2f}, destinations {r['mean_reached']:.2f}, "
                     f"EOD breach {100 * r['eod_breach_rate']:.1f}%")
    return "\n".join(lines)
