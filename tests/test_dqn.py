"""Masked DQN: masking in exploration, greedy choice and target; training API; save/load."""

from __future__ import annotations

import threading
import zipfile

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3 import DQN
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import Logger

import uam_studio.planning.agents.dqn.masked as dqn_mod
from uam_studio.errors import InputError
from uam_studio.planning.agents.dqn.agent_file import load_agent, load_card, save_agent
from uam_studio.planning.agents.dqn.masked import MaskedDQN, action_mask, greedy_action, masked_target
from uam_studio.planning.agents.dqn.training import FINE_TUNE, DQNTrainConfig, EpisodeStats, train_dqn

X = np.array([3.0, 1.0, 4.0, 2.0, 5.0])  # cell positions; the agent starts at x = 0
PRIORITY = np.array([1, 2, 3, 1, 2])
N = len(X)
OPTIMUM = 2.0 * N - 5.0  # +2 per visit, -distance: best is visiting by increasing x (distance 5)
INVALID_REWARD = -100.0


class VisitEnv(gym.Env):
    """Toy masked env: visit each of N cells once. Action i = fly to cell i (reward 2 - distance).

    Observation: one-hot position (start + N cells), then the action mask (unvisited cells). Revisiting
    is invalid: reward -100, nothing changes. Ends when all cells are visited (terminated, mask all zero)
    or after 2N steps (truncated).
    """

    def __init__(self) -> None:
        self.observation_space = spaces.Box(0.0, 1.0, shape=(N + 1 + N,), dtype=np.float32)
        self.action_space = spaces.Discrete(N)

    def _obs(self) -> np.ndarray:
        o = np.zeros(2 * N + 1, dtype=np.float32)
        o[self.pos + 1] = 1.0
        o[N + 1:] = ~self.visited
        return o

    def _info(self) -> dict:
        names = [f"c{i}" for i in np.flatnonzero(self.visited)]
        return {"reached": names, "reached_priority": int(PRIORITY[self.visited].sum()),
                "charging_cycles": 0, "eod": False, "invalid": self.invalid}

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.pos, self.t, self.invalid = -1, 0, 0
        self.visited = np.zeros(N, dtype=bool)
        return self._obs(), self._info()

    def step(self, action):
        a = int(action)
        self.t += 1
        if self.visited[a]:
            self.invalid += 1
            reward = INVALID_REWARD
        else:
            here = 0.0 if self.pos < 0 else X[self.pos]
            reward = 2.0 - abs(X[a] - here)
            self.pos = a
            self.visited[a] = True
        terminated = bool(self.visited.all())
        return self._obs(), float(reward), terminated, self.t >= 2 * N and not terminated, self._info()


def random_masked_obs(rng: np.random.Generator, n_obs: int) -> np.ndarray:
    obs = np.zeros((n_obs, 2 * N + 1), dtype=np.float32)
    obs[np.arange(n_obs), rng.integers(0, N + 1, n_obs)] = 1.0
    mask = rng.random((n_obs, N)) < 0.4
    mask[np.arange(n_obs), rng.integers(0, N, n_obs)] = True  # at least one valid action
    obs[:, N + 1:] = mask
    return obs


def small_model(**kw) -> MaskedDQN:
    env = make_vec_env(VisitEnv, n_envs=2, seed=0)
    kw.setdefault("policy_kwargs", {"net_arch": [32, 32]})
    model = MaskedDQN("MlpPolicy", env, learning_starts=50, buffer_size=1000, seed=0, device="cpu", **kw)
    model.set_logger(Logger(folder=None, output_formats=[]))  # SB3's default makes a tempdir/SB3-<time> folder
    return model


def rollout_greedy(model: MaskedDQN) -> tuple[float, int]:
    env = VisitEnv()
    obs, info = env.reset(seed=1)
    total, done = 0.0, False
    while not done:
        obs, r, term, trunc, info = env.step(greedy_action(model, obs))
        total += r
        done = term or trunc
    return total, info["invalid"]


@pytest.fixture(autouse=True)
def one_thread():
    n = th.get_num_threads()
    th.set_num_threads(1)
    yield
    th.set_num_threads(n)


def test_exploration_samples_only_valid_actions_and_all_of_them():
    model = small_model()
    model.exploration_rate = 1.0
    rng = np.random.default_rng(0)
    obs = random_masked_obs(rng, 64)
    mask = obs[:, N + 1:] > 0.5
    seen = np.zeros_like(mask)
    for _ in range(200):
        a, _ = model.predict(obs, deterministic=False)
        assert a.shape == (64,)
        assert mask[np.arange(64), a].all()
        seen[np.arange(64), a] = True
    assert (seen == mask).all()  # uniform among valid: every valid action turns up
    a, _ = model.predict(obs[0], deterministic=False)  # one observation -> 0-d action
    assert np.ndim(a) == 0 and mask[0, int(a)]
    # SB3's warm-up phase (before learning_starts) is masked too.
    model.num_timesteps, model._last_obs = 0, obs
    for _ in range(50):
        a, buffer_a = model._sample_action(learning_starts=10**6, n_envs=64)
        assert mask[np.arange(64), a].all() and (a == buffer_a).all()


def test_warm_up_acts_with_the_network_when_not_random():
    """A fine-tuning run's warm-up (``random_warmup=False``, :data:`FINE_TUNE`) plays the agent's own
    (valid, greedy at epsilon 0) actions; the default warm-up is uniform among the valid ones."""
    rng = np.random.default_rng(1)
    obs = random_masked_obs(rng, 64)
    mask = obs[:, N + 1:] > 0.5
    own = small_model(random_warmup=False)
    own.exploration_rate, own.num_timesteps, own._last_obs = 0.0, 0, obs
    greedy, _ = own.predict(obs, deterministic=True)
    for _ in range(5):
        a, buffer_a = own._sample_action(learning_starts=10**6, n_envs=64)
        assert (a == greedy).all() and (a == buffer_a).all()
    uniform = small_model()
    uniform.exploration_rate, uniform.num_timesteps, uniform._last_obs = 0.0, 0, obs
    draws = [uniform._sample_action(learning_starts=10**6, n_envs=64)[0] for _ in range(20)]
    assert all(mask[np.arange(64), a].all() for a in draws)
    assert any((a != greedy).any() for a in draws)
    assert FINE_TUNE["random_warmup"] is False


def test_greedy_never_picks_invalid_even_with_highest_q():
    model = small_model()
    last = model.q_net.q_net[-1]
    with th.no_grad():  # Q(s, a) = 10 * a whatever s: the highest index is best
        last.weight.zero_()
        last.bias.copy_(10.0 * th.arange(N, dtype=th.float32))
    obs = random_masked_obs(np.random.default_rng(1), 200)
    mask = obs[:, N + 1:] > 0.5
    expected = np.array([np.flatnonzero(m).max() for m in mask])
    a, _ = model.predict(obs, deterministic=True)
    np.testing.assert_array_equal(a, expected)
    assert all(greedy_action(model, o) == e for o, e in zip(obs[:20], expected[:20]))
    with pytest.raises(ValueError):
        greedy_action(model, np.zeros(2 * N + 1, dtype=np.float32))


def test_masked_target_matches_manual_computation():
    q_t = th.tensor([[1.0, 9.0, 3.0], [5.0, 2.0, 7.0], [4.0, 4.0, 4.0], [1.0, 2.0, 3.0]])
    q_o = th.tensor([[0.0, 0.0, 1.0], [3.0, 0.0, 9.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    mask = th.tensor([[True, False, True], [True, True, False], [False, False, False], [True, True, True]])
    rewards = th.tensor([[1.0], [0.5], [2.0], [-1.0]])
    dones = th.tensor([[0.0], [0.0], [1.0], [1.0]])
    y = masked_target(rewards, dones, 0.9, q_t, mask)
    # row 0: max over valid {1, 3} = 3 (not 9); row 1: max {5, 2} = 5 (not 7); rows 2-3: terminal.
    np.testing.assert_allclose(y.numpy().ravel(), [1 + 0.9 * 3, 0.5 + 0.9 * 5, 2.0, -1.0])
    # Double DQN: online net picks among valid (row 0: action 2, row 1: action 0), target net values it.
    y2 = masked_target(rewards, dones, 0.9, q_t, mask, q_o)
    np.testing.assert_allclose(y2.numpy().ravel(), [1 + 0.9 * 3, 0.5 + 0.9 * 5, 2.0, -1.0])
    # A non-terminal next state without valid actions bootstraps 0, and nothing is NaN.
    y3 = masked_target(rewards, th.zeros_like(dones), th.full((4, 1), 0.9), q_t, mask)
    assert th.isfinite(y3).all() and float(y3[2, 0]) == 2.0


@pytest.mark.parametrize("double", [False, True])
def test_train_uses_masked_target_with_mask_of_next_observations(monkeypatch, double):
    calls = []

    def spy(rewards, dones, discounts, next_q_target, next_mask, next_q_online=None):
        calls.append((next_mask.clone(), next_q_online is not None))
        return masked_target(rewards, dones, discounts, next_q_target, next_mask, next_q_online)

    model = small_model(double_dqn=double, batch_size=16)
    model.learn(100)  # fills the buffer and does a few updates
    sampled = []
    real_sample = model.replay_buffer.sample

    def sample(*args, **kwargs):
        sampled.append(real_sample(*args, **kwargs))
        return sampled[-1]

    monkeypatch.setattr(model.replay_buffer, "sample", sample)
    monkeypatch.setattr(dqn_mod, "masked_target", spy)
    model.train(gradient_steps=1, batch_size=16)
    assert len(calls) == 1 and calls[0][1] == double
    next_obs = sampled[0].next_observations
    assert calls[0][0].shape == (16, N)
    assert th.equal(calls[0][0], next_obs[:, -N:] > 0.5) and th.equal(calls[0][0], action_mask(next_obs, N))
    assert not calls[0][0].all()  # the batch does contain invalid next actions


def test_toy_env_learned_with_no_invalid_action_and_streamed_stats():
    stats: list[EpisodeStats] = []
    cfg = DQNTrainConfig(steps=4000, n_envs=2, learning_starts=300, buffer_size=5000, batch_size=64,
                         target_update_interval=200, train_freq=2, gradient_steps=1, learning_rate=2e-3,
                         exploration_fraction=0.4, net_arch=(64, 64), seed=0)
    model = train_dqn(cfg, VisitEnv, callback=stats.append)
    ret, invalid = rollout_greedy(model)
    assert invalid == 0
    assert ret == pytest.approx(OPTIMUM)
    # Streamed stats: one per episode, in order, and no invalid action ever taken (not even exploring).
    assert len(stats) > 300
    assert [s.episode for s in stats] == list(range(1, len(stats) + 1))
    assert all(b.timestep >= a.timestep for a, b in zip(stats, stats[1:]))
    assert all(s.length == N and s.reached == N for s in stats)
    assert all(s.reward > INVALID_REWARD / 2 for s in stats)
    assert all(s.reached_priority == PRIORITY.sum() and s.charging_cycles == 0 and not s.eod_breach
               for s in stats)
    assert np.mean([s.reward for s in stats[-50:]]) > OPTIMUM - 2.0


def test_training_leaves_no_log_folder_behind(tmp_path, monkeypatch):
    """SB3's default logger makes an empty tempdir/SB3-<time> folder per run; training logs nowhere."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    train_dqn(DQNTrainConfig(steps=50, n_envs=1, learning_starts=10, net_arch=(16,), seed=3), VisitEnv)
    assert not list(tmp_path.glob("SB3-*"))


def test_stop_event_stops_training():
    stop = threading.Event()
    seen = []

    def on_episode(s: EpisodeStats) -> None:
        seen.append(s)
        if len(seen) == 3:
            stop.set()

    cfg = DQNTrainConfig(steps=100_000, n_envs=2, learning_starts=100, net_arch=(16,))
    model = train_dqn(cfg, VisitEnv, callback=on_episode, stop_event=stop)
    assert model.num_timesteps < 100 and len(seen) in (3, 4)  # both envs may finish on the same step


def test_save_load_round_trip_and_bad_files(tmp_path):
    model = small_model(double_dqn=True)
    model.learn(200)
    path = tmp_path / "sub" / "agent.zip"
    save_agent(model, path, {"scenario": "toy", "steps": 200})
    assert sorted(p.name for p in path.parent.iterdir()) == ["agent.zip", "agent.zip.sha256"]  # no temp file left
    loaded = load_agent(path, env=VisitEnv())
    assert isinstance(loaded, MaskedDQN) and loaded.double_dqn
    obs = random_masked_obs(np.random.default_rng(2), 50)
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0],
                                  loaded.predict(obs, deterministic=True)[0])
    card = load_card(path)
    assert card["scenario"] == "toy" and card["steps"] == 200

    def bad(p, why):
        with pytest.raises(InputError) as err:
            load_agent(p)
        assert err.value.field == "agent" and str(err.value).startswith("agent:")
        assert "\n" not in str(err.value), why

    bad(tmp_path / "missing.zip", "missing")
    garbage = tmp_path / "garbage.zip"
    garbage.write_bytes(b"not a zip at all")
    bad(garbage, "garbage")
    truncated = tmp_path / "truncated.zip"
    truncated.write_bytes(path.read_bytes()[:2000])
    bad(truncated, "truncated")
    other = tmp_path / "other.zip"
    with zipfile.ZipFile(other, "w") as zf:
        zf.writestr("hello.txt", "hi")
    bad(other, "zip without an agent")
    broken = tmp_path / "broken.zip"  # a valid zip whose weights are garbage
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(broken, "w") as dst:
        for name in src.namelist():
            dst.writestr(name, b"garbage" if name == "policy.pth" else src.read(name))
    bad(broken, "corrupted weights")
    plain = tmp_path / "plain.zip"  # an unmasked SB3 DQN is not a planner agent
    DQN("MlpPolicy", VisitEnv(), device="cpu").save(plain)
    bad(plain, "unmasked DQN")
    with pytest.raises(InputError, match="incompatible"):
        wrong_env = VisitEnv()
        wrong_env.observation_space = spaces.Box(0.0, 1.0, shape=(3,), dtype=np.float32)
        load_agent(path, env=wrong_env)
    with pytest.raises(InputError):
        load_card(garbage)


def test_warm_start_copies_the_agent_and_rejects_mismatches(tmp_path):
    """init_agent: the new model starts with the saved agent's weights (it plans the same before
    any update); a missing file or another net_arch is a clear init_agent error."""
    src_cfg = DQNTrainConfig(steps=400, n_envs=2, learning_starts=100, net_arch=(16,), seed=5)
    src = train_dqn(src_cfg, VisitEnv)
    path = tmp_path / "src.zip"
    save_agent(src, path, {"scenario": "toy"})
    cfg = DQNTrainConfig(steps=2, n_envs=1, learning_starts=100, net_arch=(16,), seed=9,
                         init_agent=str(path), exploration_initial_eps=0.2)
    warm = train_dqn(cfg, VisitEnv)  # 2 steps < learning_starts: no gradient step yet
    for k, v in src.policy.state_dict().items():
        assert th.equal(v, warm.policy.state_dict()[k]), k
    cold = train_dqn(DQNTrainConfig(steps=2, n_envs=1, learning_starts=100, net_arch=(16,), seed=9), VisitEnv)
    assert not all(th.equal(v, cold.policy.state_dict()[k]) for k, v in src.policy.state_dict().items())
    with pytest.raises(InputError, match="init_agent.*net_arch"):
        train_dqn(DQNTrainConfig(steps=2, n_envs=1, net_arch=(8,), init_agent=str(path)), VisitEnv)
    with pytest.raises(InputError, match="init_agent.*not found"):
        train_dqn(DQNTrainConfig(steps=2, n_envs=1, net_arch=(16,), init_agent=str(tmp_path / "no.zip")),
                  VisitEnv)
