"""State of the Retrain tab: a retraining run (the paper's DQN or the attention planner) in the background,
and its learning curves' reference.

:class:`RetrainState` validates the settings and trains with the library
(:mod:`uam_studio.planning.agents.retrain`, :mod:`uam_studio.planning.agents.attention.retrain`) in a
child process or a thread with a stop flag; episode (epoch) stats go through a queue that the view
drains on its own (periodic) callback; progress comes with elapsed time and time left; the exact
oracle's plan of the map (a comparison row, :mod:`uam_studio.app.planner.comparison`) is the curves' reference.
"""

from __future__ import annotations

import collections
import dataclasses
import os
import threading
import time
import traceback
from collections.abc import Callable
from typing import Any

import numpy as np
import param

from uam_studio.app.planner.comparison import (
    COMPARE_MODES,
    cached_row,
    compare_row,
    comparison_runner,
    store_row,
)
from uam_studio.app.planner.plans import PlanRequest
from uam_studio.app.services import ACTIVITY, one_line
from uam_studio.errors import InputError
from uam_studio.planning.agents.attention.retrain import (
    CLASS_EPOCHS,
    CLASS_MISSIONS,
    EPOCHS_RANGE,
    MISSIONS_RANGE,
)
from uam_studio.planning.agents.trainer import TrainJob, trainer
from uam_studio.planning.missions.mission import SCENARIOS, Mission
from uam_studio.planning.missions.scenario import DEFAULT_SCENARIO
from uam_studio.planning.planners import PAPER_PLANNER, PLANNERS

__all__ = ["CURVE_COLUMNS", "DEFAULT_MODEL", "EPOCH_COLUMNS", "MODELS", "RUNNER_ENV", "RetrainState"]

RUNNER_ENV = "UAM_STUDIO_RETRAIN_RUNNER"  # "process" (default) or "thread"


def _clock(seconds: float) -> str:
    """``m:ss`` (``h:mm:ss`` from an hour)."""
    t = int(round(seconds))
    h, rest = divmod(t, 3600)
    return f"{h}:{rest // 60:02d}:{rest % 60:02d}" if h else f"{rest // 60}:{rest % 60:02d}"


CURVE_SERIES = ("reached", "cycles", "reward", "breach")  # per-episode values the Retrain tab plots
CURVE_COLUMNS = ["episode", *CURVE_SERIES, *(f"{k}_ma" for k in CURVE_SERIES)]
"""Columns of :meth:`RetrainState.poll`'s rows for a DQN run."""
EPOCH_COLUMNS = ["epoch", "loss", "accuracy", "priority", "priority_net"]
"""Columns of :meth:`RetrainState.poll`'s rows for an attention run (priorities NaN without a map)."""
DEFAULT_MODEL = PAPER_PLANNER  # the paper's agent: the Retrain tab's first planner
MODELS = {PLANNERS[n].train_label: n for n in sorted((n for n, p in PLANNERS.items() if p.trainer is not None),
                                                      key=lambda n: n != DEFAULT_MODEL)}


class RetrainState(param.Parameterized):
    """A retraining run in the background (one per session at a time): the paper's DQN (``model="dqn"``)
    or the attention planner (``model="attention"``: imitation of the exact oracle on random missions,
    each epoch's network scored on the current map).

    :meth:`start` validates the settings (:func:`uam_studio.planning.agents.retrain.training_setup`,
    :func:`uam_studio.planning.agents.attention.retrain.attention_setup`) and starts the run: in a child process
    (``runner="process"``, the served app's default:
    :class:`~uam_studio.planning.agents.retrain.RetrainProcess`, lower CPU priority, no GIL shared with
    the sessions) or in a thread of this process (``runner="thread"``). :meth:`stop` sets the stop
    flag (the agent trained so far is still saved). Neither touches the param values: :meth:`poll`,
    called on the session's own thread (a periodic callback in the app), drains the episodes into
    the values that views watch and returns the new ones.
    """

    model: param.Selector[str] = param.Selector(
        default=DEFAULT_MODEL, objects=list(MODELS.values()),
        doc="the paper's DQN, or the attention planner (the app's default planner)")
    source: param.Selector[str] = param.Selector(
        default="map", objects=["map", "random"],
        doc="DQN: train on the current map or on random missions; attention: score each "
            "epoch on the current map, or not at all (it always trains on random missions)")
    scenario: param.Selector[str] = param.Selector(default=DEFAULT_SCENARIO, objects=list(SCENARIOS))
    alpha = param.Number(default=1.0, bounds=(0.0, 100.0), doc="reward per destination x priority")
    beta = param.Number(default=1.0, bounds=(0.0, 100.0), doc="penalty per charging stop")
    gamma = param.Number(default=5.0, bounds=(0.0, 100.0), doc="penalty for an end of discharge")
    steps = param.Integer(default=5000, bounds=(100, 1_000_000), doc="environment transitions")
    missions = param.Integer(default=CLASS_MISSIONS, bounds=MISSIONS_RANGE,
                             doc="attention: training missions, each solved by the exact oracle")
    epochs = param.Integer(default=CLASS_EPOCHS, bounds=EPOCHS_RANGE, doc="attention: passes over the examples")
    seed = param.Integer(default=0, bounds=(0, 2**31 - 1))
    start_from: param.Selector[str] = param.Selector(
        default="scratch", objects=["scratch", "bundled"],
        doc="random weights, or fine-tune the bundled agent (DQN: "
            "pretrained/dqn_<scenario>.zip, exploration from epsilon 0.2; attention: "
            "pretrained/attention_planner.pt)")

    running = param.Boolean(default=False)
    timesteps = param.Integer(default=0)
    episodes = param.Integer(default=0)
    status = param.String(default="")
    error = param.String(default="")
    agent_path = param.String(default="", doc="the last saved agent")
    reference = param.Dict(default=None, allow_None=True,
                           doc="the exact oracle's plan of the map (compare_row, plus 'label' and 'cell'), the "
                               "learning curves' reference; None for random missions or until computed")
    runner: param.Selector[str] = param.Selector(
        default="process", objects=["process", "thread"],
        doc="train in a child process (default; $UAM_STUDIO_RETRAIN_RUNNER overrides) "
            "or in a thread of this process")

    MA_WINDOW = 50

    def __init__(self, dispatch: Callable[[Callable[[], None]], None] | None = None, compare: str = "off",
                 **params: Any) -> None:
        """
        :param dispatch: how a result computed elsewhere (the oracle reference) is handed back to the
            session's thread (default: applied in the computing thread).
        :param compare: where the oracle reference is computed (see :class:`PlannerState`'s ``compare``).
        """
        env = os.environ.get(RUNNER_ENV, "").strip()
        if "runner" not in params and env in ("process", "thread"):
            params["runner"] = env
        super().__init__(**params)
        if compare not in COMPARE_MODES:
            raise InputError("compare", f"{compare!r}: allowed {', '.join(COMPARE_MODES)}")
        self.dispatch = dispatch or (lambda cb: cb())
        self.compare = compare
        self._reference_req: PlanRequest | None = None
        self._t_start: float | None = None
        self._t_end: float | None = None
        self._proc: Any = None
        self._queue: collections.deque = collections.deque()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._result: Any = None
        self._failure: str | None = None
        self._finished = False
        self._target_steps = 0
        self._series: dict[str, list[float]] = {k: [] for k in CURVE_SERIES}
        self._kind = DEFAULT_MODEL  # the model of the last run started
        self._last_timestep = 0
        self._run_epochs = 0
        self._stage: tuple[str, int, int] | None = None  # an attention run's examples: (stage, done, total)

    @param.depends("model", watch=True)
    def _forget_other_run(self) -> None:
        """Choosing the other planner while no run goes clears the last run's status, counts and
        clock: they described the other planner's run (its saved agent stays in the policy list)."""
        if self.running or self.model == self._kind:
            return
        self._target_steps, self._t_start, self._t_end, self._stage = 0, None, None, None
        self._kind = self.model
        self.param.update(timesteps=0, episodes=0, status="", error="")

    def start(self, mission: Mission | None = None) -> bool:
        """Start training on ``mission`` (``source == "map"``) or on random missions (the attention
        planner: always on random missions, scored on ``mission``). Returns False (with :attr:`error`
        set) for bad settings or while a run is going."""
        if self.running:
            self.error = "training: a run is already going; stop it first"
            return False
        m = mission if self.source == "map" else None
        if self.source == "map" and mission is None:
            self.error = "training: no map to train on"
            return False
        how = trainer(self.model, "model")
        values = {k: getattr(self, k) for k in ("scenario", "seed", *how.settings)}
        init_agent = how.bundled_init(self.scenario) if self.start_from == "bundled" else None
        try:
            job = how.job(values, m, init_agent, "app")
        except InputError as err:
            what = "current map" if m is not None and how.trains_on_map else "settings"
            self.error = f"training ({what}): {one_line(err)}"
            return False
        self.error = ""
        self._queue.clear()
        self._stop.clear()
        self._result, self._failure, self._finished = None, None, False
        self._series = {k: [] for k in CURVE_SERIES}
        self._kind, self._stage = self.model, None
        self._target_steps, self._run_epochs = job.target, job.epochs
        self._t_start, self._t_end = time.monotonic(), None
        self.request_reference(mission)
        self.param.update(running=True, timesteps=0, episodes=0, agent_path="", status=job.status)
        if self.runner == "process":
            from uam_studio.planning.agents.retrain import RetrainProcess

            self._proc = RetrainProcess(job.path, mission=job.mission, source="app", pause_event=ACTIVITY.event,
                                        kind=self.model, **job.setup)
            self._proc.start()
            return True
        self._proc = None
        self._thread = threading.Thread(target=self._run, args=(job,), daemon=True, name="uam-retrain")
        self._thread.start()
        return True

    def _run(self, job: TrainJob) -> None:
        import torch

        torch.set_num_threads(1)  # leave the other core to the sessions
        try:
            self._result = job.run(self._queue.append, self._progress, self._stop)
        except Exception as err:
            traceback.print_exc()
            self._failure = f"training failed: {type(err).__name__}: {one_line(err)}"
        finally:
            self._finished = True

    def _progress(self, stage: str, done: int, total: int) -> None:
        self._stage = (stage, done, total)

    def stop(self) -> None:
        """Ask the run to stop at the next environment step (the agent so far is saved)."""
        if self.running:
            self._stop.set()
            if self._proc is not None:
                self._proc.stop()
            self.status = "stopping..."

    @property
    def run_model(self) -> str:
        """The model of the last run started (``"dqn"`` before any run)."""
        return self._kind

    @property
    def _unit(self) -> str:
        """What the last run's reports count (its trainer's ``unit``: ``"episode"`` or ``"epoch"``)."""
        return trainer(self._kind).unit

    @property
    def progress(self) -> float:
        """Fraction of the steps done, 0-1."""
        return min(1.0, self.timesteps / self._target_steps) if self._target_steps else 0.0

    @property
    def elapsed_s(self) -> float:
        """Seconds since the run started (until it ended), 0 before any run."""
        if self._t_start is None:
            return 0.0
        return (self._t_end if self._t_end is not None else time.monotonic()) - self._t_start

    def progress_text(self) -> str:
        """Work done of the total, percent, elapsed time and (while running) the time left at the
        pace so far, e.g. ``"1200 of 5000 steps (24%) · 0:12 elapsed · about 0:38 left"`` (an attention
        run: missions solved by the oracle, then epochs)."""
        if not self._target_steps:
            return "not started"
        p = self.progress
        if self.running and p == 0 and self._proc is not None and (self._unit != "epoch" or self._stage is None):
            return (f"starting the trainer: a new process loads torch · {_clock(self.elapsed_s)} elapsed "
                    "(Stop ends it at once; nothing is saved before the first "
                    f"{self._unit})")
        if self._unit == "epoch":
            total = self._target_steps - self._run_epochs
            solved = self._stage[1] if self._stage is not None else 0
            done = f"{solved} of {total} missions solved by the oracle, {self.episodes} of {self._run_epochs} epochs"
        else:
            done = f"{self.timesteps} of {self._target_steps} steps"
        text = f"{done} ({100 * p:.0f}%) \u00b7 {_clock(self.elapsed_s)} elapsed"
        if self.running:
            eta = self.elapsed_s * (1 - p) / p if p > 0 else None
            first = f"{self._unit}s"
            text += (f" \u00b7 about {_clock(eta)} left" if eta is not None
                     else f" \u00b7 time left: after the first {first}")
        return text

    def request_reference(self, mission: Mission | None) -> None:
        """Compute the learning curves' reference for ``mission`` with this run's scenario: the exact
        oracle's plan (:func:`compare_row`; at once if this process has it), or none (``mission``
        None: random missions)."""
        if mission is None or self.source != "map" or self.compare == "off":
            self._reference_req = None
            self.reference = None
            return
        m = mission if mission.scenario == self.scenario else dataclasses.replace(mission, scenario=self.scenario)
        req = PlanRequest(m, "oracle")
        if req == self._reference_req:
            return
        self._reference_req = req
        extra = {"label": "exact oracle (this map)", "cell": f"q_max {m.battery.q_max:g} C, R0 {m.battery.r0:.3g} ohm"}
        row = cached_row(req)
        if row is None and self.compare == "inline":
            row = compare_row(m, "oracle")
            store_row(req, row)
        if row is not None:
            self.reference = {**row, **extra}
            return
        self.reference = None

        def done(row: dict[str, Any]) -> None:
            self.dispatch(lambda: self._reference_result(req, {**row, **extra}))

        comparison_runner(self.compare).submit(("retrain", id(self)), [(req, done)])

    def _reference_result(self, req: PlanRequest, row: dict[str, Any]) -> None:
        if req == self._reference_req:
            self.reference = row

    def poll(self) -> list[dict[str, float]]:
        """Drain the episode queue (call on the session's thread); updates the progress and, at the
        end, the status. Returns the new rows:

        - a DQN run: one per episode, of :data:`CURVE_COLUMNS`: ``episode`` and ``reached``
          (destinations), ``cycles`` (charging cycles), ``reward`` (undiscounted return) and
          ``breach`` (1 if the cell went below EOD), each with its moving average over
          :attr:`MA_WINDOW` episodes (``<name>_ma``; for ``breach`` the share of episodes that breached);
        - an attention run: one per epoch, of :data:`EPOCH_COLUMNS`: ``loss``, ``accuracy`` (share of
          decisions where the oracle's choice ranked first), ``priority`` (its plan of the map with
          the Planner's search, 0 if unsafe) and ``priority_net`` (the network's first choices alone).
        """
        if self._proc is not None and not self._finished:
            self._queue.extend(self._proc.poll())
            self._stage = self._proc.stage
            if self._proc.finished:
                self._result = self._proc.result
                self._failure = f"training failed: {self._proc.error}" if self._proc.error else None
                self._finished = True
        rows = self._epoch_rows() if self._unit == "epoch" else self._episode_rows()
        changes: dict[str, Any] = {}
        if self._unit == "epoch":
            solved = self._stage[1] if self._stage is not None else 0
            epochs = self.episodes + len(rows)
            if (solved + epochs, epochs) != (self.timesteps, self.episodes):
                changes.update(timesteps=solved + epochs, episodes=epochs)
        elif rows:
            changes.update(timesteps=int(self._last_timestep), episodes=self.episodes + len(rows))
        if self.running and self._finished:
            changes["running"] = False
            self._t_end = time.monotonic()
            if self._failure:
                changes.update(error=self._failure, status="training failed")
            elif self._result is not None:
                r = self._result
                end = "stopped" if r.stopped else "done"
                if self._unit == "epoch":
                    changes.update(timesteps=self._target_steps if not r.stopped else self.timesteps,
                                   agent_path=str(r.path), error="",
                                   status=f"{end}: {r.episodes} epoch{'s' * (r.episodes != 1)}; "
                                          f"saved {r.path.parent.name} (now in the Planner's policy list)")
                else:
                    changes.update(timesteps=r.timesteps, agent_path=str(r.path), error="",
                                   status=f"{end}: {r.episodes} episodes, {r.timesteps} steps; saved "
                                          f"{r.path.name} (now in the Planner's policy list)")
            else:  # stopped before the first episode (DQN) or epoch (attention: the oracle was solving its missions)
                first = self._unit
                changes.update(error="",
                               status=f"stopped before the first {first} ended: nothing learned, nothing saved")
        if changes:
            self.param.update(**changes)
        return rows

    def _episode_rows(self) -> list[dict[str, float]]:
        rows = []
        while self._queue:
            e = self._queue.popleft()
            values = {"reached": float(e.reached), "cycles": float(e.charging_cycles), "reward": float(e.reward),
                      "breach": float(e.eod_breach)}
            row = {"episode": float(e.episode)}
            for key, value in values.items():
                self._series[key].append(value)
                row[key] = value
                row[f"{key}_ma"] = float(np.mean(self._series[key][-self.MA_WINDOW:]))
            rows.append(row)
            self._last_timestep = e.timestep
        return rows

    def _epoch_rows(self) -> list[dict[str, float]]:
        rows = []
        while self._queue:
            e = self._queue.popleft()
            ev = e.evaluation or {}
            rows.append({"epoch": float(e.epoch), "loss": float(e.loss), "accuracy": float(e.accuracy),
                         "priority": float(ev.get("priority", np.nan)),
                         "priority_net": float(ev.get("priority_net", np.nan))})
        return rows

    def join(self, timeout: float | None = None) -> None:
        """Wait for the training thread or process (tests)."""
        if self._proc is not None:
            self._proc.join(timeout)
        elif self._thread is not None:
            self._thread.join(timeout)
