"""The Battery lab's real NASA cell: one real discharge of the paper's cell type, predicted as an operator
would have, against what happened.

:class:`NasaLabState` holds the cell and the discharge (a position over its life) and its :attr:`result`,
a :class:`~uam_studio.battery.real.nasa_replay.NasaReplay` (or a one-line error); :class:`NasaLabView` draws
it: the measured voltage, the end of the context, the prediction's median, 90% band and 5%-risk bound,
the persistence guess, progpy's default model along the same current, and a sentence on what happened.
Without the data, one line says where to put it.
"""

from __future__ import annotations

import html
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

import holoviews as hv
import numpy as np
import panel as pn
import param

from uam_studio.app.services import LatestWorker, one_line
from uam_studio.app.session import ensure_bokeh_backend
from uam_studio.app.style import heading, no_scroll_zoom, window_height
from uam_studio.battery.real.nasa_data import (
    DATA_ENV,
    NasaCell,
    NasaDataError,
    nasa_cell_files,
    nasa_folder,
)
from uam_studio.battery.real.places import sample_note
from uam_studio.errors import InputError

__all__ = ["NASA_COLORS", "NasaLabState", "NasaLabView"]

NASA_COLORS = {"measured": "#222222", "predicted": "#1f77b4", "bound": "#ff7f0e", "persistence": "#2ca02c",
               "progpy": "#9467bd", "EOD": "#d62728", "context": "#8c8c8c"}
METHODS = {"history": "the cell's own history at this load",
           "prior": "no history at this load and ambient: the training cells' charge, a wide interval"}
FIRST_POSITION = 84  # the discharge shown first: mid-life of B0005, where the cell's history speaks
PLOT_HEIGHT_CSS = "max(300px, calc((100vh - 230px) * 0.55))"


FIT_WORDS = {"loco": "fitted without this cell", "bundled": "bundled, never read this cell",
             "in-sample": "bundled, which read this cell (in-sample)", "given": "given"}


class NasaLabState(param.Parameterized):
    """One real discharge of a NASA PCoE cell, replayed (:func:`~uam_studio.battery.real.nasa_replay.replay_discharge`).

    ``cell`` is a file name stem in the data folder (:func:`~uam_studio.battery.real.nasa_data.nasa_folder`);
    ``position`` counts the cell's scoreable discharges from 0. :attr:`result` is ``{"replay": NasaReplay}``
    or ``{"error": one line}``; without the data, :attr:`missing` says where to put it.
    """

    cell: param.Selector[str | None] = param.Selector(default=None, objects=[], allow_None=True,
                                                      doc="the cell (file name stem)")
    position = param.Integer(default=0, bounds=(0, None), doc="the discharge, 0 = the cell's first")
    discharges = param.Integer(default=1, doc="how many scoreable discharges the cell has")
    context_s = param.Number(default=300.0, bounds=(60.0, 600.0), doc="voltage read before predicting (s)")
    result = param.Dict(default=None, allow_None=True)
    busy = param.Boolean(default=False)
    missing = param.String(default="", doc="one line: where the data should be, when they are not there")
    source = param.String(default="", doc="one line: the data shown are the bundled sample (empty otherwise)")

    def __init__(self, folder: str | None = None, background: bool = False,
                 dispatch: Callable[[Callable[[], None]], None] | None = None, **params: Any) -> None:
        super().__init__(**params)
        self.background = background
        self._cell: NasaCell | None = None  # the NasaCell shown, read once per cell
        self._worker: LatestWorker[tuple, dict[str, Any]] = LatestWorker(
            self._compute, self._apply, lambda _r, err: {"error": one_line(err)}, dispatch=dispatch)
        try:
            self.folder: Path | None = nasa_folder(folder)
            names = [f.name.split(".")[0] for f in nasa_cell_files(self.folder)]
            self.source = sample_note(self.folder) or ""
        except NasaDataError as err:
            self.folder, names = None, []
            self.missing = (f"No NASA PCoE data ({one_line(err)}): set ${DATA_ENV} to a folder of BXXXX.csv.gz "
                            "files (see `uam-studio data`).")
        self.param.cell.objects = names
        if names:
            with param.parameterized.discard_events(self):
                self.cell = "B0005" if "B0005" in names else names[0]
                self.position = FIRST_POSITION
        self.param.watch(lambda *_: self.refresh(), ["cell", "position", "context_s"])
        self.refresh()

    def refresh(self) -> None:
        """Replay the chosen discharge (in the shared pool when ``background``)."""
        if self.folder is None or self.cell is None:
            return
        request = (self.cell, int(self.position), float(self.context_s))
        if not self.background:
            self._worker.run(request)
            return
        self.busy = True
        self._worker.submit(request)

    def _compute(self, request: tuple) -> dict[str, Any]:
        from uam_studio.battery.real.nasa_data import load_nasa_cell
        from uam_studio.battery.real.nasa_replay import replay_discharge

        name, position, context_s = request
        try:
            if self._cell is None or self._cell.name != name:  # a slider move replays the cell already read
                # refresh() requests a replay only with the data folder found
                self._cell = load_nasa_cell(cast("Path", self.folder) / f"{name}.csv.gz")
            cell = self._cell
            n = len(cell.discharges)
            return {"replay": replay_discharge(cell, min(position, max(n - 1, 0)), context_s), "discharges": n}
        except InputError as err:
            return {"error": one_line(err)}

    def _apply(self, res: dict[str, Any], latest: bool) -> None:
        extra = {}
        if "discharges" in res:
            extra["discharges"] = res["discharges"]
            with param.parameterized.discard_events(self):  # the shown discharge, clamped to this cell's life
                self.position = res["replay"].position
        self.param.update(result=res, **extra, **({"busy": False} if latest else {}))

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until the newest request's result is applied (tests)."""
        return self._worker.wait_idle(timeout)


def _vline(x: float, ylim: tuple[float, float], label: str, color: str, dash: str = "solid", width: float = 2.0):
    return hv.Curve(([x, x], list(ylim)), "time since the load (min)", "voltage (V)", label=label).opts(
        color=color, line_dash=dash, line_width=width, backend="bokeh")


def nasa_figure(r) -> hv.Overlay:
    """The replay drawn: measured voltage, context end, band, median, bound, persistence, progpy, EOD."""
    ensure_bokeh_backend()  # Bokeh's styling options exist once its backend is loaded; each names it, so a
    # current backend switched elsewhere in the process (another pane, another test) cannot reject them
    p = r.prediction
    t_max = max(float(r.time_s[-1]), p.high_s, r.persistence_s or 0.0) / 60.0 * 1.05
    keep = r.progpy_time_s <= t_max * 60.0
    volts = np.r_[r.voltage_v, r.progpy_voltage_v[keep], r.cutoff_v]
    ylim = (float(np.nanmin(volts)) - 0.05, float(np.nanmax(volts)) + 0.05)
    x = "time since the load (min)"
    parts = [
        hv.VSpan(p.low_s / 60.0, p.high_s / 60.0).opts(color=NASA_COLORS["predicted"], alpha=0.15, backend="bokeh"),
        hv.Curve((r.progpy_time_s[keep] / 60.0, r.progpy_voltage_v[keep]), x, "voltage (V)",
                 label="progpy default (no health)").opts(color=NASA_COLORS["progpy"], line_width=1.5, backend="bokeh"),
        hv.Curve((r.time_s / 60.0, r.voltage_v), x, "voltage (V)", label="measured").opts(
            color=NASA_COLORS["measured"], line_width=2.5, backend="bokeh"),
        _vline(r.context_s / 60.0, ylim, f"context end ({r.context_s:g} s)", NASA_COLORS["context"], "dotted", 1.5),
        _vline(p.median_s / 60.0, ylim, "predicted (90% band)", NASA_COLORS["predicted"], width=3.0),
        _vline(p.bound95_s / 60.0, ylim, "bound, 5% risk", NASA_COLORS["bound"], "dashed", 3.0),
        hv.Curve(([0.0, t_max], [r.cutoff_v, r.cutoff_v]), x, "voltage (V)", label=f"EOD {r.cutoff_v:g} V").opts(
            color=NASA_COLORS["EOD"], line_dash="dashed", line_width=1.5, backend="bokeh"),
    ]
    if r.persistence_s is not None:
        parts.insert(4, _vline(r.persistence_s / 60.0, ylim, "persistence (previous discharge)",
                               NASA_COLORS["persistence"], "dotdash", 2.0))
    return hv.Overlay(parts).opts(
        hv.opts.Overlay(responsive=True, title=f"{r.cell}, discharge {r.discharge} ({r.condition})", xlabel=x,
                        ylabel="voltage (V)",
                        hooks=[no_scroll_zoom], legend_position="right", show_grid=True, xlim=(0.0, t_max),
                        ylim=ylim, fontsize={"title": "10pt", "legend": "8pt"}, backend="bokeh"))


class NasaLabView(pn.viewable.Viewer):
    """A cell picker, a slider over its life, the replay's figure and its sentence."""

    # never None once built: __init__ gives a new NasaLabState when none is given (param types it Optional)
    state = cast("param.ClassSelector[NasaLabState]", param.ClassSelector(class_=NasaLabState))

    def __init__(self, state: NasaLabState | None = None, **params: Any) -> None:
        ensure_bokeh_backend()
        super().__init__(state=state or NasaLabState(), **params)
        s = self.state
        self.cell = pn.widgets.Select(name="NASA cell", options=list(s.param.cell.objects), value=s.cell, width=250)
        self.position = pn.widgets.IntSlider(name="Discharge (over its life)", start=0, end=max(s.discharges - 1, 1),
                                             value=s.position, width=250)
        self.cell.link(s, value="cell")
        self.position.link(s, value="position")
        self.plot = pn.pane.HoloViews(linked_axes=False, sizing_mode="stretch_both", css_classes=["uam-nasa-voltage"])
        self.text = pn.pane.HTML(sizing_mode="stretch_width")  # its content carries the class (shadow root)
        self.busy = pn.indicators.LoadingSpinner(value=False, size=18, visible=False, margin=(0, 5))
        s.param.watch(self._on_result, "result")
        s.param.watch(lambda e: self.busy.param.update(value=e.new, visible=e.new), "busy")
        s.param.watch(self._on_discharges, "discharges")
        self._on_result()

    def __panel__(self) -> pn.viewable.Viewable:
        title = pn.Row(heading("A real NASA cell: predicted before the end, then what happened"), self.busy)
        if self.state.missing:
            return pn.Column(title, pn.pane.Alert(html.escape(self.state.missing), alert_type="info",
                                                  css_classes=["uam-nasa-missing"]), sizing_mode="stretch_width")
        note = [pn.pane.HTML(f"<div class='uam-nasa-source'>{html.escape(self.state.source)}</div>",
                             sizing_mode="stretch_width")] if self.state.source else []
        controls = pn.Column(self.cell, self.position, self.text, *note, width=290)
        plot = pn.Column(window_height(self.plot, PLOT_HEIGHT_CSS), min_width=560, sizing_mode="stretch_width",
                         styles={"flex": "1 1 560px"})
        return pn.Column(title, pn.FlexBox(controls, plot, flex_wrap="wrap", gap="10px", sizing_mode="stretch_width"),
                         sizing_mode="stretch_width")

    def _on_discharges(self, event: param.parameterized.Event) -> None:
        self.position.param.update(end=max(event.new - 1, 1), value=self.state.position)

    def _on_result(self, *events: Any) -> None:
        res = self.state.result
        if self.position.value != self.state.position:
            self.position.value = self.state.position
        if res is None:
            return
        if "error" in res:
            self.text.object = f"<div class='uam-nasa-summary uam-nasa-error'>{html.escape(res['error'])}</div>"
            return
        r = res["replay"]
        self.plot.object = nasa_figure(r)
        p = r.prediction
        lines = [f"<b>{html.escape(r.cell)}</b>, discharge {r.discharge} ({r.position + 1} of {r.discharges}), "
                 f"{html.escape(r.condition)}.",
                 html.escape(r.sentence()) + ".",
                 "Persistence (the previous discharge at this load): "
                 + (f"{r.persistence_s:,.0f} s." if r.persistence_s is not None else "none (no earlier discharge at "
                    "this load and ambient)."),
                 "progpy's default cell: " + (f"{r.progpy_s:,.0f} s." if r.progpy_s is not None else "never.")
                 + " It knows nothing of this cell's health.",
                 f"Method: {METHODS[p.method]}; model "
                 + FIT_WORDS.get(r.fit, r.fit) + "."]
        if p.flag:
            lines.append(f"<span class='uam-nasa-flag'>&#9888; {html.escape(p.flag)}</span>")
        self.text.object = ("<div class='uam-nasa-summary'>"
                            + "".join(f"<p style='margin:4px 0'>{x}</p>" for x in lines) + "</div>")
