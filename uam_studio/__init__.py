"""uam_studio: health-aware mission planning for battery-powered eVTOL aircraft.

Layers (each imports only those above it in this list; ``lint-imports`` checks it):
``errors`` and ``lazy_exports``, ``atomic_io``, then ``bundled`` / ``tensor_files`` / ``registration`` / ``engine``
(Dask tasks); ``flight`` (leg -> per-cell current), ``battery`` (current -> voltage, EOD; health
fits; real cells' loaders), ``dynaformer`` (learned battery model), ``planning`` (missions,
environments, agents, oracle, real-time flight), ``fleet`` (packs that age, dispatchers, a fleet's
day), then ``app`` (the Panel app), ``classroom`` (notebook helpers) and ``studies`` (experiments),
and ``cli`` on top.

Importing the package registers the planning environment's gymnasium ids
(:data:`uam_studio.registration.ENV_IDS`, e.g. ``"uam_studio/SingleCharge-v0"``).

The front door: the names of the main jobs, imported when first used (the README's example runs them):
simulate a cell (:func:`simulate`), fit its health (:func:`fit_health`), load, plan and fly a mission
(:func:`load_mission`, :func:`plan_mission`, :func:`fly_mission`) with a pack's logbook (:class:`Logbook`,
:func:`simulate_logbook`), run a fleet's day (:class:`Fleet`,
:func:`poisson_demand`, :func:`simulate_day`), and predict a real NASA discharge's end
(:func:`load_nasa_folder`, :func:`replay_discharge`).
"""

from uam_studio.lazy_exports import lazy_getattr
from uam_studio.registration import register_envs as _register_envs

__version__ = "0.1.0"

_FRONT_DOOR = {
    "simulate": "uam_studio.battery",
    "fit_health": "uam_studio.battery",
    "load_mission": "uam_studio.planning",
    "plan_mission": "uam_studio.planning",
    "fly_mission": "uam_studio.planning",
    "Logbook": "uam_studio.battery.health.logbook",
    "simulate_logbook": "uam_studio.planning.operations.pack_history",
    "Fleet": "uam_studio.fleet.day",
    "simulate_day": "uam_studio.fleet.day",
    "poisson_demand": "uam_studio.fleet.demand",
    "load_nasa_folder": "uam_studio.battery.real.nasa_data",
    "replay_discharge": "uam_studio.battery.real.nasa_replay",
}

__all__ = sorted(_FRONT_DOOR)

__getattr__ = lazy_getattr(__name__, _FRONT_DOOR)


_register_envs()
