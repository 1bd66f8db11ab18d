"""Missions: the JSON format (:mod:`.mission`), random and held-out missions (:mod:`.generate`),
route simulation with the physics model (:mod:`.route`) and the physics check of a plan
(:mod:`.check`: :class:`Plan`, :class:`PlanCheck`, :func:`make_plan`, :func:`check_plan`).

The lowest room of :mod:`uam_studio.planning` after :mod:`~uam_studio.planning.legs`: it imports no
environment, solver or agent.
"""

from uam_studio.planning.missions.check import Plan, PlanCheck, check_plan, make_plan
from uam_studio.planning.missions.generate import held_out_missions, random_mission
from uam_studio.planning.missions.mission import (
    COORD_RANGE_KM,
    SCENARIOS,
    VERTIPORT,
    Battery,
    Destination,
    Mission,
    Vertiport,
    as_mission,
    load_mission,
    mission_from_dict,
    mission_from_json,
    mission_to_dict,
    save_mission,
)
from uam_studio.planning.missions.route import LegResult, RouteSimulation, simulate_route

__all__ = [
    "COORD_RANGE_KM", "SCENARIOS", "VERTIPORT", "Battery", "Destination", "LegResult", "Mission", "Plan",
    "PlanCheck", "RouteSimulation", "Vertiport", "as_mission", "check_plan", "held_out_missions", "load_mission",
    "make_plan", "mission_from_dict", "mission_from_json", "mission_to_dict", "random_mission",
    "save_mission", "simulate_route",
]
