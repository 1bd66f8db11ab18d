"""A bare Panel page of the Planner's shape, the floor of ``bench_app.py steps``: one slider, an HTML summary
that carries ``data-busy``/``data-inputs`` as the Planner's does, and four Bokeh figures whose lines are
replaced on every step, with no planning. Served with ``panel serve benchmarks/bare_page.py``."""

import numpy as np
import panel as pn
from bokeh.models import ColumnDataSource
from bokeh.plotting import figure

pn.extension()
slider = pn.widgets.FloatSlider(name="R0 (ohm)", start=0.05, end=0.3, step=0.001, value=0.117, width=260)
summary = pn.pane.HTML("")
sources = [ColumnDataSource({"x": [], "y": []}) for _ in range(4)]
figs = []
for src in sources:
    f = figure(width=520, height=220)
    f.line("x", "y", source=src)
    figs.append(pn.pane.Bokeh(f))


def update(value: float) -> None:
    x = np.linspace(0.0, 60.0, 600)
    for k, src in enumerate(sources):
        src.data = {"x": x, "y": 4.1 - value * (k + 1) * x / 60.0}
    summary.object = (f"<div class='uam-plan-summary' data-busy='false' data-inputs='r0={value:g}'>"
                      f"Route: R0 {value:.3f}</div>")


slider.param.watch(lambda e: update(e.new), "value")
update(slider.value)
pn.Row(pn.Column(slider, summary, width=290), pn.Column(*figs)).servable()
