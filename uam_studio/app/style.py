"""Small shared pieces of the views' look: section headings, note text, Bokeh hooks of the plots, and the check
that plot data changed."""

from __future__ import annotations

import html
from typing import Any

import numpy as np
import panel as pn

NOTE_STYLE = {"font-size": "12px", "color": "#555"}
# The voltage figures' colours, the same in every tab: what the physics model (the true cell) does,
# what the learned model or the operator predicts, what the sensor measures.
PHYSICS_COLOR = "#1f77b4"
PREDICTED_COLOR = "#ff7f0e"
MEASURED_COLOR = "#333333"
NAME_OFFSET_PX = 10  # map names sit this many screen pixels above their place (the vertiport's below it)


def draw_on_canvas() -> None:
    """Make every HoloViews figure of this process draw on a 2D canvas, not with WebGL.

    HoloViews' Bokeh renderer asks for WebGL by default, and a browser without a GPU (software GL: CI, school
    VMs, remote desktops, acceleration turned off) then draws the axes and legend but none of the lines
    and markers. The app's curves are a few thousand points, which the canvas draws at once. The plain
    Bokeh figures (Planner, Fly) use Bokeh's own default, the canvas. Called by
    :func:`~uam_studio.app.main.create_app` before it builds a session.
    """
    import holoviews as hv

    type(hv.renderer("bokeh")).webgl = False  # the class default: every renderer instance, then and later


def heading(text: str, **params: Any) -> pn.pane.HTML:
    """A section heading of one fixed size (a Markdown ``####`` renders at different sizes in the
    first tab and in tabs built later)."""
    params.setdefault("margin", (4, 10, 2, 10))
    return pn.pane.HTML(f"<div style='font-size:15px;font-weight:600'>{html.escape(text)}</div>", **params)


BUSY_HEIGHT_PX = 22
BUSY_CSS = """
.uam-busy { display: flex; align-items: center; gap: 6px; font-size: 12px; color: #555; height: 22px; }
.uam-busy-ring { width: 14px; height: 14px; border: 2px solid #c8d3e0; border-top-color: #1f4e79;
                 border-radius: 50%; animation: uam-spin 0.8s linear infinite; }
@keyframes uam-spin { to { transform: rotate(360deg); } }
"""


def busy_html(busy: bool, label: str = "planning...") -> str:
    """A busy mark's content: a turning ring and ``label`` while busy, else empty (``data-busy`` says which)."""
    body = f"<span class='uam-busy-ring'></span>{html.escape(label)}" if busy else ""
    return f"<div class='uam-busy' data-busy='{str(busy).lower()}'>{body}</div>"


def busy_mark(busy: bool, width_px: int, label: str = "planning...") -> pn.pane.HTML:
    """A fixed-size pane for :func:`busy_html`: showing or hiding the mark changes its content only, never its
    size or visibility, so the browser does not lay the page out again (a spinner made visible and hidden
    cost about 300 ms a step on a 2-core laptop; ``bench_app.py steps``)."""
    return pn.pane.HTML(busy_html(busy, label), width=width_px, height=BUSY_HEIGHT_PX, margin=(0, 5),
                        stylesheets=[BUSY_CSS])


def intro(text: str) -> pn.pane.Markdown:
    """A tab's introduction: Markdown at one size across the tabs, the tab's whole width."""
    return pn.pane.Markdown(text, sizing_mode="stretch_width", styles={"font-size": "13px"})


def window_height(obj: Any, height_css: str) -> pn.Column:
    """``obj`` (sized ``stretch_both``) in a full-width box whose height is the CSS ``height_css``, e.g.
    a share of the window's height (``100vh``) with a floor: Bokeh sizes a figure or table only from a
    box of definite height."""
    return pn.Column(obj, sizing_mode="stretch_width", styles={"height": height_css})


def no_scroll_zoom(plot: Any, element: Any) -> None:
    """Bokeh hook: the mouse wheel scrolls the page, not the plot (the zoom stays in the toolbar)."""
    plot.state.toolbar.active_scroll = None


PAGE_TOOLS = "pan,wheel_zoom,box_zoom,save,reset"


def page_figure(**kwargs: Any) -> Any:
    """A Bokeh figure with the app's tools whose mouse wheel scrolls the page, not the plot (the zoom
    stays in the toolbar): the Bokeh-figure twin of :func:`no_scroll_zoom`. ``kwargs`` go to
    :func:`bokeh.plotting.figure`."""
    from bokeh.plotting import figure

    fig = figure(tools=PAGE_TOOLS, **kwargs)
    fig.toolbar.active_scroll = None
    return fig


def derived_looks(fig: Any) -> Any:
    """``fig`` with each glyph renderer's non-selected and muted looks left for BokehJS to derive from its
    glyph (``"auto"``: the glyph with its fill at alpha 0.2, its line as it is), where
    :mod:`bokeh.plotting`'s glyph methods build both as models of their own: two models fewer per
    renderer for the server to build, track and send with every new page. Call it once the figure's
    glyphs are drawn."""
    from bokeh.models.renderers import GlyphRenderer

    for r in fig.renderers:
        if isinstance(r, GlyphRenderer):
            r.nonselection_glyph = "auto"
            r.muted_glyph = "auto"
    return fig


def legend_above(fig: Any) -> None:
    """Move the legend that ``fig``'s ``legend_label`` glyphs made above the plot, in one row, without
    the empty band Bokeh leaves around it."""
    fig.add_layout(fig.legend[0], "above")
    fig.legend.orientation, fig.legend.margin, fig.legend.padding = "horizontal", 0, 4


def same_plot_data(a: Any, b: Any) -> bool:
    """Deep equality of plot data (dicts, lists, tuples, arrays, numbers): a view sets a Bokeh source or draws a
    figure only when its data changed, as Bokeh sends every set of a document's source to the browser, equal or not."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same_plot_data(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple, np.ndarray)) and isinstance(b, (list, tuple, np.ndarray)):
        if len(a) != len(b):
            return False
        if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
            x, y = np.asarray(a), np.asarray(b)
            return x.shape == y.shape and x.dtype == y.dtype and bool(np.array_equal(x, y))
        return all(same_plot_data(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and a == b
