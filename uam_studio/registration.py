"""Gymnasium ids of the planning environment, registered by ``import uam_studio``.

    import gymnasium, uam_studio
    env = gymnasium.make("uam_studio/SingleCharge-v0", render_mode="ansi")

Each id is :class:`~uam_studio.planning.env.UAMPlanningEnv` on random missions of one scenario;
keyword arguments of ``gymnasium.make`` go to its constructor (e.g. ``mission=``, ``alpha=``). The
entry points are strings, so registering imports neither the environment nor the physics.
"""

from __future__ import annotations

ENTRY_POINT = "uam_studio.planning.env:UAMPlanningEnv"
ENV_IDS: dict[str, str] = {
    "uam_studio/SingleFlight-v0": "single_flight",
    "uam_studio/SingleCharge-v0": "single_charge",
    "uam_studio/MultiCharge-v0": "multi_charge",
}
"""Gymnasium id -> the environment's ``scenario``."""

__all__ = ["ENTRY_POINT", "ENV_IDS", "register_envs"]


def register_envs() -> None:
    """Register :data:`ENV_IDS` with gymnasium (ids already registered are left as they are)."""
    import gymnasium

    for env_id, scenario in ENV_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=ENTRY_POINT, kwargs={"scenario": scenario})
