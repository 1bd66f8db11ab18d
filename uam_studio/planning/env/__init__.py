"""The Gymnasium environment (:mod:`.environment`: :class:`UAMPlanningEnv`, :func:`make_env`; the
observation layout in :mod:`.observation`; the queries on an episode that leave it unchanged in
:mod:`.queries`) and its battery backends with the take-off health observation (:mod:`.backends`).
"""

from uam_studio.planning.env.backends import (
    CONTEXT_S,
    HEALTH_CLIP,
    BatteryBackend,
    DynaformerBattery,
    LegOutcome,
    PhysicsBattery,
    fallback_health,
    observe_takeoff,
    takeoff_context_current,
    takeoff_health,
)
from uam_studio.planning.env.environment import (
    FEATURE_NAMES,
    MAX_EPISODE_STEPS,
    N_FEATURES,
    OBS_DIM,
    UAMPlanningEnv,
    make_env,
)

__all__ = [
    "CONTEXT_S", "FEATURE_NAMES", "HEALTH_CLIP", "MAX_EPISODE_STEPS", "N_FEATURES", "OBS_DIM", "BatteryBackend",
    "DynaformerBattery", "LegOutcome", "PhysicsBattery", "UAMPlanningEnv", "fallback_health", "make_env",
    "observe_takeoff", "takeoff_context_current", "takeoff_health",
]
