"""Two fixes of how Panel 1.9 and BokehJS 3.9 handle a served page's stylesheets.

**Stylesheets stay on this server** (:func:`keep_stylesheets_local`) when a hidden tab's panes change.

A ``pn.Tabs(dynamic=True)`` keeps the models of a tab that is not shown, detached from the page's
document. When a pane in such a tab changes (a plan comparison arriving while the Fly tab is
shown, say), Panel rebuilds the pane's properties for ``model.document``, which is then None. With
no document it takes Panel's CDN address as the place of its stylesheets and rewrites, in place,
the stylesheet objects that the session shares between all its models (``loading.css`` first):
from then on the page asks ``cdn.holoviz.org`` for them, which an offline classroom cannot reach.

:func:`keep_stylesheets_local` makes a detached model's properties resolve against the document
being served (``pn.state.curdoc``, the document of that very session) instead. Outside a server
session ``pn.state.curdoc`` is None and Panel's behaviour is unchanged.

**A figure's paint restyles the page once** (:func:`paint_without_restyling`), not once per part. At every
paint BokehJS 3.9 writes each part's position (axes, grids, title, glyphs) into that part's own ``<style>``
element, whether or not it moved, and then reads each part's colours from the browser's computed style. A
``<style>`` element written, even with the text it had, makes the browser compute the page's style again at
the next read: 6-9 times per paint of a Fly figure, 7-13 ms of each figure's 12-20 ms paint on a 2-core
machine (chromium, in-page timing; ``benchmarks/RESULTS.md``, "A figure's paint restyles the page once"). The
fix, run in the page once the document is ready, writes a BokehJS inline stylesheet only when its text
changes; a paint that moves nothing then costs 2.5-4 ms. Its cost: the Battery lab's changes, made back to back,
reach the page about 35 ms later at the median (the same entry).
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


# Run in the browser (a CustomJS of the document's ``document_ready``): BokehJS's inline stylesheets keep their
# text when asked to write the same text again. ``window.Bokeh.require`` is BokehJS's module loader; on a BokehJS
# without ``core/dom``'s InlineStyleSheet this does nothing (tests/test_app_browser.py checks it is installed).
SAME_TEXT_KEPT_JS = """
const dom = window.Bokeh && window.Bokeh.require ? window.Bokeh.require("core/dom") : null
const sheet = dom && dom.InlineStyleSheet ? dom.InlineStyleSheet.prototype : null
if (sheet != null && typeof sheet._update === "function" && !sheet._uam_same_text_kept) {
  const write = sheet._update
  sheet._update = function (css) {
    if (this.el.textContent !== css)
      write.call(this, css)
  }
  sheet._uam_same_text_kept = true
}
"""


def paint_without_restyling(doc: Any) -> None:
    """Install the paint fix in the page of ``doc`` (a Bokeh document being served) when it is ready; None:
    nothing (Jupyter, plain Python)."""
    if doc is None:
        return
    from bokeh.models import CustomJS

    doc.js_on_event("document_ready", CustomJS(code=SAME_TEXT_KEPT_JS))
