"""Training API for the masked DQN planner (used by the CLI and the Panel app).

Public API:

- :class:`DQNTrainConfig`: every setting of a training run (also what a model card records).
- :func:`train_dqn`: train a :class:`~uam_studio.planning.agents.dqn.masked.MaskedDQN` on ``n_envs`` copies of an
  env, streaming one :class:`EpisodeStats` per finished episode, stoppable with a ``threading.Event``.
- :class:`EpisodeStatsCallback`, :class:`TqdmCallback`: the SB3 callbacks behind it.
- :func:`fine_tuning`: a config that starts from a saved agent's weights (:data:`FINE_TUNE` exploration).

The agent file (save, load, model card) is :mod:`uam_studio.planning.agents.dqn.agent_file`; acting with a
trained agent is :func:`~uam_studio.planning.agents.dqn.masked.greedy_action` and
:func:`~uam_studio.planning.agents.dqn.masked.ranked_actions`.

Env convention (see :mod:`uam_studio.planning.agents.dqn.masked`): flat ``Box`` observations whose last
``action_space.n`` entries are the action mask; ``info`` on each step has ``reached`` (list of
destination names), ``charging_cycles`` (int), ``eod`` (bool), optionally ``reached_priority``.
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import HumanOutputFormat, Logger
from stable_baselines3.common.vec_env import DummyVecEnv

from uam_studio.errors import InputError
from uam_studio.planning.agents.dqn.agent_file import load_agent
from uam_studio.planning.agents.dqn.masked import MaskedDQN, MaskedDQNPolicy
from uam_studio.planning.agents.vec_env import GroupedSubprocVecEnv
from uam_studio.planning.env.environment import REWARD_DEFAULTS
from uam_studio.planning.missions.scenario import DEFAULT_SCENARIO

__all__ = [
    "DQNTrainConfig",
    "EpisodeStats",
    "FINE_TUNE",
    "EpisodeStatsCallback",
    "TqdmCallback",
    "fine_tuning",
    "train_dqn",
]

@dataclass
class DQNTrainConfig:
    """Settings of one DQN training run.

    Mission episodes are short (about 10 decisions), so the Atari defaults of SB3 (1e6 buffer, target
    update every 1e4 steps, 10% exploration) are far off. These start from the rl-zoo CartPole DQN
    settings (lr 2.3e-3, net 256x256, learning_starts 1000, gamma 0.99), scaled to ~10-step episodes.

    ``scenario``, ``alpha``, ``beta``, ``gamma`` describe the environment (reward per destination times
    priority, charging-stop penalty, EOD-breach penalty); the caller's ``env_fn`` builds it from them and
    they are recorded in the model card. ``gamma_discount`` is the RL discount factor.
    """

    scenario: str = DEFAULT_SCENARIO
    steps: int = 50_000  # total env transitions (all envs together); ~5,000 episodes of ~10 steps
    alpha: float = REWARD_DEFAULTS["alpha"]
    beta: float = REWARD_DEFAULTS["beta"]
    gamma: float = REWARD_DEFAULTS["gamma"]
    seed: int = 0
    n_envs: int = 4  # env copies: decorrelates consecutive samples
    n_workers: int = 1  # 1: all copies here (DummyVecEnv); >= 2: GroupedSubprocVecEnv processes (on 2 cores
    # slower for DQN: the gradient steps compete with the workers; RESULTS.md, "Planning")
    learning_rate: float = 1e-3  # Adam; rl-zoo CartPole uses 2.3e-3, a bit lower is steadier here
    buffer_size: int = 50_000  # holds the whole run at the default budget: small episodes, no staleness issue
    learning_starts: int = 1000  # ~100 random (masked) episodes before the first update
    batch_size: int = 128
    target_update_interval: int = 1000  # env transitions (SB3 divides by n_envs): ~100 episodes, not 10k
    train_freq: int = 4  # vec-env steps between updates, i.e. 4 * n_envs transitions
    gradient_steps: int = 4  # one gradient step per 4 transitions with n_envs=4
    exploration_initial_eps: float = 1.0  # epsilon at the start (lower it to fine-tune a trained agent)
    exploration_fraction: float = 0.3  # epsilon initial -> final over the first 30% of steps
    exploration_final_eps: float = 0.05
    gamma_discount: float = 0.99  # ~10-step episodes: terminal rewards stay visible at the first decision
    net_arch: tuple[int, ...] = (256, 256)
    double_dqn: bool = True  # less over-estimation of the max; cheap
    safe_return: bool = False  # env option: a leg that leaves no way home ends the episode with -gamma
    init_agent: str | None = None  # warm start: copy this agent zip's network weights (same net_arch)
    random_warmup: bool = True  # the first learning_starts transitions: uniform valid actions (False: the network's)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["net_arch"] = list(self.net_arch)
        return d


@dataclass(frozen=True)
class EpisodeStats:
    """One finished training episode.

    :param episode: 1-based episode counter over the run (all envs)
    :param timestep: total env transitions when the episode ended
    :param reward: undiscounted episode return
    :param reached: number of destinations reached
    :param reached_priority: sum of reached priorities (``info["reached_priority"]`` if the env gives it,
        else the count)
    :param charging_cycles: charging cycles used
    :param eod_breach: the battery went below EOD at some step
    :param length: number of steps
    """

    episode: int
    timestep: int
    reward: float
    reached: int
    reached_priority: float
    charging_cycles: int
    eod_breach: bool
    length: int


class EpisodeStatsCallback(BaseCallback):
    """SB3 callback: one :class:`EpisodeStats` per finished episode, and a cooperative stop.

    :param on_episode: called with each :class:`EpisodeStats` (or None)
    :param stop_event: when set, training stops at the next env step (``_on_step`` returns False)
    :param keep: keep the stats in :attr:`episodes` as well
    """

    def __init__(self, on_episode: Callable[[EpisodeStats], Any] | None = None,
                 stop_event: threading.Event | None = None, keep: bool = True, verbose: int = 0) -> None:
        super().__init__(verbose)
        self.on_episode = on_episode
        self.stop_event = stop_event
        self.keep = keep
        self.episodes: list[EpisodeStats] = []
        self.n_episodes = 0
        self._ret: np.ndarray | None = None
        self._len: np.ndarray | None = None
        self._eod: np.ndarray | None = None
        self._reached: list[set[str]] = []

    def _init_callback(self) -> None:
        n = self.training_env.num_envs if self.training_env is not None else 1
        self._ret = np.zeros(n)
        self._len = np.zeros(n, dtype=int)
        self._eod = np.zeros(n, dtype=bool)
        self._reached = [set() for _ in range(n)]

    def _on_step(self) -> bool:
        rewards = np.asarray(self.locals["rewards"], dtype=float).reshape(-1)
        dones = np.asarray(self.locals["dones"]).reshape(-1)
        infos = self.locals["infos"]
        assert self._ret is not None and self._len is not None and self._eod is not None
        self._ret += rewards
        self._len += 1
        for i, info in enumerate(infos):
            self._eod[i] |= bool(info.get("eod", False))
            # Union over the episode: right whether the env reports cumulative or per-step names.
            self._reached[i].update(info.get("reached", ()) or ())
            if dones[i]:
                self._finish(i, info)
        return not (self.stop_event is not None and self.stop_event.is_set())

    def _finish(self, i: int, info: dict[str, Any]) -> None:
        assert self._ret is not None and self._len is not None and self._eod is not None
        self.n_episodes += 1
        reached = len(self._reached[i])
        prio = info.get("reached_priority")
        stats = EpisodeStats(
            episode=self.n_episodes,
            timestep=int(self.num_timesteps),
            reward=float(self._ret[i]),
            reached=reached,
            reached_priority=float(prio) if prio is not None else float(reached),
            charging_cycles=int(info.get("charging_cycles", 0)),
            eod_breach=bool(self._eod[i]),
            length=int(self._len[i]),
        )
        self._ret[i], self._len[i], self._eod[i] = 0.0, 0, False
        self._reached[i] = set()
        if self.keep:
            self.episodes.append(stats)
        if self.on_episode is not None:
            self.on_episode(stats)


class TqdmCallback(BaseCallback):
    """A tqdm progress bar over env transitions (SB3's own ``progress_bar`` needs ``rich``)."""

    def __init__(self, desc: str = "DQN") -> None:
        super().__init__()
        self.desc = desc
        self.bar: Any = None

    def _on_training_start(self) -> None:
        from tqdm.auto import tqdm

        total = int(self.locals.get("total_timesteps", 0)) - int(self.model.num_timesteps)
        self.bar = tqdm(total=max(total, 0), desc=self.desc, unit="step")

    def _on_step(self) -> bool:
        if self.bar is not None:
            self.bar.update(self.training_env.num_envs if self.training_env is not None else 1)
        return True

    def _on_training_end(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def train_dqn(
    config: DQNTrainConfig,
    env_fn: Callable[[], gym.Env],
    callback: Callable[[EpisodeStats], Any] | None = None,
    stop_event: threading.Event | None = None,
    progress_bar: bool = False,
    verbose: int = 0,
) -> MaskedDQN:
    """Train a masked DQN on ``config.n_envs`` copies of ``env_fn()`` for ``config.steps`` transitions.

    :param config: the run's settings
    :param env_fn: builds one environment (called ``n_envs`` times; each copy gets seed ``config.seed + i``)
    :param callback: called with an :class:`EpisodeStats` after every finished episode (in the training
        thread; keep it quick)
    :param stop_event: set it from another thread to stop training cleanly at the next env step; the
        model trained so far is returned
    :param progress_bar: show a tqdm progress bar
    :param verbose: SB3 verbosity (0 silent, 1 rollout/train tables)
    :return: the trained :class:`~uam_studio.planning.agents.dqn.masked.MaskedDQN` (greedy use: :func:`greedy_action`)
    """
    if config.steps < 1:
        raise InputError("steps", f"{config.steps!r} is out of range; allowed >= 1")
    if config.n_envs < 1:
        raise InputError("n_envs", f"{config.n_envs!r} is out of range; allowed >= 1")
    if not 1 <= config.n_workers <= config.n_envs:
        raise InputError("n_workers", f"{config.n_workers!r} is out of range; allowed 1 to n_envs ({config.n_envs})")
    in_process = config.n_workers == 1
    vec_env = make_vec_env(env_fn, n_envs=config.n_envs, seed=config.seed,
                           # SB3 annotates vec_env_cls as DummyVecEnv | SubprocVecEnv, but calls any VecEnv class
                           vec_env_cls=DummyVecEnv if in_process else GroupedSubprocVecEnv,  # type: ignore[arg-type]
                           vec_env_kwargs=None if in_process else {"n_workers": config.n_workers})
    try:
        model = MaskedDQN(
            MaskedDQNPolicy,
            vec_env,
            learning_rate=config.learning_rate,
            buffer_size=config.buffer_size,
            learning_starts=config.learning_starts,
            batch_size=config.batch_size,
            gamma=config.gamma_discount,
            train_freq=config.train_freq,
            gradient_steps=config.gradient_steps,
            target_update_interval=config.target_update_interval,
            exploration_initial_eps=config.exploration_initial_eps,
            exploration_fraction=config.exploration_fraction,
            exploration_final_eps=config.exploration_final_eps,
            policy_kwargs={"net_arch": list(config.net_arch)},
            double_dqn=config.double_dqn,
            random_warmup=config.random_warmup,
            seed=config.seed,
            device="cpu",
            verbose=verbose,
        )
        if config.init_agent is not None:
            _warm_start(model, config.init_agent)
        # SB3's default logger makes an empty tempdir/SB3-<time> folder per run: log to stdout or nowhere
        model.set_logger(Logger(folder=None, output_formats=[HumanOutputFormat(sys.stdout)] if verbose else []))
        callbacks: list[BaseCallback] = [EpisodeStatsCallback(callback, stop_event, keep=False)]
        if progress_bar:
            callbacks.append(TqdmCallback())
        if stop_event is None or not stop_event.is_set():
            model.learn(total_timesteps=config.steps, callback=CallbackList(callbacks))
    finally:
        if not in_process:
            vec_env.close()  # the worker processes end with the run (or its error); the model keeps its weights
    return model


# Exploration and warm-up of a fine-tuning run (``init_agent``): the agent already plans, so it
# explores a little around its own choices, warm-up included, instead of starting from uniform
# random actions (which made a fine-tuning run start as badly as random weights).
FINE_TUNE: dict[str, Any] = {"exploration_initial_eps": 0.2, "exploration_fraction": 0.2, "exploration_final_eps": 0.02,
                             "learning_starts": 500, "random_warmup": False}


def _load_init_agent(agent_path: str | os.PathLike[str]) -> MaskedDQN:
    """:func:`load_agent`, with its errors reported under the field ``init_agent``."""
    try:
        return load_agent(agent_path)
    except InputError as err:
        raise InputError("init_agent", str(err).split(": ", 1)[-1]) from None


def fine_tuning(config: DQNTrainConfig, init_agent: str | os.PathLike[str]) -> DQNTrainConfig:
    """``config`` set to fine-tune ``init_agent`` (a saved agent zip): its weights are copied in by
    :func:`train_dqn`, with the :data:`FINE_TUNE` exploration (epsilon from 0.2, not 1).

    :raises InputError: (field ``init_agent``) a missing or unreadable agent, checked now
    """
    _load_init_agent(init_agent)
    return replace(config, init_agent=str(init_agent), **FINE_TUNE)


def _warm_start(model: MaskedDQN, agent_path: str | os.PathLike[str]) -> None:
    """Copy the Q-network (and target network) weights of a saved agent into ``model``.

    :raises InputError: (field ``init_agent``) an unreadable agent, or one whose spaces or network
        shape differ from ``model``'s
    """
    src = _load_init_agent(agent_path)
    if src.observation_space != model.observation_space or src.action_space != model.action_space:
        raise InputError("init_agent", f"{agent_path}: incompatible agent (observations "
                                       f"{src.observation_space.shape}, {src.action_space})")
    theirs, ours = src.policy.state_dict(), model.policy.state_dict()
    if {k: v.shape for k, v in theirs.items()} != {k: v.shape for k, v in ours.items()}:
        raise InputError("init_agent", f"{agent_path}: network shape differs from net_arch "
                                       f"{list(model.policy.net_arch)}")
    model.policy.load_state_dict(theirs)
