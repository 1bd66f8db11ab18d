"""GroupedSubprocVecEnv: the same transitions as DummyVecEnv, indexed calls, worker errors, training."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv

from uam_studio.errors import InputError
from uam_studio.planning.agents.dqn.training import DQNTrainConfig, train_dqn
from uam_studio.planning.agents.vec_env import GroupedSubprocVecEnv, WorkerError
from uam_studio.planning.env import N_FEATURES, UAMPlanningEnv, make_env

# Tests of the calls themselves start their workers by fork (about 4 s faster each); the default start
# method (forkserver) is what the first test and the training tests use.


def _random_actions(obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One random valid action per env, read from the mask at the end of each observation."""
    return np.array([rng.choice(np.flatnonzero(o[N_FEATURES:] > 0.5)) for o in obs])


def test_same_transitions_as_dummy_vec_env():
    fns = [make_env(scenario=s)
           for s in ("single_charge", "multi_charge", "single_flight", "single_charge", "multi_charge")]
    dummy = DummyVecEnv(fns)
    grouped = GroupedSubprocVecEnv(fns, n_workers=2)
    try:
        assert grouped.groups == [[0, 1, 2], [3, 4]]
        assert grouped.observation_space == dummy.observation_space and grouped.action_space == dummy.action_space
        dummy.seed(11)
        grouped.seed(11)
        obs_d, obs_g = dummy.reset(), grouped.reset()
        np.testing.assert_array_equal(obs_d, obs_g)
        rng = np.random.default_rng(0)
        n_done = 0
        for _ in range(40):
            actions = _random_actions(obs_d, rng)
            obs_d, rew_d, done_d, info_d = dummy.step(actions)
            obs_g, rew_g, done_g, info_g = grouped.step(actions)
            np.testing.assert_array_equal(obs_d, obs_g)
            np.testing.assert_array_equal(rew_d, rew_g)
            np.testing.assert_array_equal(done_d, done_g)
            for a, b in zip(info_d, info_g, strict=True):
                assert a.keys() == b.keys()
                assert a["TimeLimit.truncated"] == b["TimeLimit.truncated"]
                if "terminal_observation" in a:
                    np.testing.assert_array_equal(a["terminal_observation"], b["terminal_observation"])
            n_done += int(done_d.sum())
        assert n_done >= 5  # episodes ended and were reset inside the workers
    finally:
        grouped.close()
        dummy.close()
    assert all(not p.is_alive() for p in grouped.processes)


def test_indexed_calls_keep_the_callers_order():
    fns = [make_env(scenario="single_charge", alpha=float(k + 1)) for k in range(5)]
    vec = GroupedSubprocVecEnv(fns, n_workers=2, start_method="fork")
    try:
        vec.reset()
        assert vec.get_attr("alpha") == [1.0, 2.0, 3.0, 4.0, 5.0]
        assert vec.get_attr("alpha", indices=[4, 0, 2]) == [5.0, 1.0, 3.0]
        vec.set_attr("alpha", 9.0, indices=[1, 3])
        assert vec.get_attr("alpha") == [1.0, 9.0, 3.0, 9.0, 5.0]
        masks = vec.env_method("action_masks", indices=[3, 1])
        assert len(masks) == 2 and all(m.dtype == bool and m.any() for m in masks)
        assert vec.env_is_wrapped(Monitor) == [False] * 5
        assert vec.has_attr("alpha") and not vec.has_attr("no_such_attribute")
    finally:
        vec.close()


def test_worker_error_is_raised_in_the_caller_and_the_env_stays_usable():
    vec = GroupedSubprocVecEnv([make_env() for _ in range(4)], n_workers=2, start_method="fork")
    try:
        vec.set_options({"mission": "not a mission"})
        with pytest.raises(WorkerError, match="options.mission"):
            vec.reset()
        vec.set_options(None)
        obs = vec.reset()
        assert obs.shape == (4, UAMPlanningEnv().observation_space.shape[0])
    finally:
        vec.close()


def test_an_env_that_cannot_be_built_is_a_worker_error_at_construction():
    bad = functools.partial(UAMPlanningEnv, scenario="no_such_scenario")
    with pytest.raises(WorkerError, match="scenario"):
        GroupedSubprocVecEnv([make_env(), make_env(), bad], n_workers=2, start_method="fork")


def test_bad_worker_counts_are_one_line_errors():
    with pytest.raises(InputError, match="n_workers.*allowed 1 to 2"):
        GroupedSubprocVecEnv([make_env(), make_env()], n_workers=3)
    with pytest.raises(InputError, match="env_fns"):
        GroupedSubprocVecEnv([], n_workers=1)
    with pytest.raises(InputError, match="n_workers.*allowed 1 to n_envs"):
        train_dqn(DQNTrainConfig(steps=10, n_envs=2, n_workers=3), make_env())


def test_training_with_worker_processes_streams_episodes_and_closes_them():
    stats = []
    cfg = DQNTrainConfig(steps=600, n_envs=4, n_workers=2, learning_starts=200, batch_size=32, net_arch=(32,))
    model = train_dqn(cfg, make_env(scenario="single_charge"), callback=stats.append)
    assert len(stats) >= 20 and all(s.length >= 1 for s in stats)
    assert 600 <= model.num_timesteps <= 616 and stats[-1].timestep <= model.num_timesteps
    assert model.env.closed and all(not p.is_alive() for p in model.env.processes)


def test_worker_processes_are_closed_when_the_training_set_up_fails(tmp_path):
    import multiprocessing

    bad = tmp_path / "not_an_agent.zip"
    bad.write_bytes(b"not a zip")
    cfg = DQNTrainConfig(steps=10, n_envs=2, n_workers=2, init_agent=str(bad))
    with pytest.raises(InputError, match="init_agent"):
        train_dqn(cfg, make_env(scenario="single_charge"))
    assert multiprocessing.active_children() == []
