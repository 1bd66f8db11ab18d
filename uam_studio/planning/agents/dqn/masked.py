"""DQN with action masking, built on stable-baselines3's DQN (2.x).

stable-baselines3's DQN has no action masking: ``predict`` explores with
``action_space.sample()``, the warm-up phase samples the whole action space, and
the bootstrap target takes ``max`` over all actions. Here the mask is masked in
all three places, and everything else (replay buffer, target network,
vectorised envs, logger, save/load) is SB3's own.

Convention: the observation space is a flat ``Box`` whose **last** ``n``
entries are the action mask (1.0 = valid, 0.0 = invalid), with
``n = action_space.n`` for a ``Discrete`` action space. The Q-network sees the
whole observation, mask included (it is part of the state).

Public API:

- :class:`MaskedQNetwork`, :class:`MaskedDQNPolicy` (alias ``"MlpPolicy"`` in
  :class:`MaskedDQN`): greedy choice restricted to valid actions.
- :class:`MaskedDQN`: epsilon-greedy exploration among valid actions (each env
  of a vectorised batch draws its own coin and its own valid action), masked
  warm-up, masked (optionally double-DQN) bootstrap target.
- :func:`action_mask`, :func:`masked_q_values`, :func:`masked_target`: the
  pieces, usable and testable on their own.

Note: masks are read from the observation the agent sees, so do not normalise
observations (``VecNormalize(norm_obs=True)`` would corrupt the mask).
"""

from __future__ import annotations

from typing import Any, ClassVar, cast, overload

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3 import DQN
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import PyTorchObs
from stable_baselines3.dqn.policies import DQNPolicy, QNetwork
from torch.nn import functional as F

__all__ = [
    "MaskedDQN",
    "greedy_action",
    "ranked_actions",
    "MaskedDQNPolicy",
    "MaskedQNetwork",
    "action_mask",
    "masked_q_values",
    "masked_target",
]


def _check_spaces(observation_space: spaces.Space, action_space: spaces.Space) -> int:
    """Return ``n_actions`` if the spaces follow the masking convention, else raise ValueError."""
    if not isinstance(action_space, spaces.Discrete):
        raise ValueError(f"masked DQN needs a Discrete action space, got {action_space}")
    n = int(action_space.n)
    if not isinstance(observation_space, spaces.Box) or len(observation_space.shape) != 1:
        raise ValueError(f"masked DQN needs a flat Box observation space, got {observation_space}")
    if observation_space.shape[0] < n:
        raise ValueError(
            f"observation has {observation_space.shape[0]} entries; the last {n} must be the action mask"
        )
    return n


@overload
def action_mask(obs: np.ndarray, n_actions: int) -> np.ndarray: ...
@overload
def action_mask(obs: th.Tensor, n_actions: int) -> th.Tensor: ...
def action_mask(obs: np.ndarray | th.Tensor, n_actions: int) -> np.ndarray | th.Tensor:
    """Boolean mask of valid actions: the last ``n_actions`` entries of ``obs`` (> 0.5 means valid).

    :param obs: observation(s), shape ``(..., obs_dim)``, numpy array or torch tensor
    :param n_actions: number of discrete actions (the mask length)
    :return: boolean array/tensor of shape ``(..., n_actions)``, same library as ``obs``
    """
    return obs[..., -n_actions:] > 0.5


def masked_q_values(q_values: th.Tensor, mask: th.Tensor) -> th.Tensor:
    """Q-values with invalid actions set to ``-inf`` (so any max/argmax ignores them)."""
    return q_values.masked_fill(~mask, -th.inf)


def masked_target(
    rewards: th.Tensor,
    dones: th.Tensor,
    discounts: th.Tensor | float,
    next_q_target: th.Tensor,
    next_mask: th.Tensor,
    next_q_online: th.Tensor | None = None,
) -> th.Tensor:
    """1-step TD target with the bootstrap restricted to valid next actions.

    ``y = r + (1 - done) * discount * V(s')`` where ``V(s') = max_{a valid} Q_target(s', a)``, or with
    double DQN (``next_q_online`` given) ``Q_target(s', argmax_{a valid} Q_online(s', a))``. A next
    state with no valid action has ``V(s') = 0`` (nothing more can happen there), which also keeps
    ``-inf * 0`` NaNs out of terminal transitions.

    :param rewards: shape ``(B, 1)``
    :param dones: shape ``(B, 1)``, 1.0 where the episode terminated (not truncated)
    :param discounts: scalar or ``(B, 1)`` (n-step buffers give per-sample discounts)
    :param next_q_target: target-network Q-values at the next observations, ``(B, n_actions)``
    :param next_mask: boolean valid-action mask of the next observations, ``(B, n_actions)``
    :param next_q_online: online-network Q-values at the next observations for double DQN, or None
    :return: targets, shape ``(B, 1)``
    """
    has_valid = next_mask.any(dim=1)
    if next_q_online is None:
        next_v = masked_q_values(next_q_target, next_mask).max(dim=1).values
    else:
        best = masked_q_values(next_q_online, next_mask).argmax(dim=1, keepdim=True)
        next_v = th.gather(next_q_target, dim=1, index=best).squeeze(1)
    next_v = th.where(has_valid, next_v, th.zeros_like(next_v)).reshape(-1, 1)
    return rewards + (1 - dones) * discounts * next_v


class MaskedQNetwork(QNetwork):
    """SB3's :class:`~stable_baselines3.dqn.policies.QNetwork` whose greedy action skips invalid actions.

    The mask is the last ``action_space.n`` entries of the observation. A row with no valid action
    (only seen at a terminal state) falls back to the unmasked argmax.
    """

    def _predict(self, observation: PyTorchObs, deterministic: bool = True) -> th.Tensor:
        q_values = self(observation)
        assert isinstance(observation, th.Tensor)
        mask = action_mask(observation, int(self.action_space.n))
        mask = mask | ~mask.any(dim=1, keepdim=True)  # no valid action at all: keep every column
        return masked_q_values(q_values, mask).argmax(dim=1).reshape(-1)


class MaskedDQNPolicy(DQNPolicy):
    """SB3's MLP :class:`~stable_baselines3.dqn.policies.DQNPolicy` with :class:`MaskedQNetwork` (online and
    target networks). Same constructor arguments; the observation space must follow the masking convention.
    """

    def __init__(self, observation_space: spaces.Space, action_space: spaces.Discrete, *args: Any,
                 **kwargs: Any) -> None:
        _check_spaces(observation_space, action_space)
        super().__init__(observation_space, action_space, *args, **kwargs)

    def make_q_net(self) -> MaskedQNetwork:
        net_args = self._update_features_extractor(self.net_args, features_extractor=None)
        return MaskedQNetwork(**net_args).to(self.device)


class MaskedDQN(DQN):
    """Deep Q-Network with action masking (the mask is the observation's last ``action_space.n`` entries).

    Accepts every argument of :class:`stable_baselines3.DQN`, plus:

    :param double_dqn: use the double-DQN target (online net picks the next action, target net values it)
    :param random_warmup: before ``learning_starts`` transitions, act uniformly among the valid actions
        (SB3's warm-up); False: act with the network, epsilon-greedy, as after it (a fine-tuned agent's
        warm-up fills the buffer with its own play)

    Differences from SB3's DQN: exploration (warm-up and epsilon steps) samples uniformly among the
    valid actions, and epsilon is drawn per env of a vectorised batch (SB3 draws one coin for the whole
    batch); the greedy action is the best valid one; the bootstrap target maxes over valid next actions
    only (see :func:`masked_target`).
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {
        "MlpPolicy": MaskedDQNPolicy,
        "MaskedDQNPolicy": MaskedDQNPolicy,
    }
    policy: MaskedDQNPolicy

    def __init__(self, policy: str | type[MaskedDQNPolicy], env: Any, *args: Any, double_dqn: bool = False,
                 random_warmup: bool = True, **kwargs: Any) -> None:
        self.double_dqn = double_dqn
        self.random_warmup = random_warmup
        super().__init__(policy, env, *args, **kwargs)

    # ------------------------------------------------------------------ exploration
    @property
    def n_actions(self) -> int:
        return int(self.action_space.n)  # type: ignore[attr-defined]

    def random_valid_actions(self, observation: np.ndarray) -> np.ndarray:
        """One action per row of ``observation`` (``(B, obs_dim)``), uniform among that row's valid
        actions (uniform among all actions if a row has none). Uses ``np.random`` (seeded by SB3).
        """
        obs_space = cast(spaces.Box, self.observation_space)  # a flat Box: MaskedDQNPolicy checks the spaces
        mask = np.asarray(action_mask(np.asarray(observation).reshape(-1, obs_space.shape[0]), self.n_actions))
        mask = mask | ~mask.any(axis=1, keepdims=True)
        # Uniform among valid entries: argmax of masked uniform noise.
        noise = np.where(mask, np.random.rand(*mask.shape), -1.0)
        return noise.argmax(axis=1)

    def predict(
        self,
        observation: np.ndarray | dict[str, np.ndarray],
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """Masked epsilon-greedy action(s).

        :param observation: one observation ``(obs_dim,)`` or a batch ``(B, obs_dim)``
        :param state: unused (no recurrent policies)
        :param episode_start: unused
        :param deterministic: greedy (masked) actions only, no exploration
        :return: the action(s) (a 0-d array for one observation, ``(B,)`` for a batch) and ``state``
        """
        greedy, state = self.policy.predict(observation, state, episode_start, deterministic)
        if deterministic or self.exploration_rate <= 0.0:
            return greedy, state
        obs = np.asarray(observation)
        vectorized = self.policy.is_vectorized_observation(obs)
        greedy_b = np.asarray(greedy).reshape(-1)
        explore = np.random.rand(greedy_b.shape[0]) < self.exploration_rate
        action = np.where(explore, self.random_valid_actions(obs), greedy_b)
        return (action if vectorized else action.reshape(())), state

    def _sample_action(
        self, learning_starts: int, action_noise: Any = None, n_envs: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        # SB3's warm-up samples the full action space; sample valid actions instead, or (no random
        # warm-up) the network's epsilon-greedy ones.
        if self.num_timesteps < learning_starts:
            assert self._last_obs is not None, "self._last_obs was not set"
            if self.random_warmup:
                action = self.random_valid_actions(self._last_obs)  # type: ignore[arg-type]
            else:
                action = np.asarray(self.predict(self._last_obs, deterministic=False)[0]).reshape(-1)
            return action, action
        return super()._sample_action(learning_starts, action_noise, n_envs)

    # ------------------------------------------------------------------ learning
    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        """SB3's DQN update with the masked (optionally double) target of :func:`masked_target`."""
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)

        losses = []
        for _ in range(gradient_steps):
            replay_data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            discounts = replay_data.discounts if replay_data.discounts is not None else self.gamma
            next_obs = replay_data.next_observations
            assert isinstance(next_obs, th.Tensor)

            with th.no_grad():
                next_q_target = self.q_net_target(next_obs)
                next_q_online = self.q_net(next_obs) if self.double_dqn else None
                target_q_values = masked_target(
                    replay_data.rewards, replay_data.dones, discounts, next_q_target,
                    action_mask(next_obs, self.n_actions), next_q_online,
                )

            current_q_values = self.q_net(replay_data.observations)
            current_q_values = th.gather(current_q_values, dim=1, index=replay_data.actions.long())

            loss = F.smooth_l1_loss(current_q_values, target_q_values)
            losses.append(loss.item())

            self.policy.optimizer.zero_grad()
            loss.backward()
            th.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
            self.policy.optimizer.step()

        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/loss", np.mean(losses))


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
    obs = np.asarray(obs, dtype=np.float32).reshape(1, -1)
    n = int(model.action_space.n)  # type: ignore[attr-defined]
    valid = np.flatnonzero(obs[0, -n:] > 0.5)
    with th.no_grad():
        q = model.policy.q_net(th.as_tensor(obs, device=model.device)).cpu().numpy()[0]
    return valid[np.argsort(-q[valid], kind="stable")]
