"""The Retrain tab: retrain the paper's DQN agent or the attention planner, live.

Training runs in a child process or a thread (:class:`~uam_studio.app.retrain.state.RetrainState`). This
view drains its episode (epoch) queue on a periodic callback of the session (so every widget and plot
update happens on the session's own thread) and streams the rows into a
:class:`holoviews.streams.Buffer` behind the learning curves, which show the exact oracle's plan of the
map as a reference line (:attr:`RetrainState.reference`). The progress bar comes with steps, elapsed time and the time
left. A finished (or stopped) agent is saved in the user folder and appears in every session's Planner policy list.
"""

from __future__ import annotations

import html
from typing import Any, cast

import holoviews as hv
import numpy as np
import pandas as pd
import panel as pn
import param

from uam_studio.app.planner.state import PlannerState
from uam_studio.app.retrain.state import CURVE_COLUMNS, EPOCH_COLUMNS, MODELS, RetrainState
from uam_studio.app.services import registry
from uam_studio.app.session import ensure_bokeh_backend
from uam_studio.app.style import NOTE_STYLE, heading, intro, no_scroll_zoom
from uam_studio.planning.agents.retrain import agents_dir
from uam_studio.planning.agents.trainer import trainer
from uam_studio.planning.missions.mission import SCENARIOS

POLL_MS = 1000  # curves and progress once a second: each update re-renders two plots
SETTINGS_WIDTH = 270  # px, the settings' widgets


class RetrainView(pn.viewable.Viewer):
    """Settings, Start/Stop, progress and learning curves of a :class:`RetrainState`."""

    # required arguments of __init__: never None once built (param types them Optional, as they have no default)
    state = cast("param.ClassSelector[RetrainState]", param.ClassSelector(class_=RetrainState))
    planner = cast("param.ClassSelector[PlannerState]", param.ClassSelector(class_=PlannerState))

    def __init__(self, state: RetrainState, planner: PlannerState, **params: Any) -> None:
        ensure_bokeh_backend()
        super().__init__(state=state, planner=planner, **params)
        s = state
        s.scenario = planner.scenario
        w = SETTINGS_WIDTH
        self.model = pn.widgets.RadioButtonGroup(name="Planner", options=MODELS, value=s.model, width=w,
                                                 css_classes=["uam-train-model"])
        self.source = pn.widgets.RadioButtonGroup(
            name="Missions", options={"Current map": "map", "Random missions": "random"}, value=s.source, width=w)
        self.scenario = pn.widgets.Select(name="Scenario", options=list(SCENARIOS), value=s.scenario, width=w)
        third = (w - 20) // 3
        self.alpha = pn.widgets.FloatInput(name="alpha", value=s.alpha, start=0, end=100, step=0.5, width=third,
                                           description="reward per destination reached x its priority")
        self.beta = pn.widgets.FloatInput(name="beta", value=s.beta, start=0, end=100, step=0.5, width=third,
                                          description="penalty per charging stop")
        self.gamma = pn.widgets.FloatInput(name="gamma", value=s.gamma, start=0, end=100, step=0.5, width=third,
                                           description="penalty for an end of discharge")
        self.steps = pn.widgets.IntInput(name="Steps (environment transitions)", value=s.steps, start=100,
                                         end=1_000_000, step=500, width=w - 90)
        self.seed = pn.widgets.IntInput(name="Seed", value=s.seed, start=0, width=80)
        half = (w - 10) // 2
        self.missions = pn.widgets.IntInput(name="Training missions", value=s.missions, start=10, end=5000, step=50,
                                            width=half, css_classes=["uam-train-missions"],
                                            description="random missions of 2-6 destinations, each solved by "
                                                        "the exact oracle: its choices are the examples")
        self.epochs = pn.widgets.IntInput(name="Epochs", value=s.epochs, start=1, end=500, step=5, width=half,
                                          css_classes=["uam-train-epochs"],
                                          description="passes over the examples")
        self.start_from = pn.widgets.RadioButtonGroup(
            name="Start from", options={"Random weights": "scratch", "Fine-tune bundled": "bundled"},
            value=s.start_from, width=w, css_classes=["uam-train-start-from"])
        for key in ("model", "source", "scenario", "alpha", "beta", "gamma", "steps", "seed", "missions", "epochs",
                    "start_from"):
            getattr(self, key).link(s, value=key)
        planner.param.watch(lambda ev: setattr(self.scenario, "value", ev.new), "scenario")

        self.start = pn.widgets.Button(name="Start", button_type="success", width=w // 2 - 5,
                                       css_classes=["uam-train-start"])
        self.stop = pn.widgets.Button(name="Stop", button_type="danger", width=w // 2 - 5, disabled=True,
                                      css_classes=["uam-train-stop"])
        self.start.on_click(self._on_start)
        self.stop.on_click(lambda _ev: s.stop())
        # The bar inside keeps no margin of its own, so its whole height (border, shadow) is drawn.
        self.progress = pn.indicators.Progress(name="progress", value=0, max=1000, width=w, height=18,
                                               bar_color="success", css_classes=["uam-train-progress"],
                                               margin=(10, 10, 6, 10),
                                               stylesheets=["progress { margin: 0 !important; height: 18px; }"])
        self.progress_text = pn.pane.HTML("", width=w, styles={"font-size": "12px"}, margin=(0, 10, 10, 10))
        self.status = pn.pane.HTML("", css_classes=["uam-train-status"], sizing_mode="stretch_width")
        self.reference_text = pn.pane.HTML("", css_classes=["uam-train-reference"], sizing_mode="stretch_width",
                                           styles={"font-size": "12px", "color": "#444"})
        self.error = pn.pane.Alert("", alert_type="danger", visible=False, css_classes=["uam-error"])

        self.buffer = hv.streams.Buffer(pd.DataFrame({c: [] for c in CURVE_COLUMNS}), length=200_000, index=False)
        ref = hv.streams.Params(parameterized=s, parameters=["reference"])
        self.reached_plot = pn.pane.HoloViews(hv.DynamicMap(self._reached_element, streams=[self.buffer, ref]),
                                              linked_axes=False, css_classes=["uam-curve-reached"],
                                              sizing_mode="stretch_width")
        self.cycles_plot = pn.pane.HoloViews(hv.DynamicMap(self._cycles_element, streams=[self.buffer, ref]),
                                             linked_axes=False, css_classes=["uam-curve-cycles"],
                                             sizing_mode="stretch_width")
        self.reward_plot = pn.pane.HoloViews(hv.DynamicMap(self._reward_element, streams=[self.buffer]),
                                             linked_axes=False, css_classes=["uam-curve-reward"],
                                             sizing_mode="stretch_width")
        self.breach_plot = pn.pane.HoloViews(hv.DynamicMap(self._breach_element, streams=[self.buffer]),
                                             linked_axes=False, css_classes=["uam-curve-breach"],
                                             sizing_mode="stretch_width")
        self.epoch_buffer = hv.streams.Buffer(pd.DataFrame({c: [] for c in EPOCH_COLUMNS}), length=100_000,
                                              index=False)
        self.priority_plot = pn.pane.HoloViews(hv.DynamicMap(self._priority_element,
                                                             streams=[self.epoch_buffer, ref]),
                                               linked_axes=False, css_classes=["uam-curve-priority"],
                                               sizing_mode="stretch_width")
        self.loss_plot = pn.pane.HoloViews(hv.DynamicMap(self._loss_element, streams=[self.epoch_buffer]),
                                           linked_axes=False, css_classes=["uam-curve-loss"],
                                           sizing_mode="stretch_width")
        self.dqn_curves = pn.Column(self.reached_plot, self.cycles_plot, self.reward_plot, self.breach_plot,
                                    sizing_mode="stretch_width", margin=0)
        self.priority_note = pn.pane.HTML(
            "How to read it: <b>its plan</b> is what the Planner flies: the network ranks the choices and "
            "the Planner's search checks each leg on the physics model, so it can match the oracle from the "
            "first epoch. <b>First choices alone</b> follows the network's top choice with no search and "
            "scores 0 as soon as one of them is unsafe: in a short run it often falls to 0 while the network "
            "is still learning; what training improves is how often the oracle's choice is ranked first "
            "(the share below).", css_classes=["uam-curve-priority-note"], styles=NOTE_STYLE,
            sizing_mode="stretch_width")
        self.attention_curves = pn.Column(self.priority_plot, self.priority_note, self.loss_plot,
                                          sizing_mode="stretch_width", margin=0)
        # each setting's widgets, shown for the planners whose trainer reads it
        self.setting_widgets: dict[str, list[Any]] = {"alpha": [self.alpha], "beta": [self.beta],
                                                       "gamma": [self.gamma], "steps": [self.steps],
                                                       "missions": [self.missions], "epochs": [self.epochs]}
        # each report unit's curves (a HoloViews pane's own `visible` fails in Panel 1.9: their columns)
        self.unit_curves = {"episode": self.dqn_curves, "epoch": self.attention_curves}
        self._poller: pn.io.PeriodicCallback | None = None
        s.param.watch(self._on_status, ["running", "status", "error", "timesteps", "episodes", "agent_path"])
        s.param.watch(self._on_reference_inputs, ["source", "scenario"])
        s.param.watch(self._on_model, "model")
        s.param.watch(self._on_status, "model")
        s.param.watch(self._on_reference, "model")
        s.param.watch(self._on_reference, "reference")
        planner.param.watch(self._on_reference_inputs, "comparison")
        self._on_status()
        self._on_reference_inputs()
        self._on_reference()
        self._on_model()

    def __panel__(self) -> pn.viewable.Viewable:
        w = SETTINGS_WIDTH
        text = intro(
            "Retrain a planner and watch it learn.\n\n"
            "- **DQN (paper)** learns by trial and error, one episode after another, on the *current map* "
            "(a random cell each episode) or on *random missions*.\n"
            "- **Attention (default)** learns by imitation: the exact oracle solves random missions of 2-6 "
            "destinations and the network learns to rank the oracle's choice first. After each epoch it "
            "plans the *current map*.\n"
            "- *Fine-tune bundled* starts from the bundled agent (DQN: it reached the oracle on an "
            "8-destination map in 3 minutes where random weights did not: `benchmarks/RESULTS.md`, \"Planning\").\n"
            f"- Saved in `{html.escape(str(agents_dir()))}` (`UAM_STUDIO_HOME` moves it), never over the bundled "
            "ones; they appear in every session's Planner policy list. The full recipe is "
            "`uam-studio train attention`.")
        self.rewards = pn.pane.HTML("alpha: reward per destination x priority; beta: penalty per charging stop; "
                                    "gamma: penalty for an end of discharge", width=w, styles=NOTE_STYLE,
                                    margin=(0, 10))
        for name in ("alpha", "beta", "gamma"):
            self.setting_widgets[name].append(self.rewards)
        controls = pn.Column(heading("Settings"), pn.pane.HTML("Planner", margin=(4, 10, 0, 10)), self.model,
                             self.source, self.scenario,
                             pn.pane.HTML("Start from", margin=(4, 10, 0, 10)), self.start_from,
                             pn.Row(self.alpha, self.beta, self.gamma), self.rewards,
                             pn.Row(self.missions, self.epochs), pn.Row(self.steps, self.seed),
                             pn.Row(self.start, self.stop), self.progress, self.progress_text, width=w + 20,
                             css_classes=["uam-train-settings"])
        curves = pn.Column(self.status, self.reference_text, self.dqn_curves, self.attention_curves, min_width=520,
                           sizing_mode="stretch_width", styles={"flex": "1 1 520px"})
        self._on_model()
        return pn.Column(text, self.error, pn.FlexBox(controls, curves, flex_wrap="wrap", gap="10px",
                                                       sizing_mode="stretch_width"),
                         sizing_mode="stretch_width")

    def _on_model(self, *events: Any) -> None:
        """Show the chosen planner's settings and curves."""
        how = trainer(self.state.model)
        for name, widgets in self.setting_widgets.items():
            for widget in widgets:
                widget.visible = name in how.settings
        for unit, curves in self.unit_curves.items():
            curves.visible = unit == how.unit

    # ------------------------------------------------------------------ actions

    def _on_start(self, _event: Any) -> None:
        self.buffer.clear()
        self.epoch_buffer.clear()
        if self.state.start(self.planner.mission):
            if self._poller is None:
                self._poller = pn.state.add_periodic_callback(self._poll, period=POLL_MS, start=False)
            self._poller.start()

    def _poll(self) -> None:
        rows = self.state.poll()
        if rows and "epoch" in rows[0]:
            self.epoch_buffer.send(pd.DataFrame(rows, columns=EPOCH_COLUMNS))
        elif rows:
            self.buffer.send(pd.DataFrame(rows, columns=CURVE_COLUMNS))
        if not self.state.running and self._poller is not None:
            self._poller.stop()
            registry().refresh()  # the new agent appears in every session's Planner

    def _on_reference_inputs(self, *events: Any) -> None:
        req = self.planner.plan_request
        if not self.state.running:  # a run keeps the reference of its own map
            self.state.request_reference(req.mission if req is not None and self.state.source == "map" else None)

    def _on_reference(self, *events: Any) -> None:
        ref = self.state.reference
        attention = not trainer(self.state.model).trains_on_map  # it scores each epoch on the map
        if self.state.source != "map":
            text = ("Reference line: none (choose Current map to score each epoch on it)." if attention
                    else "Reference line: none for random missions (each episode is another map).")
        elif ref is None:
            text = "Reference line: the exact oracle on this map (computing...)."
        elif ref.get("status") != "done":
            text = f"Reference line: the exact oracle on this map failed ({ref.get('error')})."
        else:
            text = (f"Reference line (dashed): the exact oracle's plan of this map for the Planner's cell "
                    f"({ref['cell']}): {ref['reached']} of {ref['of']} destinations, "
                    f"priority {ref['priority']}, {ref['cycles']} charging cycle{'s' * (ref['cycles'] != 1)}. "
                    + ("Each epoch's network plans this map for the same cell: the line is the best it can reach."
                       if attention else "Training draws a new cell each episode, so it is a guide, not a bound."))
        self.reference_text.object = html.escape(text)

    def _on_status(self, *events: Any) -> None:
        s = self.state
        self.start.disabled = s.running
        self.model.disabled = s.running  # the curves shown are the running planner's
        self.stop.disabled = not s.running
        self.progress.value = int(round(1000 * s.progress))
        self.progress_text.object = f"<span class='uam-train-progress-text'>{html.escape(s.progress_text())}</span>"
        self.error.object = html.escape(s.error)
        self.error.visible = bool(s.error)
        if trainer(s.run_model if s.running or s.episodes else s.model).unit == "epoch":
            episodes = f"epochs: <b class='uam-episodes'>{s.episodes}</b>"
        else:
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
                    ma_color: str, reference: float | None, ref_label: str) -> hv.Overlay:
        """Per-episode ``column``, its moving average (``<column>_ma``) and the oracle's value as a
        dashed line, with axes that fit them all (from the first episode on: 50 episodes wide)."""
        n = float(data["episode"].max()) if len(data) else 0.0
        x1 = max(50.0, n)
        raw = hv.Curve(data, "episode", column, label="per episode").opts(color=raw_color, line_width=1, alpha=0.35)
        ma = hv.Curve(data, "episode", f"{column}_ma", label=f"moving average ({RetrainState.MA_WINDOW})").opts(
            color=ma_color, line_width=2.5)
        ref_y = [reference] * 2 if reference is not None else [np.nan] * 2
        ref = hv.Curve(([0.0, x1], ref_y), "episode", column, label=ref_label).opts(
            color="#333333", line_width=1.5, line_dash="dashed")
        top = max([1.0, float(data[column].max()) if len(data) else 0.0, reference or 0.0])
        bottom = min(0.0, float(data[column].min()) if len(data) else 0.0)
        span = top - bottom
        return (raw * ma * ref).opts(
            hv.opts.Overlay(responsive=True, height=240, title=title, ylabel=ylabel, legend_position="right",
                            hooks=[no_scroll_zoom],
                            show_grid=True, xlim=(0.0, x1), ylim=(bottom - 0.05 * span, top + 0.1 * span + 0.1),
                            fontsize={"title": "10pt", "legend": "8pt"}),
            hv.opts.Curve(framewise=True))

    @staticmethod
    def _reference(reference: dict[str, Any] | None, key: str) -> tuple[float | None, str]:
        value = float(reference[key]) if reference is not None and reference.get("status") == "done" else None
        return value, "exact oracle (this map)"

    @classmethod
    def _reached_element(cls, data: pd.DataFrame, reference: dict[str, Any] | None = None) -> hv.Overlay:
        return cls._curve_pair(data, "reached", "Destinations reached per episode", "destinations reached",
                               "#9ecae1", "#08519c", *cls._reference(reference, "reached"))

    @classmethod
    def _cycles_element(cls, data: pd.DataFrame, reference: dict[str, Any] | None = None) -> hv.Overlay:
        return cls._curve_pair(data, "cycles", "Charging cycles per episode (single charge: 1 = came home, "
                               "0 = did not)", "charging cycles",
                               "#fdae6b", "#a63603", *cls._reference(reference, "cycles"))

    @classmethod
    def _reward_element(cls, data: pd.DataFrame) -> hv.Overlay:
        return cls._curve_pair(data, "reward", "Reward per episode (alpha x priority - beta x stops - gamma x EOD)",
                               "reward", "#bcbddc", "#54278f", None, "")

    @classmethod
    def _breach_element(cls, data: pd.DataFrame) -> hv.Overlay:
        return cls._curve_pair(data, "breach", "End of discharge (EOD) per episode: 1 = the cell went below it",
                               "breach (moving average: share)", "#fc9272", "#a50f15", None, "")

    @staticmethod
    def _priority_element(data: pd.DataFrame, reference: dict[str, Any] | None = None) -> hv.Overlay:
        """The attention network's plan of the map after each epoch: with the Planner's search and by
        its first choices alone (0 if unsafe), and the exact oracle's priority as a dashed line."""
        n = float(data["epoch"].max()) if len(data) else 0.0
        x1 = max(10.0, n)
        search = hv.Curve(data, "epoch", "priority", label="its plan (Planner's search)").opts(
            color="#08519c", line_width=2.5)
        alone = hv.Curve(data, "epoch", "priority_net", label="first choices alone (no search)").opts(
            color="#6baed6", line_width=1.5, line_dash="dotted")
        ref_value = float(reference["priority"]) if reference is not None and reference.get("status") == "done" \
            else np.nan
        ref = hv.Curve(([0.0, x1], [ref_value] * 2), "epoch", "priority", label="exact oracle (this map)").opts(
            color="#333333", line_width=1.5, line_dash="dashed")
        values = [v for v in (*data["priority"], *data["priority_net"], ref_value) if np.isfinite(v)]
        top = max([1.0, *values])
        return (search * alone * ref).opts(
            hv.opts.Overlay(responsive=True, height=260, title="Priority of its plan of this map after each epoch "
                            "(0 = unsafe)", ylabel="priority reached", legend_position="right", show_grid=True,
                            hooks=[no_scroll_zoom],
                            xlim=(0.0, x1), ylim=(-0.05 * top, 1.1 * top + 0.1),
                            fontsize={"title": "10pt", "legend": "8pt"}),
            hv.opts.Curve(framewise=True))

    @staticmethod
    def _loss_element(data: pd.DataFrame) -> hv.Overlay:
        """Imitation loss (cross-entropy) and the share of decisions where the oracle's choice ranked first."""
        n = float(data["epoch"].max()) if len(data) else 0.0
        loss = hv.Curve(data, "epoch", "loss", label="loss (cross-entropy)").opts(color="#a63603", line_width=2)
        acc = hv.Curve(data, "epoch", "accuracy", label="oracle's choice ranked first (share)").opts(
            color="#54278f", line_width=2)
        top = max([1.0, *(float(v) for v in data["loss"])]) if len(data) else 1.0
        return (loss * acc).opts(
            hv.opts.Overlay(responsive=True, height=240, title="Imitation of the exact oracle: loss and agreement",
                            ylabel="loss / share", legend_position="right", show_grid=True, hooks=[no_scroll_zoom],
                            xlim=(0.0, max(10.0, n)), ylim=(0.0, 1.05 * top),
                            fontsize={"title": "10pt", "legend": "8pt"}),
            hv.opts.Curve(framewise=True))
