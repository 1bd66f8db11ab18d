"""Where a session runs: served (a Bokeh document with a server session) or not (Jupyter, tests)."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any, cast

import panel as pn
from bokeh.document import Document


def in_server_session() -> bool:
    """True while building a session of a Panel/Bokeh server (not in Jupyter or plain Python)."""
    doc = pn.state.curdoc
    return doc is not None and doc.session_context is not None


def ensure_bokeh_backend() -> None:
    """Load HoloViews' Bokeh plotting backend (no notebook output), so that views can be built
    anywhere: in a served session, in Jupyter, in tests and benchmarks."""
    import holoviews as hv

    if "bokeh" not in hv.Store.renderers:
        hv.renderer("bokeh")
    # importing holoviews.plotting.bokeh alone makes bokeh the current backend without building the
    # ``hv.opts`` builders (hv.opts.Overlay...); switching to it again builds them
    if hv.Store.current_backend != "bokeh" or not hasattr(hv.opts, "Overlay"):
        hv.Store.set_current_backend("bokeh")


def configure_server_threads() -> None:
    """One torch thread per call in the server process.

    The sessions, the planning pool and any retraining share the machine's cores. With torch's
    default intra-op threads, a Dynaformer prediction on a busy machine waits on threads spinning
    against each other (many times its single-thread time; the app is measured with one torch thread,
    ``benchmarks/RESULTS.md``, "App (python benchmarks/bench_app.py all"), so the served
    app runs torch single-threaded and gets its parallelism from the sessions instead.
    """
    import torch

    if torch.get_num_threads() != 1:
        torch.set_num_threads(1)


def session_dispatcher(delay_ms: int = 0) -> Callable[[Callable[[], None]], None] | None:
    """A function that runs a callback on this session's event loop with the document lock held
    (``doc.add_next_tick_callback``, or ``doc.add_timeout_callback`` after ``delay_ms``; safe to
    call from any thread), or None outside a server session.

    Worker threads (planning, training) hand their results back through it, so every change to
    widgets, panes and plots happens on the session's own thread, and a callback's changes reach the browser as
    one batch (``pn.io.hold``: each batch costs the browser a page layout). A delay lets the event loop send
    the changes made so far to the browser first.
    """
    if not in_server_session():
        return None
    from panel.io.state import set_curdoc

    doc = cast(Document, pn.state.curdoc)  # in_server_session() has just found this session's document

    def dispatch(cb: Callable[[], None]) -> None:
        def run() -> None:
            with set_curdoc(doc), pn.io.hold(doc):  # the result's changes reach the browser as one batch
                cb()

        try:
            if delay_ms > 0:
                doc.add_timeout_callback(run, delay_ms)
            else:
                doc.add_next_tick_callback(run)
        except Exception:  # the session has gone: nothing to update
            pass

    return dispatch


def after_page(items: Sequence[tuple[Any, dict[str, Any]]]) -> list[Any]:
    """Slots that show each ``(item, slot_params)``'s item once a served page is drawn, all in one change.

    Served, each slot is an empty ``pn.Column(**slot_params)`` with Panel's loading mark; when the browser
    says the page is drawn (``pn.state.onload``) every slot gets its item in one frozen update of the
    document, so Bokeh collects the document's models once for all of them (one deferred pane each,
    ``defer_load``, costs that walk once per pane: about 15 ms a pane on a 2-core laptop with 30 pages
    loading; ``bench_classroom.py``). Outside a server session: the items themselves, shown at once.
    """
    if not in_server_session():
        return [item for item, _ in items]
    slots = [pn.Column(loading=True, **params) for _, params in items]

    def fill() -> None:
        doc = cast(Document, pn.state.curdoc)
        with doc.models.freeze():
            for slot, (item, _) in zip(slots, items, strict=True):
                slot.param.update(objects=[item], loading=False)

    pn.state.onload(fill)
    return slots


def respond_at_once(widgets: Iterable[pn.widgets.Widget]) -> None:
    """Handle a browser change of these widgets' ``value`` on the session's next tick.

    Panel waits 50 ms after a change from the browser before it handles it, to gather related
    changes into one event (``Syncable._debounce``, for every property not listed in the widget's
    ``_priority_changes``). The app's states keep only the newest request of a burst of changes
    anyway (:class:`~uam_studio.app.services.LatestWorker`), so for their inputs the wait is only
    latency: a fifth of a slider step's time to the new plan on a 2-core laptop.
    """
    for wd in widgets:
        prop = value_property(wd)
        if prop is not None and prop not in wd._priority_changes:
            # this widget only (a class list; Panel types it a ClassVar, so mypy forbids the instance's own)
            wd._priority_changes = [*wd._priority_changes, prop]  # type: ignore[misc]


def value_property(widget: pn.widgets.Widget) -> str | None:
    """The Bokeh property that carries ``widget.value`` to and from the browser (``active`` for a
    radio-button group), or None if it has none."""
    return widget._rename.get("value", "value")
