"""Mission planning: missions and their JSON format, route simulation, the environment, planners and agents.

Rooms (each imports only the ones below it; import-linter contract in pyproject.toml)::

    planner.py     plan_mission: the one entry point of the CLI and the app
    safety.py      a plan's safety verdict by source, a failed take-off
    operations/    flying a mission in real time (world, operator, flight loop)
    agents/        the attention planner, DQN networks, training, agent files, retraining, rollout
                   (the only torch users)
    env/           the Gymnasium environment and its battery backends
    solvers/       the exact oracle, the OR-Tools reference, the greedy baseline and their shared setup
    missions/      mission format, generation, route simulation, plan checks
    legs.py        the discrete action space and the leg table of a mission

Public API: :class:`Mission` (with :class:`Vertiport`, :class:`Destination`,
:class:`Battery`), :func:`mission_from_dict`, :func:`mission_from_json`, :func:`mission_to_dict`,
:func:`load_mission`, :func:`save_mission`, :func:`simulate_route`
(-> :class:`RouteSimulation` with :class:`LegResult` per leg).

Planning: the action space (:mod:`~uam_studio.planning.legs`: ``N_MAX``, ``ALTITUDES_M``,
``N_ACTIONS``, :func:`encode_action`, :func:`decode_action`), the Gymnasium environment
:class:`UAMPlanningEnv` (:func:`make_env`), random and held-out missions
(:func:`random_mission`, :func:`held_out_missions`), planners returning a :class:`Plan`
(:func:`attention_plan`, the learned default, 1-20 destinations; :func:`oracle_plan`, exact up to 8,
:func:`reference_plan` beyond; :func:`greedy_plan`, baseline), the physics check
:func:`check_plan` (-> :class:`PlanCheck`) and the one entry point of the CLI and the app,
:func:`plan_mission` (any of :data:`POLICIES`, each described in :data:`PLANNERS`, checked on physics, with the
Dynaformer's prediction and its voltage band; -> :class:`PlanResult`), its :func:`safety_verdict` by source,
and flying a mission with surprises, :func:`fly_mission`.

``env``, ``solvers``, ``agents``, ``planner``, ``safety`` and ``operations`` are imported lazily (attribute access), so
``import uam_studio.planning`` stays light (no gymnasium, no torch).
"""

from uam_studio.lazy_exports import lazy_getattr
from uam_studio.planning.legs import ALTITUDES_M, N_ACTIONS, N_MAX, decode_action, encode_action
from uam_studio.planning.missions.check import Plan, PlanCheck, check_plan, make_plan
from uam_studio.planning.missions.generate import held_out_missions, random_mission
from uam_studio.planning.missions.mission import (
    COORD_RANGE_KM,
    MAX_DESTINATIONS,
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

_LAZY = {
    "UAMPlanningEnv": "env",
    "make_env": "env",
    "oracle_plan": "solvers.oracle",
    "greedy_plan": "solvers.greedy",
    "reference_plan": "solvers.reference",
    "plan_mission": "planner",
    "PlanResult": "planner",
    "plan_csv": "planner",
    "POLICIES": "planners",
    "PLANNERS": "planners",
    "PlannerInfo": "planners",
    "planner_info": "planners",
    "attention_plan": "agents.attention.decode",
    "safety_verdict": "safety",
    "fly_mission": "operations",
}

__getattr__ = lazy_getattr(__name__, {name: f"uam_studio.planning.{module}" for name, module in _LAZY.items()})


__all__ = [
    "fly_mission",
    "safety_verdict",
    "ALTITUDES_M",
    "N_ACTIONS",
    "N_MAX",
    "Plan",
    "PlanCheck",
    "UAMPlanningEnv",
    "check_plan",
    "decode_action",
    "encode_action",
    "greedy_plan",
    "reference_plan",
    "plan_mission",
    "PlanResult",
    "plan_csv",
    "POLICIES",
    "PLANNERS",
    "PlannerInfo",
    "planner_info",
    "attention_plan",
    "MAX_DESTINATIONS",
    "as_mission",
    "held_out_missions",
    "make_env",
    "make_plan",
    "oracle_plan",
    "random_mission",
    "COORD_RANGE_KM",
    "SCENARIOS",
    "VERTIPORT",
    "Battery",
    "Destination",
    "LegResult",
    "Mission",
    "RouteSimulation",
    "Vertiport",
    "load_mission",
    "mission_from_dict",
    "mission_from_json",
    "mission_to_dict",
    "save_mission",
    "simulate_route",
]
