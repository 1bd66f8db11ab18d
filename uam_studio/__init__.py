"""uam_studio: health-aware mission planning for battery-powered eVTOL aircraft.

Layers (each imports only those above it in this list):
``flight`` (leg -> per-cell current), ``battery`` (current -> voltage, EOD),
``dynaformer`` (learned battery model), ``planning`` (missions, environments,
agents, oracle, plan checks), ``app`` (Panel views), ``cli``.
"""

__version__ = "0.1.0"
