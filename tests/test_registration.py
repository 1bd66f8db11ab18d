"""The gymnasium ids registered by ``import uam_studio``: they make, pass gymnasium's env checker and
render text (``render_mode="ansi"``)."""

from __future__ import annotations

import warnings

import gymnasium
import pytest
from gymnasium.utils.env_checker import check_env

import uam_studio  # noqa: F401 - registers the ids
from uam_studio.errors import InputError
from uam_studio.planning.env import UAMPlanningEnv
from uam_studio.registration import ENV_IDS

IDS = list(ENV_IDS)


def test_the_three_scenarios_are_registered():
    assert {ENV_IDS[i] for i in IDS} == {"single_flight", "single_charge", "multi_charge"}
    for env_id in IDS:
        assert env_id in gymnasium.registry


@pytest.mark.parametrize("env_id", IDS)
def test_registered_env_passes_the_env_checker(env_id):
    env = gymnasium.make(env_id)
    assert isinstance(env.unwrapped, UAMPlanningEnv) and env.unwrapped.scenario == ENV_IDS[env_id]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the unwrapped env passes without a single warning
        check_env(env.unwrapped)
    check_env(env)  # the made env too (gymnasium warns only that it is wrapped)
    env.close()


@pytest.mark.parametrize("env_id", IDS)
def test_ansi_render_summarises_the_episode(env_id):
    env = gymnasium.make(env_id, render_mode="ansi")
    obs, info = env.reset(seed=3)
    text = env.render()
    assert isinstance(text, str) and text.startswith(f"{ENV_IDS[env_id]} | ") and "step 0/" in text
    assert "running" in text and "route: vertiport\n" in text
    action = int(next(a for a in range(env.action_space.n) if env.unwrapped.action_masks()[a]))
    obs, reward, terminated, truncated, info = env.step(action)
    text = env.render()
    assert "step 1/" in text and f"-> {info['route'][0]} ({info['altitudes_m'][0]:g} m)" in text
    if terminated:
        assert ("end of discharge" in text) == info["eod"]
    env.close()


def test_render_mode_is_checked_and_optional():
    with pytest.raises(InputError, match="^render_mode: 'human' is not a render mode"):
        UAMPlanningEnv(render_mode="human")
    env = UAMPlanningEnv(scenario="single_charge")
    assert env.render_mode is None and env.render() is None
    assert "no episode yet" in UAMPlanningEnv(render_mode="ansi").render()


def test_make_passes_constructor_arguments():
    env = gymnasium.make("uam_studio/MultiCharge-v0", n_dest=3, gamma=2.0)
    env.reset(seed=0)
    assert env.unwrapped.scenario == "multi_charge" and len(env.unwrapped.mission.destinations) == 3
    assert env.unwrapped.gamma == 2.0
