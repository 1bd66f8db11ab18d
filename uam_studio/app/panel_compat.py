"""Keeps a served page's stylesheets on this server when a hidden tab's panes change (Panel 1.9).

A ``pn.Tabs(dynamic=True)`` keeps the models of a tab that is not shown, detached from the page's
document. When a pane in such a tab changes (a plan comparison arriving while the Fly tab is
shown, say), Panel rebuilds the pane's properties for ``model.document``, which is then None. With
no document it takes Panel's CDN address as the place of its stylesheets and rewrites, in place,
the stylesheet objects that the session shares between all its models (``loading.css`` first):
from then on the page asks ``cdn.holoviz.org`` for them, which an offline classroom cannot reach.

:func:`keep_stylesheets_local` makes a detached model's properties resolve against the document
being served (``pn.state.curdoc``, the document of that very session) instead. Outside a server
session ``pn.state.curdoc`` is None and Panel's behaviour is unchanged.
"""

from __future__ import annotations

import functools
from typing import Any


def keep_stylesheets_local() -> None:
    """Install the fix on ``panel.reactive.Reactive`` (once per process; further calls do nothing)."""
    from panel.io.state import state
    from panel.reactive import Reactive

    original = Reactive._get_properties
    if getattr(original, "_resolves_detached_models", False):
        return

    @functools.wraps(original)
    def _get_properties(self: Any, doc: Any, *args: Any, **kwargs: Any) -> dict[str, Any]:
        return original(self, doc if doc is not None else state.curdoc, *args, **kwargs)

    _get_properties._resolves_detached_models = True  # type: ignore[attr-defined]
    Reactive._get_properties = _get_properties  # type: ignore[method-assign]  # the patch itself
