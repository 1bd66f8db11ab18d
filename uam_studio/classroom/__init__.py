"""Helpers for the classroom notebooks (``notebooks/``): the fast-mode switch and shared figures.

Public API: :func:`fast_mode`, :func:`pick`, :data:`FAST_ENV_VAR`, :func:`asset_path` (this module, no heavy
imports);
holoviews figures in :mod:`uam_studio.classroom.plots` (imports holoviews).

Layer: beside the app, on top of the library. Nothing in ``flight``, ``battery``, ``dynaformer``
or ``planning`` imports it.
"""

from uam_studio.classroom.mode import FAST_ENV_VAR, REPO_ROOT, asset_path, fast_mode, pick

__all__ = ["FAST_ENV_VAR", "REPO_ROOT", "asset_path", "fast_mode", "pick"]
