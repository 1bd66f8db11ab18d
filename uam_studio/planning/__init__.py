"""Mission planning: missions and their JSON format, and route simulation.

Public API: :class:`Mission` (with :class:`Vertiport`, :class:`Destination`,
:class:`Battery`), :func:`mission_from_dict`, :func:`mission_to_dict`,
:func:`load_mission`, :func:`save_mission`, :func:`simulate_route`
(-> :class:`RouteSimulation` with :class:`LegResult` per leg).
"""

from uam_studio.planning.mission import (
    COORD_RANGE_KM,
    SCENARIOS,
    VERTIPORT,
    Battery,
    Destination,
    Mission,
    Vertiport,
    load_mission,
    mission_from_dict,
    mission_to_dict,
    save_mission,
)
from uam_studio.planning.route import LegResult, RouteSimulation, simulate_route

__all__ = [
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
    "mission_to_dict",
    "save_mission",
    "simulate_route",
]
