"""What the solvers share: the planners' preamble (:func:`prepare_mission` -> :class:`PlanSetup`:
validate, pick the scenario, cap at the policy's number of destinations, build the
:class:`~uam_studio.planning.episode.Episode`, stop early if the cell cannot finish the take-off) and
the exact answer of a single flight (:func:`safest_single_flight`, :func:`single_flight_plan`,
:func:`safest_level`, also used by :mod:`~uam_studio.planning.operations`).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from uam_studio.battery.parameters import Cell, CellParameters
from uam_studio.errors import InputError
from uam_studio.planning.episode import Episode
from uam_studio.planning.legs import ALTITUDES_M, MIN_LEG_KM, N_MAX, LegTable, fly_takeoff
from uam_studio.planning.missions.check import Plan, make_plan
from uam_studio.planning.missions.mission import MAX_DESTINATIONS, Mission, as_mission
from uam_studio.planning.missions.scenario import check_scenario
from uam_studio.planning.planners import PLANNERS

# ----------------------------------------------------------------------------- planner preamble


def _as_mission(mission: Any) -> tuple[Mission | None, list[str]]:
    try:
        return as_mission(mission), []
    except InputError as err:
        return None, [f"invalid mission: {err}"]


def takeoff_failure(cell: Cell) -> str | None:
    """A message if a fresh ``cell`` cannot finish the take-off and climb to 500 m above its cut-off
    (:func:`fly_takeoff`), else None."""
    res = fly_takeoff(cell)
    if not res.eod_reached:
        return None
    return (f"the battery cannot finish takeoff: the voltage falls below {cell.eod_v:.2f} V after "
            f"{res.eod_s:.0f} s of the {res.time_s.size} s take-off and climb to 500 m "
            f"(q_max {cell.q_max:.0f} C, R0 {cell.r0:.3f} ohm)")


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
    scenario, messages, stats and the episode (its leg table has ``max(N_MAX, destinations)`` slots;
    N_MAX for the DQN; its cell is the mission's); ``early`` is a finished :class:`Plan` when there is
    nothing to plan."""

    mission: Mission | None
    full_mission: Mission | None
    scenario: str | None
    messages: list[str]
    stats: dict[str, Any]
    episode: Episode | None = None
    early: Plan | None = None

    @property
    def legs(self) -> LegTable | None:
        """The episode's leg table."""
        return None if self.episode is None else self.episode.legs


def destination_limit(policy: str) -> int:
    """The most destinations ``policy`` plans (:data:`~uam_studio.planning.planners.PLANNERS`: N_MAX (8)
    for the paper's DQN, its action space; MAX_DESTINATIONS (20) for the others and for a name not there)."""
    info = PLANNERS.get(policy)
    return MAX_DESTINATIONS if info is None else info.max_destinations


def prepare_mission(mission: Any, scenario: str | None, policy: str,
                    params: CellParameters | None = None) -> PlanSetup:
    """The planners' shared preamble: validate the mission, pick the scenario, keep at most
    :func:`destination_limit` destinations (the rest get a message), build the leg table and stop
    early if the battery cannot finish takeoff. ``params``: the parameter set flown (default: the mission's,
    :attr:`~uam_studio.planning.missions.mission.Mission.cell`); a reference that knows a pack's own set passes
    it."""
    mission, msgs = _as_mission(mission)
    if mission is None:
        return PlanSetup(None, None, scenario, msgs, {}, early=Plan(policy, messages=tuple(msgs)))
    scenario = scenario or mission.scenario
    try:
        check_scenario(scenario)
    except InputError as err:
        return PlanSetup(mission, mission, scenario, msgs, {}, early=Plan(policy, messages=(str(err),)))
    stats: dict[str, Any] = {"scenario": scenario}
    dests = mission.destinations
    if not dests:
        return PlanSetup(mission, mission, scenario, msgs, stats,
                         early=Plan(policy, messages=("the mission has no destinations",), stats=stats))
    full_mission = mission
    limit = destination_limit(policy)
    if len(dests) > limit:
        extra = ", ".join(d.name for d in dests[limit:])
        msgs.append(f"the planner handles at most {limit} destinations; not planned: {extra}")
        mission = Mission(mission.name, mission.vertiport, dests[:limit], mission.scenario, mission.battery,
                          mission.eod_v)
    info = PLANNERS.get(policy)
    slots = N_MAX if info is not None and info.fixed_slots else max(N_MAX, len(mission.destinations))
    cell = None if params is None else dataclasses.replace(mission.cell, params=params)
    episode = Episode.of(LegTable(mission, slots=slots), scenario, cell)
    setup = PlanSetup(mission, full_mission, scenario, msgs, stats, episode=episode)
    fail = takeoff_failure(episode.cell)
    if fail is not None:
        setup.early = Plan(policy, messages=(*msgs, fail), stats=stats)
    return setup


# ----------------------------------------------------------------------------- single flight


def safest_single_flight(episode: Episode, alt_indices: Iterable[int], msgs: list[str],
                         stats: dict[str, Any]) -> tuple[list[str], list[float]]:
    """single_flight: the level (among ``alt_indices``) that flies the episode's fresh cell to
    ``destinations[0]`` with the highest minimum voltage, as ``(route, altitudes_m)`` (empty if no
    level is safe); messages for what cannot be done, ``stats["min_voltage_by_altitude_v"]``."""
    legs = episode.legs
    m = legs.mission
    dest = m.destinations[0]
    msgs.extend(filter(None, [single_flight_note(m)]))
    levels = [a for a in alt_indices if legs.feasible[legs.home, 0, a]]
    if not levels:
        msgs.append(too_close(legs, 0) or f"cannot reach {dest.name} at any altitude")
        return [], []
    best, ok, vmin = safest_level(episode, legs.home, 0, levels, episode.fresh())
    stats["min_voltage_by_altitude_v"] = {ALTITUDES_M[a]: round(float(v), 4) for a, v in zip(levels, vmin)}
    if not ok.any():
        msgs.append(f"cannot reach {dest.name} at any altitude: the voltage falls below "
                    f"{episode.cell.eod_v:.2f} V at every level (best minimum {vmin.max():.3f} V)")
        return [], []
    return [dest.name], [ALTITUDES_M[best]]


def safest_level(episode: Episode, src: int, dst: int, levels: list[int], state: np.ndarray
                 ) -> tuple[int, np.ndarray, np.ndarray]:
    """Fly the leg ``src`` -> ``dst`` of the episode at each of ``levels`` (indices into ``ALTITUDES_M``)
    from the battery ``state`` (8 values) on the episode's cell and pick the level with the highest
    minimum voltage among those that stay at or above its cut-off: ``(level, ok, min_voltage_v)`` per
    level (the first level where none is ok)."""
    ok, _, vmin = episode.fly([(src, dst, a) for a in levels], state)
    return levels[int(np.argmax(np.where(ok, vmin, -np.inf)))], ok, vmin


def single_flight_plan(setup: PlanSetup, policy: str, alt_indices: Iterable[int], t0: float) -> Plan:
    """The exact plan of a single_flight ``setup`` (:func:`safest_single_flight`: one leg, any
    number of destinations), labelled ``policy``; ``stats["exact"]`` True, ``stats["time_s"]`` since
    ``t0`` (:func:`time.perf_counter`, s)."""
    assert setup.episode is not None and setup.full_mission is not None  # a setup with no early plan
    stats = setup.stats
    stats["exact"] = True
    route, alts = safest_single_flight(setup.episode, alt_indices, setup.messages, stats)
    stats["time_s"] = round(time.perf_counter() - t0, 4)
    return make_plan(setup.full_mission, policy, route, alts, setup.messages, stats)


__all__ = ["PlanSetup", "destination_limit", "prepare_mission", "safest_level", "safest_single_flight",
           "single_flight_note", "single_flight_plan", "takeoff_failure", "too_close"]
