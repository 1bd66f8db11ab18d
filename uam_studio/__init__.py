"""uam_studio: health-aware mission planning for battery-powered eVTOL aircraft.

Layers (each imports only those above it in this list; ``lint-imports`` checks it):
``errors``, ``atomic_io``, then ``bundled`` / ``tensor_files`` / ``registration`` / ``engine``
(Dask tasks); ``flight`` (leg -> per-cell current), ``battery`` (current -> voltage, EOD; health
fits; real cells' loaders), ``dynaformer`` (learned battery model), ``planning`` (missions,
environments, agents, oracle, real-time flight), ``fleet`` (packs that age, dispatchers, a fleet's
day), then ``app`` (the Panel app), ``classroom`` (notebook helpers) and ``studies`` (experiments),
and ``cli`` on top.

Importing the package registers the planning environment's gymnasium ids
(:data:`uam_studio.registration.ENV_IDS`, e.g. ``"uam_studio/SingleCharge-v0"``).
"""

from uam_studio.registration import register_envs as _register_envs

__version__ = "0.1.0"

_register_envs()
