"""Training API for the masked DQN planner (used by the CLI and the Panel app).

Public API:

- :class:`DQNTrainConfig`: every setting of a training run (also what a model card records).
- :func:`train_dqn`: train a :class:`~uam_studio.planning.agents.dqn.MaskedDQN` on ``n_envs`` copies of an
  env, streaming one :class:`EpisodeStats` per finished episode, stoppable with a ``threading.Event``.
- :class:`EpisodeStatsCallback`, :class:`TqdmCallback`: the SB3 callbacks behind it.
- :func:`save_agent` (atomic, with a model card inside the zip), :func:`load_agent`, :func:`load_card`.
- :func:`greedy_action`: the deterministic masked action for one observation.

Env convention (see :mod:`uam_studio.planning.agents.dqn`): flat ``Box`` observations whose last
``action_space.n`` entries are the action mask; ``info`` on each step has ``reached`` (list of
destination names), ``charging_cycles`` (int), ``eod`` (bool), optionally ``reached_priority``.

Loading never unpickles: :func:`load_agent` checks the zip's entry names, reads SB3's ``data`` entry
as plain JSON (its ``":serialized:"`` values are never decoded), rebuilds the network from the model
card or the JSON's readable fields, and loads the weights with ``torch.load(weights_only=True)``.
"""

from __future__ import annotations

import io
import json
import os
import threading
import zipfile
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv

from uam_studio.atomic_io import atomic_write_bytes
from uam_studio.errors import InputError
from uam_studio.planning.agents.dqn import MaskedDQN, MaskedDQNPolicy
from uam_studio.planning.agents.vec_env import GroupedSubprocVecEnv
from uam_studio.planning.env.environment import REWARD_DEFAULTS

__all__ = [
    "CARD_NAME",
    "DQNTrainConfig",
    "EpisodeStats",
    "FINE_TUNE",
    "EpisodeStatsCallback",
    "TqdmCallback",
    "fine_tuning",
    "greedy_action",
    "ranked_actions",
    "load_agent",
    "load_card",
    "network_description",
    "save_agent",
    "train_dqn",
]

CARD_NAME = "card.json"
"""Name of the model card inside an agent zip."""
NETWORK_KEY = "network"
"""Model card entry describing the network (:func:`network_description`)."""
AGENT_ENTRIES = ("data", "policy.pth")
"""Zip entries every agent file has: SB3's settings (JSON) and the policy's weights (tensors only)."""
OPTIONAL_AGENT_ENTRIES = ("policy.optimizer.pth", "pytorch_variables.pth", "_stable_baselines3_version",
                          "system_info.txt", CARD_NAME)
"""Zip entries an agent file may also have (the rest of what SB3's ``save`` and :func:`save_agent`
write). :func:`load_agent` refuses a zip with any other entry."""
MAX_ENTRY_BYTES = 256 * 2**20  # uncompressed size of one zip entry, bytes
FORMAT = "uam_studio.dqn/1"


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

    scenario: str = "single_charge"
    steps: int = 50_000  # total env transitions (all envs together); ~5,000 episodes of ~10 steps
    alpha: float = REWARD_DEFAULTS["alpha"]
    beta: float = REWARD_DEFAULTS["beta"]
    gamma: float = REWARD_DEFAULTS["gamma"]
    seed: int = 0
    n_envs: int = 4  # env copies: decorrelates consecutive samples
    n_workers: int = 1  # 1: all copies here (DummyVecEnv); >= 2: GroupedSubprocVecEnv processes (on 2 cores
    # slower for DQN: the gradient steps compete with the workers; benchmarks/RESULTS.md)
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
    :return: the trained :class:`~uam_studio.planning.agents.dqn.MaskedDQN` (greedy use: :func:`greedy_action`)
    """
    if config.steps < 1:
        raise InputError("steps", f"{config.steps!r} is out of range; allowed >= 1")
    if config.n_envs < 1:
        raise InputError("n_envs", f"{config.n_envs!r} is out of range; allowed >= 1")
    if not 1 <= config.n_workers <= config.n_envs:
        raise InputError("n_workers", f"{config.n_workers!r} is out of range; allowed 1 to n_envs ({config.n_envs})")
    in_process = config.n_workers == 1
    vec_env = make_vec_env(env_fn, n_envs=config.n_envs, seed=config.seed,
                           vec_env_cls=DummyVecEnv if in_process else GroupedSubprocVecEnv,
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
FINE_TUNE = {"exploration_initial_eps": 0.2, "exploration_fraction": 0.2, "exploration_final_eps": 0.02,
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


def greedy_action(model: MaskedDQN, obs: np.ndarray) -> int:
    """The deterministic masked action for one observation ``(obs_dim,)``.

    :raises ValueError: if the observation's mask has no valid action
    """
    obs = np.asarray(obs, dtype=np.float32)
    n = int(model.action_space.n)  # type: ignore[attr-defined]
    if not (obs.reshape(-1)[-n:] > 0.5).any():
        raise ValueError("no valid action in this observation's mask")
    action, _ = model.predict(obs, deterministic=True)
    return int(np.asarray(action).reshape(-1)[0])


def ranked_actions(model: MaskedDQN, obs: np.ndarray) -> np.ndarray:
    """The valid actions of one observation ``(obs_dim,)``, best Q-value first (empty if none is valid)."""
    import torch as th

    obs = np.asarray(obs, dtype=np.float32).reshape(1, -1)
    n = int(model.action_space.n)  # type: ignore[attr-defined]
    valid = np.flatnonzero(obs[0, -n:] > 0.5)
    with th.no_grad():
        q = model.policy.q_net(th.as_tensor(obs, device=model.device)).cpu().numpy()[0]
    return valid[np.argsort(-q[valid], kind="stable")]


def save_agent(model: MaskedDQN, path: str | os.PathLike[str], card: dict[str, Any],
               card_file: str | os.PathLike[str] | None = None) -> None:
    """Save ``model`` and its model ``card`` (JSON-serialisable dict) as one SB3 zip, atomically.

    The SB3 zip is built in memory with the card added as ``card.json``, then written with
    :func:`uam_studio.atomic_io.atomic_write_bytes` (creating the folder): a kill never leaves a
    half-written agent. The replay buffer is not saved. The card gets a ``network`` entry
    (:func:`network_description`: spaces and layer sizes), which :func:`load_agent` builds the network from.

    :param card_file: also write the card as this JSON file beside the agent, as a sidecar of the
        zip: the old one is deleted before the agent is replaced and the new one written after, so
        an existing card file always describes the agent beside it.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    card_json = json.dumps({"format": FORMAT, **card, NETWORK_KEY: network_description(model)}, indent=2,
                           sort_keys=True, default=str)
    buf = io.BytesIO()
    model.save(buf)
    with zipfile.ZipFile(buf, mode="a") as zf:
        zf.writestr(CARD_NAME, card_json)
    sidecars = {card_file: json.dumps(card, indent=2, default=str) + "\n"} if card_file is not None else None
    atomic_write_bytes(p, buf.getvalue(), sidecars=sidecars)


def _read_agent_bytes(path: str | os.PathLike[str]) -> tuple[Path, bytes]:
    p = Path(path)
    if not p.is_file():
        raise InputError("agent", f"{p}: file not found")
    data = p.read_bytes()
    if not zipfile.is_zipfile(io.BytesIO(data)):
        raise InputError("agent", f"{p}: not a DQN agent file (not a zip archive)")
    return p, data


def load_card(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The model card saved with an agent by :func:`save_agent` (``{}`` for a plain SB3 zip).

    :raises InputError: (field ``agent``) for a missing or unreadable file
    """
    p, data = _read_agent_bytes(path)
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            if CARD_NAME not in zf.namelist():
                return {}
            card = json.loads(zf.read(CARD_NAME).decode())
    except Exception as exc:
        raise InputError("agent", f"{p}: unreadable model card ({type(exc).__name__})") from None
    if not isinstance(card, dict):
        raise InputError("agent", f"{p}: model card is not a JSON object")
    return card


def network_description(model: MaskedDQN) -> dict[str, Any]:
    """What :func:`load_agent` rebuilds ``model``'s network from, as plain JSON: the policy class name,
    ``net_arch`` (hidden layer widths), the observation space (flat ``Box``: shape, dtype, bounds) and
    the action space (``Discrete``: n, start)."""
    obs, act = model.observation_space, model.action_space
    return {
        "policy_class": type(model.policy).__name__,
        "net_arch": [int(w) for w in model.policy.net_arch],
        "observation_space": {"type": "Box", "shape": list(obs.shape), "dtype": str(obs.dtype),
                              "low": obs.low.tolist(), "high": obs.high.tolist()},  # type: ignore[attr-defined]
        "action_space": {"type": "Discrete", "n": int(act.n), "start": int(act.start)},  # type: ignore[attr-defined]
    }


def _short(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters (one line: repr escapes newlines)."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


_SERIALIZED = ":serialized:"
# Keys of SB3's ``data`` JSON that SB3 stores pickled (as ":serialized:"). They are never decoded; any
# other pickled key refuses the file.
_SERIALIZED_KEYS = frozenset({
    "policy_class", "observation_space", "action_space", "_last_obs", "_last_episode_starts",
    "_last_original_obs", "ep_info_buffer", "ep_success_buffer", "replay_buffer_class", "train_freq",
    "lr_schedule", "exploration_schedule", "learning_rate", "action_noise",
})
_BOX_TYPES = ("Box", "<class 'gymnasium.spaces.box.Box'>")  # card, SB3 data
_DISCRETE_TYPES = ("Discrete", "<class 'gymnasium.spaces.discrete.Discrete'>")
# Plain settings of SB3's ``data`` JSON passed to MaskedDQN(...): kind and allowed range.
_SETTINGS: dict[str, tuple[type, float, float]] = {
    "learning_rate": (float, 0.0, 1e3), "buffer_size": (int, 1, 10**7), "learning_starts": (int, 0, 10**12),
    "batch_size": (int, 1, 10**6), "tau": (float, 0.0, 1.0), "gamma": (float, 0.0, 1.0),
    "gradient_steps": (int, -1, 10**6), "optimize_memory_usage": (bool, 0, 1), "n_steps": (int, 1, 1000),
    "target_update_interval": (int, 1, 10**12), "exploration_fraction": (float, 0.0, 1.0),
    "exploration_initial_eps": (float, 0.0, 1.0), "exploration_final_eps": (float, 0.0, 1.0),
    "max_grad_norm": (float, 0.0, 1e12), "double_dqn": (bool, 0, 1), "seed": (int, 0, 2**32 - 1),
    "random_warmup": (bool, 0, 1),
}
# Plain training counters of SB3's ``data`` JSON, set on the model after it is built.
_COUNTERS: dict[str, tuple[type, float, float]] = {
    "num_timesteps": (int, 0, 10**15), "_total_timesteps": (int, 0, 10**15),
    "_num_timesteps_at_start": (int, 0, 10**15), "_episode_num": (int, 0, 10**15), "_n_updates": (int, 0, 10**15),
    "_n_calls": (int, 0, 10**15), "exploration_rate": (float, 0.0, 1.0),
    "_current_progress_remaining": (float, -1e6, 1.0),  # below 0 when the last vec-env step overshoots
}


def _plain_values(p: Path, data: dict[str, Any], spec: dict[str, tuple[type, float, float]]) -> dict[str, Any]:
    """The keys of ``spec`` that ``data`` holds as plain JSON values (pickled or null ones are left out).

    :raises InputError: (field ``agent``) a plain value of the wrong type or out of its range
    """
    out: dict[str, Any] = {}
    for key, (kind, lo, hi) in spec.items():
        v = data.get(key)
        if v is None or (isinstance(v, dict) and _SERIALIZED in v):
            continue
        if kind is bool:
            ok = isinstance(v, bool)
        elif kind is int:
            ok = isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi
        else:
            ok = isinstance(v, (int, float)) and not isinstance(v, bool) and lo <= v <= hi  # NaN fails too
            v = float(v) if ok else v
        if not ok:
            raise InputError("agent", f"{p}: corrupted agent file (setting {key} = {_short(v)})")
        out[key] = v
    return out


def _int_field(v: Any, lo: int, hi: int) -> int | None:
    """``v`` (an int, or an int written as text by SB3) if it is in [lo, hi], else None."""
    if isinstance(v, bool) or not isinstance(v, (int, str)):
        return None
    try:
        i = int(v)
    except ValueError:
        return None
    return i if lo <= i <= hi else None


def _float_vector(v: Any, n: int, dtype: np.dtype) -> np.ndarray | None:
    """A 1-D array of ``n`` numbers from a JSON list or from numpy's text of one (as SB3 writes it), else None."""
    if isinstance(v, str):
        text = v.strip()
        if not (text.startswith("[") and text.endswith("]")) or "[" in text[1:-1] or "..." in text:
            return None  # not 1-D, or numpy's summary of a long array
        try:
            vals = [float(x) for x in text[1:-1].split()]
        except ValueError:
            return None
    elif isinstance(v, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        vals = [float(x) for x in v]
    else:
        return None
    return np.array(vals, dtype=dtype) if len(vals) == n else None


def _spaces(p: Path, obs: Any, act: Any) -> tuple[gym.spaces.Box, gym.spaces.Discrete]:
    """The observation (flat ``Box``) and action (``Discrete``) spaces from their plain description:
    the card's (:func:`network_description`) or the readable fields SB3 writes beside a pickled space.

    :raises InputError: (field ``agent``) a description that is missing or not a flat Box / Discrete
    """
    from gymnasium import spaces

    def bad(what: str) -> InputError:
        return InputError("agent", f"{p}: incompatible agent (cannot read its {what}; a masked DQN needs "
                                   "a flat Box observation space and a Discrete action space)")

    if not isinstance(obs, dict) or (obs.get("type") or obs.get(":type:")) not in _BOX_TYPES:
        raise bad("observation space")
    shape = obs.get("shape", obs.get("_shape"))
    dtype = obs.get("dtype")
    if not (isinstance(shape, list) and len(shape) == 1 and dtype in ("float32", "float64")):
        raise bad("observation space")
    n_obs = _int_field(shape[0], 1, 10**7)
    if n_obs is None:
        raise bad("observation space")
    low, high = (_float_vector(obs.get(k), n_obs, np.dtype(dtype)) for k in ("low", "high"))
    if low is None or high is None or not bool(np.all(low <= high)):
        raise bad("observation space")
    if not isinstance(act, dict) or (act.get("type") or act.get(":type:")) not in _DISCRETE_TYPES:
        raise bad("action space")
    n_act, start = _int_field(act.get("n"), 1, 10**6), _int_field(act.get("start", 0), -10**9, 10**9)
    if n_act is None or start is None:
        raise bad("action space")
    return spaces.Box(low, high, shape=(n_obs,), dtype=np.dtype(dtype)), spaces.Discrete(n_act, start=start)


# The policy's module as SB3 records it: today's, and uam_studio.planning.dqn (agents saved before the
# planning package was split into rooms, the bundled ones among them).
_OWN_POLICY_MODULES = (MaskedDQNPolicy.__module__, "uam_studio.planning.dqn")


def _policy_class_name(pc: Any) -> str:
    """The class name in the readable fields SB3 writes beside a pickled policy class (its methods'
    reprs, ``<function Name.method at ...>``), prefixed by its module unless that is this package's
    :mod:`~uam_studio.planning.agents.dqn`; ``"unknown"`` if there is none."""
    if not isinstance(pc, dict):
        return "unknown"
    names = [v[len("<function "):].split(".", 1)[0] for v in pc.values()
             if isinstance(v, str) and v.startswith("<function ") and "." in v]
    if not names:
        return "unknown"
    module = pc.get("__module__")
    return names[0] if module in _OWN_POLICY_MODULES else f"{module}.{names[0]}"


def _zip_entries(p: Path, zf: zipfile.ZipFile) -> set[str]:
    """The entry names of an agent zip, after checking them (nothing is decompressed here).

    :raises InputError: (field ``agent``) an entry that is not one of :data:`AGENT_ENTRIES` and
        :data:`OPTIONAL_AGENT_ENTRIES`, a duplicate or oversized entry, or a missing required one
    """
    infos = zf.infolist()
    names = [i.filename for i in infos]
    allowed = (*AGENT_ENTRIES, *OPTIONAL_AGENT_ENTRIES)
    extra = [n for n in names if n not in allowed]
    if extra:
        raise InputError("agent", f"{p}: refused: unexpected entry {_short(extra[0], 40)} in the agent zip "
                                  f"(allowed: {', '.join(allowed)}); nothing in it was loaded")
    if len(set(names)) != len(names):
        raise InputError("agent", f"{p}: refused: duplicate entries in the agent zip; nothing in it was loaded")
    big = [i.filename for i in infos if i.file_size > MAX_ENTRY_BYTES]
    if big:
        raise InputError("agent", f"{p}: refused: entry {big[0]!r} is over {MAX_ENTRY_BYTES // 2**20} MiB")
    missing = [n for n in AGENT_ENTRIES if n not in names]
    if missing:
        raise InputError("agent", f"{p}: not a DQN agent file (no {missing[0]!r} entry)")
    return set(names)


def _read_json_entry(p: Path, zf: zipfile.ZipFile, name: str) -> dict[str, Any]:
    """Entry ``name`` parsed as a JSON object (plain JSON: nothing in it is decoded further)."""
    try:
        obj = json.loads(zf.read(name))
    except Exception as exc:
        raise InputError("agent", f"{p}: corrupted agent file ({name}: {type(exc).__name__})") from None
    if not isinstance(obj, dict):
        raise InputError("agent", f"{p}: corrupted agent file ({name} is not a JSON object)")
    return obj


def _read_tensors_entry(p: Path, zf: zipfile.ZipFile, name: str) -> dict[str, Any]:
    """Entry ``name`` loaded with :func:`uam_studio.tensor_files.load_tensors` (``torch.load(weights_only=True)``:
    tensors, numbers, strings, containers only; anything else is refused before it is built)."""
    from uam_studio.tensor_files import TensorFileError, load_tensors

    try:
        raw = zf.read(name)
    except Exception as exc:
        raise InputError("agent", f"{p}: corrupted agent file ({name}: {type(exc).__name__})") from None
    try:
        obj = load_tensors(io.BytesIO(raw))
    except TensorFileError as err:
        raise InputError("agent", f"{p}: corrupted or unsafe agent file ({name}: {err})") from None
    if not isinstance(obj, dict):
        raise InputError("agent", f"{p}: corrupted agent file ({name} is not a state dict)")
    return obj


def load_agent(path: str | os.PathLike[str], env: gym.Env | None = None) -> MaskedDQN:
    """Load an agent saved by :func:`save_agent` (on CPU), without unpickling anything.

    The zip's entry names are checked first (exactly :data:`AGENT_ENTRIES`, plus any of
    :data:`OPTIONAL_AGENT_ENTRIES`). SB3's ``data`` entry and the card are read as plain JSON; the
    pickled (``":serialized:"``) values in ``data`` are never decoded, and a pickled value under a key
    SB3 does not pickle refuses the file. The network is rebuilt as a
    :class:`~uam_studio.planning.agents.dqn.MaskedDQNPolicy` from the card's ``network`` entry
    (:func:`network_description`), or for files without one from the readable fields SB3 writes beside
    the pickled spaces and from ``policy_kwargs``; the training settings and counters come from the
    plain values of ``data``. The weights (``policy.pth``) and optimizer state (``policy.optimizer.pth``)
    are loaded with ``torch.load(weights_only=True)``; ``pytorch_variables.pth`` is not read (a DQN has
    no such variables).

    :param path: the agent zip
    :param env: optional env to check the agent against (same observation and action spaces)
    :raises InputError: (field ``agent``) for a missing, corrupted, unexpected or incompatible file
    """
    p, raw = _read_agent_bytes(path)
    try:
        zf = zipfile.ZipFile(io.BytesIO(raw))
    except Exception as exc:
        raise InputError("agent", f"{p}: corrupted agent file ({type(exc).__name__})") from None
    with zf:
        names = _zip_entries(p, zf)
        data = _read_json_entry(p, zf, "data")
        card = _read_json_entry(p, zf, CARD_NAME) if CARD_NAME in names else {}
        pickled = [k for k, v in data.items()
                   if isinstance(v, dict) and _SERIALIZED in v and k not in _SERIALIZED_KEYS]
        if pickled:
            raise InputError("agent", f"{p}: refused: unexpected pickled setting {_short(pickled[0], 40)} in "
                                      "the agent's data; nothing in it was loaded")
        network = card.get(NETWORK_KEY)
        network = network if isinstance(network, dict) else {}
        policy_name = network.get("policy_class") if network else _policy_class_name(data.get("policy_class"))
        if policy_name != MaskedDQNPolicy.__name__:
            raise InputError("agent", f"{p}: incompatible agent (policy {_short(policy_name, 40)}, "
                                      "expected MaskedDQNPolicy)")
        policy_kwargs = data.get("policy_kwargs", {})
        if not (isinstance(policy_kwargs, dict) and set(policy_kwargs) <= {"net_arch"}):
            raise InputError("agent", f"{p}: incompatible agent (policy settings other than net_arch)")
        net_arch = network.get("net_arch") if network else policy_kwargs.get("net_arch")
        if net_arch is not None and not (isinstance(net_arch, list) and len(net_arch) <= 16 and all(
                isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= 2**16 for w in net_arch)):
            raise InputError("agent", f"{p}: incompatible agent (net_arch {_short(net_arch)})")
        if network:
            obs_space, act_space = _spaces(p, network.get("observation_space"), network.get("action_space"))
        else:
            obs_space, act_space = _spaces(p, data.get("observation_space"), data.get("action_space"))
        settings = _plain_values(p, data, _SETTINGS)
        counters = _plain_values(p, data, _COUNTERS)
        config = card.get("config")
        train_freq = config.get("train_freq") if isinstance(config, dict) else None  # SB3 pickles its own
        if isinstance(train_freq, int) and not isinstance(train_freq, bool) and 1 <= train_freq <= 10**9:
            settings["train_freq"] = train_freq
        n_envs = _int_field(data.get("n_envs", 1), 1, 10**4)
        if n_envs is None:
            raise InputError("agent", f"{p}: corrupted agent file (setting n_envs = "
                                      f"{_short(data.get('n_envs'))})")
        weights = _read_tensors_entry(p, zf, "policy.pth")
        optimizer = (_read_tensors_entry(p, zf, "policy.optimizer.pth") if "policy.optimizer.pth" in names
                     else None)
    try:
        policy_kwargs = {"net_arch": list(net_arch)} if net_arch is not None else {}
        model = MaskedDQN(MaskedDQNPolicy, None, device="cpu", policy_kwargs=policy_kwargs,
                          _init_setup_model=False, **settings)
        model.observation_space, model.action_space, model.n_envs = obs_space, act_space, n_envs
        model._setup_model()
        model.policy.load_state_dict(weights)  # strict: same layers, same shapes
        if optimizer is not None:
            model.policy.optimizer.load_state_dict(optimizer)
    except Exception as exc:
        msg = " ".join(str(exc).split())[:100]
        raise InputError("agent", f"{p}: corrupted or incompatible agent file ({type(exc).__name__}: {msg})") \
            from None
    for key, value in counters.items():
        setattr(model, key, value)
    if env is not None and (env.observation_space != model.observation_space
                            or env.action_space != model.action_space):
        raise InputError("agent", f"{p}: incompatible with this environment (agent expects observations "
                                  f"{model.observation_space.shape} and {model.action_space}; env has "
                                  f"{env.observation_space.shape} and {env.action_space})")
    return model
