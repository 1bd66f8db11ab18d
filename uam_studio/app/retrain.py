"""The Retrain tab: retrain a DQN agent on the current map or on random missions, live.

Training runs in a background thread (:class:`~uam_studio.app.state.RetrainState`). This view
drains its episode queue on a periodic callback of the session (so every widget and plot update
happens on the session's own thread) and streams the rows into a :class:`holoviews.streams.Buffer`
behind the learning curves. A finished (or stopped) agent is saved in the user folder and appears
in every session's Planner policy list.
"""

from __future__ import annotations

import html
from typing import Any

import holoviews as hv
import pandas as pd
import panel as pn
import param

from uam_studio.app.session import ensure_bokeh_backend
from uam_studio.app.state import PlannerState, RetrainState, registry
from uam_studio.planning.agents.retrain import agents_dir
from uam_studio.planning.missions.mission import SCENARIOS

POLL_MS = 1000  # curves and progress once a second: each update re-renders two plots
CURVE_COLUMNS = ["episode", "reached", "cycles", "reached_ma", "cycles_ma"]


class RetrainView(pn.viewable.Viewer):
    """Settings, Start/Stop, progress and learning curves of a :class:`RetrainState`."""

    state = param.ClassSelector(class_=RetrainState)
    planner = param.ClassSelector(class_=PlannerState)

    def __init__(self, state: RetrainState, planner: PlannerState, **params: Any) -> None:
        ensure_bokeh_backend()
        super().__init__(state=state, planner=planner, **params)
        s = state
        s.scenario = planner.scenario
        w = 280
        self.source = pn.widgets.RadioButtonGroup(
            name="Missions", options={"Current map": "map", "Random missions": "random"}, value=s.source, width=w)
        self.scenario = pn.widgets.Select(name="Scenario", options=list(SCENARIOS), value=s.scenario, width=w)
        self.alpha = pn.widgets.FloatInput(name="alpha (reward per destination x priority)", value=s.alpha,
                                           start=0, end=100, step=0.5, width=w)
        self.beta = pn.widgets.FloatInput(name="beta (penalty per charging stop)", value=s.beta, start=0, end=100,
                                          step=0.5, width=w)
        self.gamma = pn.widgets.FloatInput(name="gamma (penalty for end of discharge)", value=s.gamma, start=0,
                                           end=100, step=0.5, width=w)
        self.steps = pn.widgets.IntInput(name="Steps (environment transitions)", value=s.steps, start=100,
                                         end=1_000_000, step=500, width=w)
        self.seed = pn.widgets.IntInput(name="Seed", value=s.seed, start=0, width=w)
        self.start_from = pn.widgets.RadioButtonGroup(
            name="Start from", options={"Random weights": "scratch", "Bundled agent (fine-tune)": "bundled"},
            value=s.start_from, width=w, css_classes=["uam-train-start-from"])
        for key in ("source", "scenario", "alpha", "beta", "gamma", "steps", "seed", "start_from"):
            getattr(self, key).link(s, value=key)
        planner.param.watch(lambda ev: setattr(self.scenario, "value", ev.new), "scenario")

        self.start = pn.widgets.Button(name="Start", button_type="success", width=135,
                                       css_classes=["uam-train-start"])
        self.stop = pn.widgets.Button(name="Stop", button_type="danger", width=135, disabled=True,
                                      css_classes=["uam-train-stop"])
        self.start.on_click(self._on_start)
        self.stop.on_click(lambda _ev: s.stop())
        self.progress = pn.indicators.Progress(name="progress", value=0, max=1000, width=w, bar_color="success",
                                               css_classes=["uam-train-progress"])
        self.status = pn.pane.HTML("", css_classes=["uam-train-status"], sizing_mode="stretch_width")
        self.error = pn.pane.Alert("", alert_type="danger", visible=False, css_classes=["uam-error"])

        self.buffer = hv.streams.Buffer(pd.DataFrame({c: [] for c in CURVE_COLUMNS}), length=200_000, index=False)
        self.reached_plot = pn.pane.HoloViews(hv.DynamicMap(self._reached_element, streams=[self.buffer]),
                                              linked_axes=False, css_classes=["uam-curve-reached"])
        self.cycles_plot = pn.pane.HoloViews(hv.DynamicMap(self._cycles_element, streams=[self.buffer]),
                                             linked_axes=False, css_classes=["uam-curve-cycles"])
        self._poller = None
        s.param.watch(self._on_status, ["running", "status", "error", "timesteps", "episodes", "agent_path"])
        self._on_status()

    def __panel__(self) -> pn.viewable.Viewable:
        intro = pn.pane.Markdown(
            "Retrain the masked DQN agent. *Current map* trains on the Planner's destinations with a random "
            "cell (q_max, R0) each episode; *random missions* draws a new mission every episode. "
            f"Agents are saved in `{html.escape(str(agents_dir()))}` (set `UAM_STUDIO_HOME` to move it), "
            "never over the bundled ones, and appear in the Planner's policy list. *Bundled agent* fine-tunes "
            "the scenario's bundled agent instead of starting from random weights: on an 8-destination map "
            "this reached the exact oracle's priority in 3 minutes where random weights did not "
            "(`benchmarks/RESULTS.md`).")
        controls = pn.Column("### Settings", self.source, self.scenario, "Start from", self.start_from, self.alpha,
                             self.beta, self.gamma, self.steps, self.seed, pn.Row(self.start, self.stop),
                             self.progress, width=310)
        return pn.Column(intro, self.error, pn.Row(controls, pn.Column(self.status, self.reached_plot,
                                                                       self.cycles_plot)))

    # ------------------------------------------------------------------ actions

    def _on_start(self, _event: Any) -> None:
        self.buffer.clear()
        if self.state.start(self.planner.mission):
            if self._poller is None:
                self._poller = pn.state.add_periodic_callback(self._poll, period=POLL_MS, start=False)
            self._poller.start()

    def _poll(self) -> None:
        rows = self.state.poll()
        if rows:
            self.buffer.send(pd.DataFrame(rows, columns=CURVE_COLUMNS))
        if not self.state.running and self._poller is not None:
            self._poller.stop()
            registry().refresh()  # the new agent appears in every session's Planner

    def _on_status(self, *events: Any) -> None:
        s = self.state
        self.start.disabled = s.running
        self.stop.disabled = not s.running
        self.progress.value = int(round(1000 * s.progress))
        self.error.object = html.escape(s.error)
        self.error.visible = bool(s.error)
        episodes = f"episodes: <b class='uam-episodes'>{s.episodes}</b>, steps: {s.timesteps}"
        self.status.object = f"<p>{html.escape(s.status)}</p><p>{episodes}</p>"

    def close(self) -> None:
        """The session ended: stop the run (the agent so far is still saved) and the poller."""
        self.state.stop()
        if self._poller is not None:
            self._poller.stop()

    # ------------------------------------------------------------------ plots

    @staticmethod
    def _curve_pair(data: pd.DataFrame, column: str, title: str, ylabel: str, raw_color: str,
                    ma_color: str) -> hv.Overlay:
        """Per-episode ``column`` and its moving average (``<column>_ma``) as one overlay."""
        raw = hv.Curve(data, "episode", column, label="per episode").opts(color=raw_color, line_width=1)
        ma = hv.Curve(data, "episode", f"{column}_ma", label=f"moving average ({RetrainState.MA_WINDOW})").opts(
            color=ma_color, line_width=2.5)
        return (raw * ma).opts(width=620, height=260, title=title, ylabel=ylabel,
                               legend_position="bottom_right", show_grid=True, framewise=True)

    @classmethod
    def _reached_element(cls, data: pd.DataFrame) -> hv.Overlay:
        return cls._curve_pair(data, "reached", "Destinations reached per episode", "destinations reached",
                               "#9ecae1", "#08519c")

    @classmethod
    def _cycles_element(cls, data: pd.DataFrame) -> hv.Overlay:
        return cls._curve_pair(data, "cycles", "Charging cycles per episode", "charging cycles",
                               "#fdae6b", "#a63603")
