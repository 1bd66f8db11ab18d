"""The Fly tab's "many flights" view: the price of safety, flown while a class watches.

:class:`ManyFlights` flies ``per_level`` fresh flights at each declared risk the tab offers
(:func:`~uam_studio.planning.operations.safety_price.price_of_safety`, the call ``benchmarks/bench_risk.py`` makes with
more flights), new packs in the world the tab's world selects, in the flights' thread pool; :class:`ManyFlightsView`
draws the breach rate against the declared risk (with its 95% interval) and the priority served against hindsight,
and lists the levels' table. A handful of flights per level gives wide intervals: the view says how many flew.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, cast

import pandas as pd
import panel as pn
import param
from bokeh.models import ColumnDataSource, FixedTicker, HoverTool, Range1d
from bokeh.models.annotations import Whisker  # = bokeh.models.Whisker, a re-export mypy misses

from uam_studio.app.services import FLIGHT_POOL, LatestWorker, one_line
from uam_studio.app.style import busy_html, busy_mark, derived_looks, legend_above, page_figure
from uam_studio.errors import InputError
from uam_studio.planning.operations.safety_price import RATE_FLOOR, RiskLevel, price_of_safety, risk_levels
from uam_studio.risk import RISK_LEVELS

RATE_COLOR, DIAGONAL_COLOR = "#d62728", "#808080"  # the breach rates flown; the line rate = declared risk
OPERATOR_COLOR, BLIND_COLOR = "#1f77b4", "#2ca02c"  # priority served: the operator; its pre-flight plan, blind
COLUMNS = ["declared risk", "flights", "breaches", "breach rate", "95% interval", "p (at most the risk)",
           "priority / hindsight", "single-charge", "blind / hindsight", "blind breaches"]


class ManyFlights(param.Parameterized):
    """Many flights at each declared risk (module docstring).

    Inputs: ``per_level`` (flights per risk, half single-charge), ``risks`` (the declared risks), ``world`` (the world
    the packs fly, :data:`~uam_studio.planning.operations.world.WORLDS`). Outputs: ``levels`` (one
    :class:`~uam_studio.planning.operations.safety_price.RiskLevel` per risk), ``done`` and ``total`` (flights flown and
    to fly), ``running``, ``error`` (one line).
    """

    per_level = param.Integer(default=4, bounds=(2, 40))
    risks = param.List(default=list(RISK_LEVELS), item_type=float)
    world = param.String(default="varied")
    levels = param.List(default=[], item_type=RiskLevel)
    done = param.Integer(default=0)
    total = param.Integer(default=0)
    running = param.Boolean(default=False)
    error = param.String(default="")

    def __init__(self, background: bool = False, dispatch: Callable[[Callable[[], None]], None] | None = None,
                 **params: Any) -> None:
        super().__init__(**params)
        self.background = background
        self._dispatch = dispatch or (lambda f: f())
        self._worker: LatestWorker[tuple, tuple[list[RiskLevel], str]] = LatestWorker(
            self._compute, self._landed, lambda _job, e: ([], f"the flights failed: {type(e).__name__}: "
                                                              f"{one_line(e)}"),
            dispatch=dispatch, pool=FLIGHT_POOL)

    def _compute(self, job: tuple) -> tuple[list[RiskLevel], str]:
        risks, n, world = job
        try:
            flights = price_of_safety(risks, n, world=world,
                                      progress=lambda k, _n: self._dispatch(lambda: setattr(self, "done", k)))
            return risk_levels(flights), ""
        except InputError as err:
            return [], one_line(err)

    def run(self) -> None:
        """Fly the flights (in the pool when ``background``)."""
        self.param.update(running=True, done=0, total=self.per_level * len(self.risks), error="")
        job = (tuple(self.risks), self.per_level, self.world)
        if self.background:
            self._worker.submit(job)
        else:
            self._worker.run(job)

    def _landed(self, res: tuple[list[RiskLevel], str], latest: bool) -> None:
        if latest:
            levels, err = res
            self.param.update(levels=levels, error=err, running=False)

    def wait_idle(self, timeout: float = 120.0) -> bool:
        """Block until the newest run asked for has landed, at most ``timeout`` s (tests)."""
        return self._worker.wait_idle(timeout)


class ManyFlightsView(pn.viewable.Viewer):
    """The button, the progress, the two figures and the table of a :class:`ManyFlights`."""

    state = cast("param.ClassSelector[ManyFlights]", param.ClassSelector(class_=ManyFlights))

    def __init__(self, state: ManyFlights, **params: Any) -> None:
        super().__init__(state=state, **params)
        s = self.state
        self.button = pn.widgets.Button(name="Fly many flights", button_type="primary", width=200,
                                        css_classes=["uam-many-run"])
        self.per_level = pn.widgets.IntSlider(name="Flights per declared risk", start=2, end=20, step=2,
                                              value=s.per_level, width=200)
        self.progress = busy_mark(False, 110, "flying...")
        self.note = pn.pane.Markdown("", css_classes=["uam-many-note"], sizing_mode="stretch_width")
        self.table = pn.widgets.Tabulator(pd.DataFrame(columns=COLUMNS), disabled=True, show_index=False,
                                          sizing_mode="stretch_width", css_classes=["uam-many-table"],
                                          layout="fit_columns",  # the headers wrap: each one read whole
                                          configuration={"columnDefaults": {"headerWordWrap": True}})
        x_range = (min(s.risks) / 1.6, max(s.risks) * 1.6)
        self.rates = ColumnDataSource({"risk": [], "rate": [], "low": [], "high": [], "breaches": [], "flights": []})
        self.served = ColumnDataSource({"risk": [], "operator": [], "blind": []})
        # the line rate = risk across the axis, drawn before any flight: what to read against
        self.diagonal = ColumnDataSource({"x": list(x_range), "y": list(x_range)})
        rate_fig = page_figure(title="breach rate against the declared risk", width=380, height=300,
                               x_axis_type="log", y_axis_type="log", x_axis_label="declared risk",
                               y_axis_label="breach rate (0 drawn at 0.001)",
                               x_range=Range1d(start=x_range[0], end=x_range[1]),
                               y_range=Range1d(start=RATE_FLOOR / 2, end=1.0))
        rate_fig.line("x", "y", source=self.diagonal, color=DIAGONAL_COLOR, line_dash="dashed",
                      legend_label="rate = risk")
        dots = rate_fig.scatter("risk", "rate", source=self.rates, size=9, color=RATE_COLOR,
                                legend_label="flown (95% interval)")
        rate_fig.add_layout(Whisker(source=self.rates, base="risk", lower="low", upper="high", line_color=RATE_COLOR))
        rate_fig.add_tools(HoverTool(renderers=[dots], tooltips=[("declared risk", "@risk"),
                                                                 ("breaches", "@breaches of @flights")]))
        legend_above(rate_fig)
        served_fig = page_figure(title="priority served / hindsight (breach: 0)", width=380, height=300,
                                 x_axis_type="log", x_axis_label="declared risk", y_axis_label="priority / hindsight",
                                 x_range=Range1d(start=x_range[0], end=x_range[1]),
                                 y_range=Range1d(start=0.0, end=1.05))
        for fig in (rate_fig, served_fig):
            fig.xaxis.ticker = FixedTicker(ticks=list(s.risks))
        served_fig.line("risk", "operator", source=self.served, color=OPERATOR_COLOR, line_width=2,
                        legend_label="operator")
        served_fig.scatter("risk", "operator", source=self.served, color=OPERATOR_COLOR, size=8)
        served_fig.line("risk", "blind", source=self.served, color=BLIND_COLOR, line_dash="dashed",
                        legend_label="pre-flight plan, blind")
        legend_above(served_fig)
        self.rate_fig, self.served_fig = derived_looks(rate_fig), derived_looks(served_fig)
        self.button.on_click(lambda _e: s.run())
        self.per_level.param.watch(lambda e: setattr(s, "per_level", e.new), "value")
        s.param.watch(lambda e: setattr(self.progress, "object", busy_html(bool(e.new), "flying...")), "running")
        s.param.watch(self._on_levels, "levels")
        s.param.watch(self._on_note, ["done", "error", "running"])
        self._on_note()
        self._layout = pn.Column(
            pn.Row(pn.Column(self.button, self.per_level, width=230), self.progress, self.note,
                   sizing_mode="stretch_width"),
            pn.Row(pn.pane.Bokeh(self.rate_fig), pn.pane.Bokeh(self.served_fig)), self.table,
            sizing_mode="stretch_width", css_classes=["uam-many"])

    def _on_note(self, *_: Any) -> None:
        s = self.state
        if s.error:
            self.note.object = f"**{s.error}**"
        elif s.running:
            self.note.object = f"flying {s.done} of {s.total} flights (new packs, a weather change in each)"
        elif s.levels:
            self.note.object = (f"{s.levels[0].flights} flights per declared risk, half single-charge; new packs in "
                                f"the world '{s.world}', each with a weather change. Few flights: read the intervals.")
        else:
            self.note.object = ("The same fresh missions flown at each declared risk the tab offers: does the "
                                "breach rate stay under the risk, and what does safety cost in priority?")

    def _on_levels(self, *_: Any) -> None:
        levels = self.state.levels
        risks = [v.risk for v in levels]
        self.rates.data = {"risk": risks, "rate": [max(v.rate, RATE_FLOOR) for v in levels],
                           "low": [max(v.rate_low, RATE_FLOOR) for v in levels],
                           "high": [max(v.rate_high, RATE_FLOOR) for v in levels],
                           "breaches": [v.breaches for v in levels], "flights": [v.flights for v in levels]}
        self.served.data = {"risk": risks, "operator": [v.priority_ratio for v in levels],
                            "blind": [v.blind_ratio for v in levels]}
        self.table.value = pd.DataFrame([v.row() for v in levels], columns=COLUMNS)

    def __panel__(self) -> pn.viewable.Viewable:
        return self._layout


__all__ = ["ManyFlights", "ManyFlightsView"]
