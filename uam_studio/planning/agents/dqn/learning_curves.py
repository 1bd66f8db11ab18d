"""Learning curves of DQN training runs: per-episode columns, moving averages, and a recorder of
what the agent did in each training episode (route and altitudes).

Public API:

- :func:`episode_columns`: a list of :class:`~uam_studio.planning.agents.dqn.training.EpisodeStats` as named
  numpy columns (for plotting).
- :func:`moving_average`: trailing moving average, same length as the input (the paper's
  "moving average of the number of reached destinations").
- :class:`EpisodeRecorder`: a ``gymnasium.Wrapper`` that appends one :class:`EpisodeRecord` per
  finished episode to a list you own, e.g. the altitude chosen in each episode of a single-flight
  run (the paper's altitude-per-episode figure). Use it inside the ``env_fn`` given to
  :func:`~uam_studio.planning.agents.dqn.training.train_dqn`; with the default ``DummyVecEnv`` all copies run in
  one process and share the list.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any, cast

import gymnasium as gym
import numpy as np

from uam_studio.errors import InputError

__all__ = ["EpisodeRecord", "EpisodeRecorder", "episode_columns", "moving_average"]

_COLUMNS = ("episode", "timestep", "reward", "reached", "reached_priority", "charging_cycles", "eod_breach",
            "length")


def episode_columns(stats: Sequence[Any]) -> dict[str, np.ndarray]:
    """Columns of a sequence of ``EpisodeStats`` (``episode``, ``timestep``, ``reward``, ``reached``,
    ``reached_priority``, ``charging_cycles``, ``eod_breach``, ``length``), one array each."""
    return {c: np.array([getattr(s, c) for s in stats], dtype=bool if c == "eod_breach" else float)
            for c in _COLUMNS}


def moving_average(values: Sequence[float] | np.ndarray, window: int) -> np.ndarray:
    """Trailing moving average over ``window`` samples, same length as ``values``.

    The first ``window - 1`` entries average over the samples seen so far, so the curve starts at
    the first value instead of at zero.
    """
    x = np.asarray(values, dtype=float).reshape(-1)
    w = int(window)
    if w < 1:
        raise InputError("window", f"{window!r} is out of range; allowed >= 1")
    if x.size == 0:
        return x
    c = np.cumsum(np.concatenate([[0.0], x]))
    k = np.arange(1, x.size + 1)
    lo = np.maximum(0, k - w)
    return (c[k] - c[lo]) / (k - lo)


@dataclass(frozen=True)
class EpisodeRecord:
    """What the agent did in one training episode.

    :param route: node names flown to (``"vertiport"`` = landing to recharge)
    :param altitudes_m: cruise altitude of each leg (m)
    :param reached: number of destinations reached
    :param reached_priority: their total priority
    :param charging_cycles: landings at the vertiport
    :param eod: the episode ended below the cut-off
    :param reward: undiscounted return
    """

    route: tuple[str, ...]
    altitudes_m: tuple[float, ...]
    reached: int
    reached_priority: int
    charging_cycles: int
    eod: bool
    reward: float

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class EpisodeRecorder(gym.Wrapper):
    """Append an :class:`EpisodeRecord` to ``sink`` at the end of every episode.

    Reads the env's ``info`` keys ``route``, ``altitudes_m``, ``reached``, ``reached_priority``,
    ``charging_cycles`` and ``eod`` (as :class:`~uam_studio.planning.env.UAMPlanningEnv` gives them).

    :param env: the environment to wrap
    :param sink: the list to append to (shared by all copies of a ``DummyVecEnv``)
    """

    def __init__(self, env: gym.Env, sink: list[EpisodeRecord]) -> None:
        super().__init__(env)
        if not isinstance(sink, list):
            raise InputError("sink", f"expected a list, got {type(sink).__name__}")
        self.sink = sink
        self._return = 0.0

    def reset(self, **kwargs: Any):
        self._return = 0.0
        return self.env.reset(**kwargs)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._return += float(reward)
        if terminated or truncated:
            self.sink.append(EpisodeRecord(
                tuple(info.get("route", ())), tuple(float(a) for a in info.get("altitudes_m", ())),
                len(info.get("reached", ())), int(info.get("reached_priority", 0)),
                int(info.get("charging_cycles", 0)), bool(info.get("eod", False)), self._return))
        return obs, reward, terminated, truncated, info

    def action_masks(self) -> np.ndarray:
        """The wrapped env's boolean action mask."""
        return cast(Any, self.env.unwrapped).action_masks()
