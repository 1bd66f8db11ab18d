"""Learning-curve helpers: episode columns, moving averages, the episode recorder wrapper."""

from __future__ import annotations

import numpy as np
import pytest

from uam_studio.errors import InputError
from uam_studio.planning.agents.dqn.learning_curves import EpisodeRecorder, episode_columns, moving_average
from uam_studio.planning.agents.dqn.training import EpisodeStats
from uam_studio.planning.env import UAMPlanningEnv


def test_moving_average():
    np.testing.assert_allclose(moving_average([1, 2, 3, 4, 5], 2), [1.0, 1.5, 2.5, 3.5, 4.5])
    np.testing.assert_allclose(moving_average([3.0, 1.0], 10), [3.0, 2.0])
    assert moving_average([], 3).size == 0
    with pytest.raises(InputError):
        moving_average([1.0], 0)


def test_episode_columns():
    stats = [EpisodeStats(k + 1, 10 * (k + 1), float(k), k, 2.0 * k, 1, k == 1, 3) for k in range(3)]
    cols = episode_columns(stats)
    np.testing.assert_array_equal(cols["episode"], [1, 2, 3])
    np.testing.assert_array_equal(cols["eod_breach"], [False, True, False])
    assert cols["eod_breach"].dtype == bool and cols["reward"].dtype == float


def test_episode_recorder_records_each_episode():
    sink = []
    env = EpisodeRecorder(UAMPlanningEnv(scenario="single_charge", n_dest=(3, 5)), sink)
    rng = np.random.default_rng(0)
    for ep in range(3):
        obs, info = env.reset(seed=ep)
        done = False
        total = 0.0
        while not done:
            valid = np.flatnonzero(env.action_masks())
            obs, r, term, trunc, info = env.step(int(rng.choice(valid)))
            total += r
            done = term or trunc
        rec = sink[-1]
        assert rec.route == tuple(info["route"]) and rec.altitudes_m == tuple(info["altitudes_m"])
        assert rec.reached == len(info["reached"]) and rec.eod == info["eod"]
        assert rec.reward == pytest.approx(total)
    assert len(sink) == 3
    with pytest.raises(InputError):
        EpisodeRecorder(UAMPlanningEnv(), sink=())
