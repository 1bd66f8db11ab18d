"""Retraining a DQN agent and keeping retrained agents (DQN and attention) in the user's folder.

Shared by ``uam-studio train dqn`` and the app's Retrain tab:

- :func:`training_setup`: validate the settings and build the :class:`DQNTrainConfig` and the env
  factory (a fixed map with a random cell each episode, or a random mission every episode);
- :func:`retrain_dqn`: train (stoppable, streaming :class:`EpisodeStats`), build the model card and
  save the agent atomically (never into the bundled ``pretrained/`` folder);
- :class:`RetrainProcess`: :func:`retrain_dqn` (or the attention planner's
  :func:`~uam_studio.planning.agents.attention.retrain.retrain_attention`) in a child process (lower
  CPU priority, one torch thread), streaming episodes (epochs) back; a server keeps its cores and its
  GIL for its sessions;
- :func:`user_home`, :func:`agents_dir`, :func:`list_agents`, :func:`new_agent_path`: the user folder,
  ``$UAM_STUDIO_HOME`` or ``~/.uam_studio``, whose ``agents/`` subfolder holds retrained agents.
"""

from __future__ import annotations

import datetime
import json
import multiprocessing
import os
import queue as queue_mod
import re
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from uam_studio.atomic_io import remove_stale_temps
from uam_studio.bundled import HOME_ENV, agents_dir, is_bundled, user_home
from uam_studio.errors import InputError, check_range
from uam_studio.planning.agents.run_result import RetrainResult
from uam_studio.planning.env.environment import REWARD_DEFAULTS
from uam_studio.planning.missions.mission import SCENARIOS, Mission, mission_to_dict
from uam_studio.planning.missions.scenario import DEFAULT_SCENARIO, check_scenario

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

DQN_REWARD_DEFAULTS = REWARD_DEFAULTS  # the paper's figures (UAMPlanningEnv's defaults)
STATS_WINDOW = 100  # final_stats average the last 100 episodes
MAX_STEPS = 10_000_000


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
        """``"dqn"`` or ``"attention"``."""
        return "attention" if self.card.get("model") == "attention" else "dqn"

    @property
    def label(self) -> str:
        """The name with what the card says was learned, e.g. ``"single_charge-map-20261126-120000
        (DQN, 5000 steps, single_charge)"`` or ``"... (attention, 3 epochs, stopped early)"``."""
        c = self.card
        if self.model == "attention":
            done = (c.get("stats") or {}).get("epochs_done")
            what = ["attention", f"{done} epoch{'' if done == 1 else 's'}" if isinstance(done, int) else None]
        else:
            steps = (c.get("final_stats") or {}).get("timesteps")
            what = ["DQN", f"{steps} steps" if isinstance(steps, int) else None, self.scenario]
        if c.get("stopped_early"):
            what.append("stopped early")
        return f"{self.name} ({', '.join(w for w in what if w)})"


def agent_model(path: str | os.PathLike[str]) -> str:
    """Which planner a retrained agent file holds: ``"attention"`` (``*.pt``) or ``"dqn"`` (``*.zip``)."""
    return "attention" if Path(path).suffix == ".pt" else "dqn"


def _attention_card(weights: Path) -> dict[str, Any] | None:
    """The card (``card.json``) beside an attention planner's weights, or None if it is not one."""
    try:
        card = json.loads((weights.parent / "card.json").read_text())
    except (OSError, ValueError):
        return None
    return card if isinstance(card, dict) and card.get("model") == "attention" else None


def list_agents(folder: str | os.PathLike[str] | None = None) -> list[AgentInfo]:
    """The agents in ``folder`` (default :func:`agents_dir`), newest first: DQN agents (``*.zip`` with a
    readable model card) and attention planners (``*/attention_planner.pt`` with a ``card.json`` of
    model ``attention`` beside it). Unreadable files are skipped (they are not agents); a missing
    folder gives ``[]``."""
    from uam_studio.planning.agents.attention import WEIGHTS_NAME
    from uam_studio.planning.agents.dqn.agent_file import load_card

    d = Path(folder) if folder is not None else agents_dir()
    if not d.is_dir():
        return []
    out: list[tuple[float, AgentInfo]] = []
    for p in d.glob("*.zip"):
        try:
            card = load_card(p)
            mtime = p.stat().st_mtime
        except (InputError, OSError):
            continue
        if card.get("model") != "dqn":
            continue
        scenario = card.get("scenario") if card.get("scenario") in SCENARIOS else None
        out.append((mtime, AgentInfo(p, p.stem, scenario, card)))
    for p in d.glob(f"*/{WEIGHTS_NAME}"):
        card = _attention_card(p)
        try:
            mtime = p.stat().st_mtime
        except OSError:
            continue
        if card is not None:
            out.append((mtime, AgentInfo(p, p.parent.name, None, card)))
    out.sort(key=lambda t: (-t[0], t[1].name))
    return [a for _, a in out]


_SAFE = re.compile(r"[^A-Za-z0-9_.-]+")


def new_agent_path(scenario: str, source: str, folder: str | os.PathLike[str] | None = None) -> Path:
    """A fresh file name ``<scenario>-<source>-<UTC time>.zip`` in ``folder`` (default :func:`agents_dir`)."""
    d = Path(folder) if folder is not None else agents_dir()
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%d-%H%M%S")
    base = _SAFE.sub("_", f"{scenario}-{source}-{stamp}")
    p, k = d / f"{base}.zip", 1
    while p.exists():
        k += 1
        p = d / f"{base}-{k}.zip"
    return p


# ----------------------------------------------------------------------------- training


def training_setup(
    scenario: str | None = None,
    mission: Mission | None = None,
    alpha: float | None = None,
    beta: float | None = None,
    gamma: float | None = None,
    steps: int | None = None,
    seed: int = 0,
    safe_return: bool = False,
    init_agent: str | os.PathLike[str] | None = None,
) -> tuple[Any, Callable[[], Any]]:
    """Validate the settings of a DQN retraining and build ``(DQNTrainConfig, env_fn)``.

    :param scenario: default: the mission's, else ``single_charge``.
    :param mission: train on this map (the cell's q_max and R0 drawn at random each episode), or
        None for a random mission every episode.
    :param alpha, beta, gamma: reward weights (default :data:`DQN_REWARD_DEFAULTS`), in [0, 1e6].
    :param steps: env transitions (default: :class:`DQNTrainConfig`'s), in [1, 1e7].
    :param safe_return: train with the environment's ``safe_return`` rule (a leg that would leave
        no way home ends the episode with ``-gamma``); off is the paper's setting.
    :param init_agent: fine-tune this agent (zip) instead of starting from random weights: its
        network is copied in and exploration starts at :data:`~uam_studio.planning.agents.dqn.training.FINE_TUNE`
        settings (epsilon 0.2, not 1).
    :raises InputError: bad settings, or a map the environment cannot use (no destinations, more
        than 8, none far enough from the vertiport).
    """
    from uam_studio.planning.agents.dqn.training import DQNTrainConfig, fine_tuning
    from uam_studio.planning.env import make_env

    if scenario is not None:
        check_scenario(scenario)
    scenario = scenario or (mission.scenario if mission is not None else DEFAULT_SCENARIO)
    given = {"alpha": alpha, "beta": beta, "gamma": gamma}
    weights = {k: check_range(k, DQN_REWARD_DEFAULTS[k] if v is None else v, 0.0, 1e6) for k, v in given.items()}
    cfg = DQNTrainConfig(scenario=scenario, seed=int(seed), safe_return=bool(safe_return), **weights)
    if init_agent is not None:
        cfg = fine_tuning(cfg, init_agent)  # fails here, before the env is built, on an unreadable agent
    if steps is not None:
        if isinstance(steps, bool) or int(steps) != steps or not 1 <= int(steps) <= MAX_STEPS:
            raise InputError("steps", f"{steps!r} is out of range; allowed integers in [1, {MAX_STEPS:g}]")
        cfg.steps = int(steps)
    env_kwargs: dict[str, Any] = {"scenario": scenario, "backend": "physics", "safe_return": cfg.safe_return,
                                  **weights}
    if mission is not None:
        env_kwargs.update(mission=mission, randomize_battery=True)
    env_fn = make_env(**env_kwargs)  # bad maps fail here, before training
    return cfg, env_fn


class _Tally:
    """Running count and the last :data:`STATS_WINDOW` episodes."""

    def __init__(self) -> None:
        self.n = 0
        self.last: deque = deque(maxlen=STATS_WINDOW)

    def add(self, e) -> None:
        self.n += 1
        self.last.append(e)

    def final(self, timesteps: int) -> dict[str, Any]:
        last = list(self.last)
        k = len(last)

        def mean(f) -> float | None:
            return float(sum(f(e) for e in last) / k) if k else None

        return {
            "episodes": self.n,
            "timesteps": int(timesteps),
            "last_episodes": k,
            "mean_reward": mean(lambda e: e.reward),
            "mean_reached": mean(lambda e: e.reached),
            "mean_reached_priority": mean(lambda e: e.reached_priority),
            "mean_charging_cycles": mean(lambda e: e.charging_cycles),
            "eod_rate": mean(lambda e: float(e.eod_breach)),
        }


def retrain_dqn(
    config: Any,
    env_fn: Callable[[], Any],
    agent_path: str | os.PathLike[str],
    mission: Mission | None = None,
    on_episode: Callable[[Any], Any] | None = None,
    stop_event: threading.Event | None = None,
    progress_bar: bool = False,
    source: str | None = None,
    card_path: str | os.PathLike[str] | None = None,
) -> RetrainResult | None:
    """Train a DQN agent (:func:`~uam_studio.planning.agents.dqn.training.train_dqn`) and save it with its card.

    :param config: a :class:`~uam_studio.planning.agents.dqn.training.DQNTrainConfig` (see :func:`training_setup`).
    :param env_fn: the env factory from :func:`training_setup`.
    :param agent_path: the agent zip to write (atomically); never inside ``pretrained/``.
    :param mission: the map trained on (recorded in the card), or None for random missions.
    :param on_episode: called with each :class:`~uam_studio.planning.agents.dqn.training.EpisodeStats`, in the
        training thread.
    :param stop_event: set it to stop early; the agent trained so far is saved, with
        ``"stopped_early": true`` in its card, unless it has not finished one episode: then nothing is
        saved (an agent that learned nothing is not an agent) and None is returned.
    :param source: a short note on where the run came from (``"cli"``, ``"app"``), kept in the card.
    :param card_path: also write the card as this JSON file, consistent with the agent (see
        :func:`~uam_studio.planning.agents.dqn.agent_file.save_agent`).
    :raises InputError: ``agent_path`` inside ``pretrained/``.

    Stale temp files left in the agent's folder by killed saves are deleted before training.
    """
    from uam_studio import __version__ as version
    from uam_studio.planning.agents.dqn.agent_file import save_agent
    from uam_studio.planning.agents.dqn.training import train_dqn
    from uam_studio.planning.env import OBS_DIM

    agent = Path(agent_path)
    if is_bundled(agent):
        raise InputError("agent_path", f"{agent}: must not be in the bundled pretrained/ folder")
    remove_stale_temps(agent.parent)
    tally = _Tally()

    def _on_episode(e) -> None:
        tally.add(e)
        if on_episode is not None:
            on_episode(e)

    started = datetime.datetime.now(datetime.timezone.utc)
    t0 = time.perf_counter()
    model = train_dqn(config, env_fn, callback=_on_episode, stop_event=stop_event, progress_bar=progress_bar)
    wall_s = time.perf_counter() - t0
    stopped = bool(stop_event is not None and stop_event.is_set() and model.num_timesteps < config.steps)
    if stopped and tally.n == 0:
        return None
    card = {
        "model": "dqn",
        "uam_studio_version": version,
        "scenario": config.scenario,
        "health": "fallback",  # physics-only health features (no Dynaformer), see planning.env.fallback_health
        "config": config.to_dict(),
        "env": {"mission": mission_to_dict(mission) if mission is not None else None,
                "randomize_battery": mission is not None, "backend": "physics",
                "obs_dim": OBS_DIM},
        "timing": {"started_utc": started.isoformat(timespec="seconds"), "wall_s": round(wall_s, 2),
                   "steps_per_s": round(model.num_timesteps / wall_s, 1) if wall_s > 0 else None},
        "final_stats": tally.final(model.num_timesteps),
        "stopped_early": stopped,
    }
    if source is not None:
        card["source"] = source
    save_agent(model, agent, card, card_file=card_path)
    return RetrainResult(agent, card, tally.n, int(model.num_timesteps), stopped, model)


# ----------------------------------------------------------------------------- in a child process


def _process_main(kind: str, setup: dict[str, Any], agent_path: str, mission: Mission | None, out: Any,
                  stop: Any, source: str | None, nice: int, pause: Any, max_pause_s: float) -> None:
    """Entry point of :class:`RetrainProcess`'s child: train, save, report on ``out``."""
    try:
        os.nice(nice)
    except (AttributeError, OSError):  # not on this platform / not allowed
        pass

    def on_episode(e: Any) -> None:
        out.put(e)
        if pause is not None:  # give way while the parent asks for it (at most max_pause_s per episode)
            t0 = time.monotonic()
            while pause.is_set() and not stop.is_set() and time.monotonic() - t0 < max_pause_s:
                time.sleep(0.005)

    try:
        import torch

        torch.set_num_threads(1)
        if kind == "attention":
            from uam_studio.planning.agents.attention.retrain import attention_setup, retrain_attention

            init = setup.pop("init_agent", None)
            res = retrain_attention(attention_setup(**setup), Path(agent_path).parent, mission=mission,
                                    on_epoch=on_episode, on_progress=lambda *p: out.put(("progress", *p)),
                                    stop_event=stop, source=source, init_weights=init)
            out.put(res if res is not None else ("nothing saved",))
            return
        cfg, env_fn = training_setup(mission=mission, **setup)
        res = retrain_dqn(cfg, env_fn, agent_path, mission=mission, on_episode=on_episode, stop_event=stop,
                          source=source)
        out.put(RetrainResult(res.path, res.card, res.episodes, res.timesteps, res.stopped) if res is not None
                else ("nothing saved",))
    except BaseException as err:  # reported to the parent; nothing is raised in the child
        out.put(("error", f"{type(err).__name__}: {' '.join(str(err).split())}"))


class RetrainProcess:
    """:func:`retrain_dqn` in a child process (``spawn``), streaming :class:`EpisodeStats` back (with
    ``kind="attention"``: :func:`~uam_studio.planning.agents.attention.retrain.retrain_attention`,
    streaming :class:`~uam_studio.planning.agents.attention.train.EpochStats`).

    Training in a thread of a server competes with its sessions for the GIL; a child process does
    not, and runs at a lower CPU priority (``nice``) with one torch thread. The settings are
    validated here, in the parent (:func:`training_setup` raises :class:`InputError`).

    :param agent_path: the agent zip to write (never inside ``pretrained/``); for the attention planner,
        its weights file ``<new folder>/attention_planner.pt``.
    :param mission: the map to train on, or None for random missions (the attention planner trains
        on random missions and scores each epoch's network on this map).
    :param nice: niceness added in the child (0 for none).
    :param pause_event: a ``multiprocessing`` Event (of the ``spawn`` context); while it is set the
        child pauses between episodes (at most ``max_pause_s`` per episode). A server sets it while
        its sessions plan, so that training gives way even where niceness cannot help (a server
        that itself runs niced, a machine busy with other work).
    :param kind: ``"dqn"`` or ``"attention"``.
    :param setup: ``scenario``, ``alpha``, ``beta``, ``gamma``, ``steps``, ``seed``, ``init_agent`` of
        :func:`training_setup`; for the attention planner ``missions``, ``epochs``, ``seed`` of
        :func:`~uam_studio.planning.agents.attention.retrain.attention_setup` and ``init_agent`` (a
        weights file to start from).
    """

    def __init__(self, agent_path: str | os.PathLike[str], mission: Mission | None = None,
                 source: str | None = "app", nice: int = 10, pause_event: Any = None, max_pause_s: float = 2.0,
                 kind: str = "dqn", **setup: Any) -> None:
        if kind not in ("dqn", "attention"):
            raise InputError("kind", f"{kind!r}: allowed dqn, attention")
        if is_bundled(agent_path):
            raise InputError("agent_path", f"{agent_path}: must not be in the bundled pretrained/ folder")
        if kind == "attention":
            from uam_studio.planning.agents.attention.retrain import attention_setup

            self.config = attention_setup(**{k: v for k, v in setup.items() if k != "init_agent"})
        else:
            self.config, _ = training_setup(mission=mission, **setup)
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
