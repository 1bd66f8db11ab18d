"""uam_studio: health-aware mission planning for battery-powered eVTOL aircraft.

Layers (each imports only those above it in this list):
``flight`` (leg -> per-cell current), ``battery`` (current -> voltage, EOD),
``dynaformer`` (learned battery model), ``planning`` (missions, environments,
agents, oracle, plan checks), ``app`` (Panel views), ``cli``.

Importing the package registers the planning environment's gymnasium ids
(:data:`uam_studio.registration.ENV_IDS`, e.g. ``"uam_studio/SingleCharge-v0"``).
"""

from uam_studio.registration import register_envs as _register_envs

__version__ = "0.1.0"

_register_envs()
