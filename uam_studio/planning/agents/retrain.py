"""Retraining a learned planner in a child process, and keeping retrained agents in the user's folder.

Each retrainable planner names its :class:`~uam_studio.planning.agents.trainer.Trainer` in
:data:`~uam_studio.planning.planners.PLANNERS` (the DQN's: :mod:`uam_studio.planning.agents.dqn.retrain`,
whose :func:`training_setup` and :func:`retrain_dqn` this module re-exports; the attention planner's:
:mod:`uam_studio.planning.agents.attention.retrain`). Here, for every one of them:

- :class:`RetrainProcess`: a trainer's run in a child process (lower CPU priority, one torch thread),
  streaming its reports (episodes, epochs) back; a server keeps its cores and its GIL for its sessions;
- :func:`user_home`, :func:`agents_dir`, :func:`list_agents`, :func:`new_agent_path`: the user folder,
  ``$UAM_STUDIO_HOME`` or ``~/.uam_studio``, whose ``agents/`` subfolder holds retrained agents.
"""

from __future__ import annotations

import multiprocessing
import os
import queue as queue_mod
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from uam_studio.bundled import HOME_ENV, agents_dir, is_bundled, refuse_bundled, user_home
from uam_studio.errors import InputError
from uam_studio.planning.agents.dqn.retrain import DQN_REWARD_DEFAULTS, new_agent_path, retrain_dqn, training_setup
from uam_studio.planning.agents.run_result import RetrainResult
from uam_studio.planning.agents.trainer import trainer, trainers
from uam_studio.planning.missions.mission import Mission

__all__ = [
    "DQN_REWARD_DEFAULTS",
    "HOME_ENV",
    "AgentInfo",
    "RetrainProcess",
    "RetrainResult",
    "agent_model",
    "agents_dir",
    "is_bundled",
    "list_agents",
    "new_agent_path",
    "retrain_dqn",
    "training_setup",
    "user_home",
]


# ----------------------------------------------------------------------------- user folder


@dataclass(frozen=True)
class AgentInfo:
    """A retrained agent file and what its model card says."""

    path: Path  # a DQN agent's zip, or an attention planner's weights file (attention_planner.pt)
    name: str  # file stem (DQN) or folder name (attention)
    scenario: str | None  # a DQN agent's scenario; None for the attention planner (every scenario)
    card: dict[str, Any] = field(repr=False)

    @property
    def model(self) -> str:
        """The planner it is an agent of (its card's ``"model"``)."""
        return str(self.card.get("model"))

    @property
    def label(self) -> str:
        """The name with what the card says was learned, e.g. ``"single_charge-map-20261126-120000
        (DQN, 5000 steps, single_charge)"`` or ``"... (attention, 3 epochs, stopped early)"``."""
        what = trainer(self.model).describe(self.card, self.scenario)
        if self.card.get("stopped_early"):
            what.append("stopped early")
        return f"{self.name} ({', '.join(w for w in what if w)})"


def agent_model(path: str | os.PathLike[str]) -> str:
    """Which planner a retrained agent file holds, by its name (``*.pt``: the attention planner, ``*.zip``:
    the DQN)."""
    found = [name for name, t in trainers().items() if t.owns(Path(path))]
    if not found:
        raise InputError("agent_path", f"{Path(path).name}: not an agent file of any planner")
    return found[0]


def list_agents(folder: str | os.PathLike[str] | None = None) -> list[AgentInfo]:
    """The agents in ``folder`` (default :func:`agents_dir`), newest first: every retrainable planner's
    (:meth:`~uam_studio.planning.agents.trainer.Trainer.find`: DQN agents, ``*.zip`` with a readable model
    card; attention planners, ``*/attention_planner.pt`` with a ``card.json`` of model ``attention`` beside
    it). Unreadable files are skipped (they are not agents); a missing folder gives ``[]``."""
    d = Path(folder) if folder is not None else agents_dir()
    if not d.is_dir():
        return []
    found = [f for t in trainers().values() for f in t.find(d)]
    found.sort(key=lambda f: (-f.mtime, f.name))
    return [AgentInfo(f.path, f.name, f.scenario, f.card) for f in found]


# ----------------------------------------------------------------------------- in a child process


def _process_main(kind: str, setup: dict[str, Any], agent_path: str, mission: Mission | None, out: Any,
                  stop: Any, source: str | None, nice: int, pause: Any, max_pause_s: float) -> None:
    """Entry point of :class:`RetrainProcess`'s child: train, save, report on ``out``."""
    try:
        os.nice(nice)
    except (AttributeError, OSError):  # not on this platform / not allowed
        pass

    def on_item(e: Any) -> None:
        out.put(e)
        if pause is not None:  # give way while the parent asks for it (at most max_pause_s per report)
            t0 = time.monotonic()
            while pause.is_set() and not stop.is_set() and time.monotonic() - t0 < max_pause_s:
                time.sleep(0.005)

    try:
        import torch

        torch.set_num_threads(1)
        res = trainer(kind).run(setup, Path(agent_path), mission, on_item, lambda *p: out.put(("progress", *p)),
                                stop, source)
        out.put(RetrainResult(res.path, res.card, res.episodes, res.timesteps, res.stopped) if res is not None
                else ("nothing saved",))
    except BaseException as err:  # reported to the parent; nothing is raised in the child
        out.put(("error", f"{type(err).__name__}: {' '.join(str(err).split())}"))


class RetrainProcess:
    """A planner's retraining (its :class:`~uam_studio.planning.agents.trainer.Trainer`'s ``run``) in a child
    process (``spawn``), streaming its reports back: :func:`retrain_dqn`'s :class:`EpisodeStats` (``kind="dqn"``),
    :func:`~uam_studio.planning.agents.attention.retrain.retrain_attention`'s
    :class:`~uam_studio.planning.agents.attention.train.EpochStats` (``kind="attention"``).

    Training in a thread of a server competes with its sessions for the GIL; a child process does
    not, and runs at a lower CPU priority (``nice``) with one torch thread. The settings are
    validated here, in the parent (the trainer's ``check`` raises :class:`InputError`).

    :param agent_path: the agent zip to write (never inside ``pretrained/``); for the attention planner,
        its weights file ``<new folder>/attention_planner.pt``.
    :param mission: the map to train on, or None for random missions (the attention planner trains
        on random missions and scores each epoch's network on this map).
    :param nice: niceness added in the child (0 for none).
    :param pause_event: a ``multiprocessing`` Event (of the ``spawn`` context); while it is set the
        child pauses between episodes (at most ``max_pause_s`` per episode). A server sets it while
        its sessions plan, so that training gives way even where niceness cannot help (a server
        that itself runs niced, a machine busy with other work).
    :param kind: the planner (one with a trainer: ``"dqn"`` or ``"attention"``).
    :param setup: ``scenario``, ``alpha``, ``beta``, ``gamma``, ``steps``, ``seed``, ``init_agent`` of
        :func:`training_setup`; for the attention planner ``missions``, ``epochs``, ``seed`` of
        :func:`~uam_studio.planning.agents.attention.retrain.attention_setup` and ``init_agent`` (a
        weights file to start from).
    """

    def __init__(self, agent_path: str | os.PathLike[str], mission: Mission | None = None,
                 source: str | None = "app", nice: int = 10, pause_event: Any = None, max_pause_s: float = 2.0,
                 kind: str = "dqn", **setup: Any) -> None:
        how = trainer(kind, "kind")
        refuse_bundled(agent_path, "agent_path")
        self.config = how.check(mission, setup)
        self.kind = kind
        self.agent_path = Path(agent_path)
        ctx = multiprocessing.get_context("spawn")  # no fork of a threaded server
        self._out = ctx.Queue()
        self._stop = ctx.Event()
        self._proc = ctx.Process(target=_process_main, name="uam-retrain", daemon=True,
                                 args=(kind, setup, str(agent_path), mission, self._out, self._stop, source,
                                       nice, pause_event, float(max_pause_s)))
        self.result: RetrainResult | None = None
        self.stage: tuple[str, int, int] | None = None  # the attention run's last (stage, done, total)
        self.error: str | None = None
        self.finished = False
        self._seen = 0  # episodes (epochs) reported so far
        self._pending: list[Any] = []  # drained by stop(), returned by the next poll()

    def start(self) -> None:
        self._proc.start()

    def stop(self) -> None:
        """Ask the child to stop at its next environment step; it still saves the agent so far. Before
        the child has reported its first episode (epoch) there is nothing to save: it is ended at once
        (it may still be importing torch, which does not look at the stop request)."""
        self._stop.set()
        self._pending.extend(self.poll())  # kept for the next poll
        if not self._seen and not self.finished and self._proc.is_alive():
            self._proc.terminate()
            self._proc.join(5.0)
            self.finished = True

    def poll(self) -> list[Any]:
        """The episodes reported since the last call (never blocks). Sets :attr:`result` or
        :attr:`error` and :attr:`finished` when the child is done (neither: an attention run stopped
        before its first epoch saved nothing)."""
        episodes, self._pending = self._pending, []
        exited = not self._proc.is_alive() if self._proc.pid is not None else False
        while True:
            try:
                item = self._out.get_nowait()
            except queue_mod.Empty:
                break
            except (EOFError, OSError):
                break
            if isinstance(item, RetrainResult):
                self.result, self.finished = item, True
            elif isinstance(item, tuple) and item[:1] == ("error",):
                self.error, self.finished = item[1], True
            elif isinstance(item, tuple) and item[:1] == ("nothing saved",):  # stopped before any epoch
                self.finished = True
            elif isinstance(item, tuple) and item[:1] == ("progress",):
                self.stage = (str(item[1]), int(item[2]), int(item[3]))
            else:
                episodes.append(item)
                self._seen += 1
        if exited and not self.finished:
            self.error = f"the training process exited (code {self._proc.exitcode}) without a result"
            self.finished = True
        return episodes

    def join(self, timeout: float | None = None) -> None:
        self._proc.join(timeout)
