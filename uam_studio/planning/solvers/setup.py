"""What the solvers share: the batched flight of many legs (:func:`fly_batch`, also used by
:mod:`~uam_studio.planning.operations`), the planners' preamble (:func:`prepare_mission` ->
:class:`PlanSetup`: validate, pick the scenario, cap at the policy's number of destinations, stop
early if the cell cannot finish the take-off) and the exact answer of a single flight
(:func:`safest_single_flight`, :func:`single_flight_plan`).
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from uam_studio.battery import DEFAULT_CELL, BatteryState, SimulationResult, full_charge, simulate
from uam_studio.battery.eod import below_eod
from uam_studio.battery.solver import integrate_current
from uam_studio.errors import InputError
from uam_studio.planning.legs import ALTITUDES_M, DT_S, MIN_LEG_KM, N_MAX, LegTable, takeoff_current
from uam_studio.planning.missions.check import Plan, make_plan
from uam_studio.planning.missions.mission import MAX_DESTINATIONS, Mission, as_mission
from uam_studio.planning.missions.scenario import check_scenario

_ROW_BATCH = 512  # trajectories integrated together (small blocks stay in cache: faster)
_CHUNK_S = 128  # samples per integration pass
_STATE_ORDER = ("tb", "vo", "vsn", "vsp", "qnb", "qns", "qpb", "qps")  # uam_studio.battery.STATE_NAMES


def fly_batch(
    currents: Sequence[np.ndarray], x0: np.ndarray, q_max: float, r0: float, eod_v: float,
    split: np.ndarray | None = None, chunk_s: int = _CHUNK_S,
) -> tuple[np.ndarray, ...]:
    """Fly many legs of different lengths from many states in batched integrations.

    :param currents: B per-cell currents (A, 1 s samples), any lengths.
    :param x0: start states, shape [B, 8] (order of ``STATE_NAMES``).
    :param split: optional [B] sample counts (1 to the row's length): also return the state after
        that many samples of each row (e.g. the end of the first of two legs flown as one row).
    :param chunk_s: samples per integration pass (shorter: rows that fail stop sooner; longer: fewer
        passes for a few long rows).
    :return: ``(ok [B], x_end [B, 8], v_min [B])``: no sample below ``eod_v``; state after the
        last sample (the start state where not ok); lowest voltage (V), the failing sample
        included. Same numbers as :func:`uam_studio.battery.simulate` leg by leg (same solver).
        With ``split``, a fourth array ``x_split [B, 8]``: the state after ``split`` samples (the
        start state where the row failed before them).
    """
    b = len(currents)
    x_end = np.array(x0, dtype=float, copy=True).reshape(b, -1)
    ok = np.ones(b, dtype=bool)
    v_min = np.full(b, np.inf)
    x_split = x_end.copy() if split is not None else None
    if b == 0:
        return (ok, x_end, v_min) if x_split is None else (ok, x_end, v_min, x_split)
    lengths = np.fromiter((c.size for c in currents), dtype=np.int64, count=b)
    order = np.argsort(lengths, kind="stable")
    q_total = float(DEFAULT_CELL.q_total(q_max))
    for s in range(0, b, _ROW_BATCH):
        rows = order[s:s + _ROW_BATCH]
        n_rows = rows.size
        lens = lengths[rows]
        cur = np.zeros((n_rows, int(lens.max())))
        for k, r in enumerate(rows):
            cur[k, : lens[k]] = currents[r]
        state = x_end[rows]
        alive = np.arange(n_rows)
        with np.errstate(all="ignore"):
            for start in range(0, cur.shape[1], chunk_s):
                alive = alive[lens[alive] > start]
                if alive.size == 0:
                    break
                stop = min(cur.shape[1], start + chunk_s)
                width = stop - start
                v, seq = integrate_current(
                    cur[alive, start:stop], BatteryState.from_array(state[alive]),
                    np.full(alive.size, q_total), np.full(alive.size, float(r0)), DT_S, DEFAULT_CELL)
                n_real = np.minimum(lens[alive] - start, width)
                real = np.arange(width)[None, :] < n_real[:, None]
                below = below_eod(v, eod_v) & real
                hit = below.any(axis=1)
                v_min[rows[alive]] = np.minimum(v_min[rows[alive]], np.where(real, v, np.inf).min(axis=1))
                last = n_real - 1
                idx = np.arange(alive.size)
                picked = np.stack([seq[n][idx, last] for n in _STATE_ORDER], axis=-1)
                keep = ~hit
                if x_split is not None:
                    at = np.asarray(split)[rows[alive]] - 1 - start  # the split's sample in this chunk
                    k = np.flatnonzero((at >= 0) & (at < width))
                    k = k[np.cumsum(below[k], axis=1)[np.arange(k.size), at[k]] == 0]  # not failed by then
                    if k.size:
                        x_split[rows[alive[k]]] = np.stack([seq[n][k, at[k]] for n in _STATE_ORDER], axis=-1)
                state[alive[keep]] = picked[keep]
                ok[rows[alive[hit]]] = False
                alive = alive[keep]
        x_end[rows] = np.where(ok[rows, None], state, x_end[rows])
    v_min = np.nan_to_num(v_min, nan=0.0)
    return (ok, x_end, v_min) if x_split is None else (ok, x_end, v_min, x_split)


# ----------------------------------------------------------------------------- planner preamble


def _as_mission(mission: Any) -> tuple[Mission | None, list[str]]:
    try:
        return as_mission(mission), []
    except InputError as err:
        return None, [f"invalid mission: {err}"]


def fly_takeoff(q_max: float, r0: float, eod_v: float) -> SimulationResult:
    """A fresh cell (q_max C, r0 ohm) on the take-off and climb to 500 m (the least demanding start
    of any leg), with the cut-off ``eod_v`` (V): the physics model's run."""
    return simulate(takeoff_current(), DT_S, q_max, r0, eod_v)


def takeoff_failure(q_max: float, r0: float, eod_v: float) -> str | None:
    """A message if a fresh cell cannot finish the take-off and climb to 500 m above the cut-off
    (:func:`fly_takeoff`), else None."""
    res = fly_takeoff(q_max, r0, eod_v)
    if not res.eod_reached:
        return None
    return (f"the battery cannot finish takeoff: the voltage falls below {eod_v:.2f} V after "
            f"{res.eod_s:.0f} s of the {res.time_s.size} s take-off and climb to 500 m "
            f"(q_max {q_max:.0f} C, r0 {r0:.3f} ohm)")


def single_flight_note(mission: Mission) -> str | None:
    """The note every planner gives for a single_flight mission of more than one destination (it flies
    the leg to the first one only), else None."""
    dests = mission.destinations
    return f"single flight: planning the leg to {dests[0].name} only" if len(dests) > 1 else None


def too_close(legs: LegTable, k: int) -> str | None:
    d = legs.dist[legs.home, k]
    if d < MIN_LEG_KM[0]:
        return (f"cannot reach {legs.names[k]} at any altitude: it is {d:.1f} km from the vertiport and "
                f"the shortest leg is {MIN_LEG_KM[0]:.1f} km")
    if not legs.feasible[legs.home, k].any():
        return f"cannot reach {legs.names[k]} at any altitude: it is {d:.0f} km from the vertiport"
    return None


@dataclass
class PlanSetup:
    """What the planners share before searching: the mission capped at the policy's number of
    destinations (:func:`destination_limit`), the user's full mission (plans are checked against it),
    scenario, messages, stats and the leg table (``max(N_MAX, destinations)`` slots; N_MAX for the
    DQN); ``early`` is a finished :class:`Plan` when there is nothing to plan."""

    mission: Mission | None
    full_mission: Mission | None
    scenario: str | None
    messages: list[str]
    stats: dict[str, Any]
    legs: LegTable | None = None
    early: Plan | None = None


def destination_limit(policy: str) -> int:
    """The most destinations ``policy`` plans: N_MAX (8) for the paper's DQN (its action space), else
    MAX_DESTINATIONS (20: the greedy rule, the oracle and its reference solver)."""
    return N_MAX if policy == "dqn" else MAX_DESTINATIONS


def prepare_mission(mission: Any, scenario: str | None, policy: str) -> PlanSetup:
    """The planners' shared preamble: validate the mission, pick the scenario, keep at most
    :func:`destination_limit` destinations (the rest get a message), build the leg table and stop
    early if the battery cannot finish takeoff."""
    mission, msgs = _as_mission(mission)
    if mission is None:
        return PlanSetup(None, None, scenario, msgs, {}, early=Plan(policy, messages=msgs))
    scenario = scenario or mission.scenario
    try:
        check_scenario(scenario)
    except InputError as err:
        return PlanSetup(mission, mission, scenario, msgs, {}, early=Plan(policy, messages=[str(err)]))
    stats: dict[str, Any] = {"scenario": scenario}
    dests = mission.destinations
    if not dests:
        return PlanSetup(mission, mission, scenario, msgs, stats,
                         early=Plan(policy, messages=["the mission has no destinations"], stats=stats))
    full_mission = mission
    limit = destination_limit(policy)
    if len(dests) > limit:
        extra = ", ".join(d.name for d in dests[limit:])
        msgs.append(f"the planner handles at most {limit} destinations; not planned: {extra}")
        mission = Mission(mission.name, mission.vertiport, dests[:limit], mission.scenario, mission.battery,
                          mission.eod_v)
    slots = N_MAX if policy == "dqn" else max(N_MAX, len(mission.destinations))
    setup = PlanSetup(mission, full_mission, scenario, msgs, stats, legs=LegTable(mission, slots=slots))
    fail = takeoff_failure(mission.battery.q_max, mission.battery.r0, mission.eod_v)
    if fail is not None:
        setup.early = Plan(policy, messages=msgs + [fail], stats=stats)
    return setup


# ----------------------------------------------------------------------------- single flight


def safest_single_flight(legs: LegTable, alt_indices: Iterable[int], msgs: list[str],
                         stats: dict[str, Any]) -> tuple[list[str], list[float]]:
    """single_flight: the level (among ``alt_indices``) that flies a full cell to
    ``destinations[0]`` with the highest minimum voltage, as ``(route, altitudes_m)`` (empty if no
    level is safe); messages for what cannot be done, ``stats["min_voltage_by_altitude_v"]``."""
    m = legs.mission
    dest = m.destinations[0]
    q, r0, eod = m.battery.q_max, m.battery.r0, m.eod_v
    msgs.extend(filter(None, [single_flight_note(m)]))
    levels = [a for a in alt_indices if legs.feasible[legs.home, 0, a]]
    if not levels:
        msgs.append(too_close(legs, 0) or f"cannot reach {dest.name} at any altitude")
        return [], []
    best, ok, vmin = safest_level(legs, legs.home, 0, levels, full_charge(q).as_array()[0], q, r0, eod)
    stats["min_voltage_by_altitude_v"] = {ALTITUDES_M[a]: round(float(v), 4) for a, v in zip(levels, vmin)}
    if not ok.any():
        msgs.append(f"cannot reach {dest.name} at any altitude: the voltage falls below "
                    f"{eod:.2f} V at every level (best minimum {vmin.max():.3f} V)")
        return [], []
    return [dest.name], [ALTITUDES_M[best]]


def safest_level(legs: LegTable, src: int, dst: int, levels: list[int], state: np.ndarray, q_max: float,
                 r0: float, eod_v: float) -> tuple[int, np.ndarray, np.ndarray]:
    """Fly the leg ``src`` -> ``dst`` of ``legs`` at each of ``levels`` (indices into ``ALTITUDES_M``)
    from the battery ``state`` (8 values; q_max C, r0 ohm) and pick the level with the highest minimum
    voltage among those that stay at or above ``eod_v`` (V): ``(level, ok, min_voltage_v)`` per level
    (the first level where none is ok)."""
    currents = [legs.current(src, dst, a) for a in levels]
    ok, _, vmin = fly_batch(currents, np.repeat(np.asarray(state)[None, :], len(levels), axis=0), q_max, r0, eod_v)
    return levels[int(np.argmax(np.where(ok, vmin, -np.inf)))], ok, vmin


def single_flight_plan(setup: PlanSetup, policy: str, alt_indices: Iterable[int], t0: float) -> Plan:
    """The exact plan of a single_flight ``setup`` (:func:`safest_single_flight`: one leg, any
    number of destinations), labelled ``policy``; ``stats["exact"]`` True, ``stats["time_s"]`` since
    ``t0`` (:func:`time.perf_counter`, s)."""
    stats = setup.stats
    stats["exact"] = True
    route, alts = safest_single_flight(setup.legs, alt_indices, setup.messages, stats)
    stats["time_s"] = round(time.perf_counter() - t0, 4)
    return make_plan(setup.full_mission, policy, route, alts, setup.messages, stats)


__all__ = ["PlanSetup", "destination_limit", "fly_batch", "prepare_mission", "safest_level", "safest_single_flight",
           "single_flight_note", "single_flight_plan", "takeoff_failure", "too_close"]
