"""A trained DQN agent as a planner: find and load agents, and roll one out on a mission.

:func:`rollout_agent` flies an agent greedily in a :class:`~uam_studio.planning.env.UAMPlanningEnv`
on the mission (physics battery), with the safety filter and optional policy rollout;
:func:`dqn_route` is :func:`~uam_studio.planning.planner.plan_mission`'s ``"dqn"`` policy;
:func:`bundled_agent_path` and :func:`load_agent_cached` find and load agent files.

Torch and stable-baselines3 are imported inside the functions that need them
(:mod:`~uam_studio.planning.agents.dqn.agent_file`, :mod:`~uam_studio.planning.agents.dqn.masked`), so that importing
this module, and with it :mod:`uam_studio.planning.planner`, the CLI and the app, stays torch-free until an agent is
loaded.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any

import numpy as np

from uam_studio.bundled import bundled_path
from uam_studio.errors import InputError
from uam_studio.planning.env import UAMPlanningEnv
from uam_studio.planning.legs import N_ALTITUDES, N_MAX, VERTIPORT_SLOT
from uam_studio.planning.missions.check import Plan
from uam_studio.planning.missions.mission import Mission, check_destination_count
from uam_studio.planning.solvers.setup import prepare_mission, single_flight_note, too_close

__all__ = ["ROLLOUT_BASES", "bundled_agent_path", "dqn_plan", "dqn_route", "load_agent_cached", "rollout_agent"]


def bundled_agent_path(scenario: str) -> Path:
    """The bundled DQN agent of ``scenario``, ``dqn_<scenario>.zip`` (:func:`uam_studio.bundled.bundled_path`:
    the user folder's ``pretrained/`` first, then the package data); it may not exist."""
    return bundled_path(f"dqn_{scenario}.zip")


# ----------------------------------------------------------------------------- DQN rollout


def dqn_route(mission: Mission, agent_path: str | os.PathLike[str] | None, predictor: Any,
               messages: list[str], lookahead: int = 0) -> tuple[list[str], list[float]]:
    """Roll the agent out greedily on ``mission`` (physics battery); messages for what went wrong.

    :raises InputError: more than ``N_MAX`` (8) destinations, the paper's action space (never cut
        silently: plan larger missions with the oracle or greedy policy)."""
    if len(mission.destinations) > N_MAX:
        check_destination_count(len(mission.destinations), N_MAX, "the dqn policy")
    setup = prepare_mission(mission, None, "dqn")  # the oracle's and greedy's preamble
    if setup.early is not None:
        messages.extend(setup.early.messages)
        return [], []
    messages.extend(setup.messages)
    assert setup.mission is not None and setup.episode is not None and setup.scenario is not None
    mission, episode, scenario = setup.mission, setup.episode, setup.scenario
    dests = mission.destinations
    for k in range(len(dests) if not episode.rules.one_leg else 1):
        reason = too_close(episode.legs, k)
        if reason is not None:
            messages.append(reason)
    if episode.rules.one_leg:
        messages.extend(filter(None, [single_flight_note(mission)]))
    if not episode.servable.any():
        return [], []

    path = bundled_agent_path(scenario) if agent_path is None else Path(agent_path)

    plan = rollout_agent(mission, path, predictor, messages, lookahead=lookahead)
    messages.extend(m for m in plan.messages if not m.startswith("end of discharge"))  # physics check says it
    return list(plan.route), list(plan.altitudes_m)



def dqn_plan(mission: Mission, *, agent_path: str | os.PathLike[str] | None = None, predictor: Any = None,
             lookahead: int = 0) -> Plan:
    """:func:`dqn_route` as a :class:`~uam_studio.planning.missions.check.Plan` (its messages inside, no
    physics check: the caller makes it): the ``"dqn"`` policy of
    :func:`~uam_studio.planning.planner.plan_mission`."""
    messages: list[str] = []
    route, alts = dqn_route(mission, agent_path, predictor, messages, lookahead)
    return Plan("dqn", tuple(route), tuple(alts), messages=tuple(messages))

@functools.lru_cache(maxsize=8)
def _cached_agent(path: str, mtime_ns: int, size: int) -> tuple[Any, dict[str, Any]]:
    from uam_studio.planning.agents.dqn.agent_file import (  # torch: at call time (see above)
        load_agent,
        load_card,
    )

    return load_agent(path), load_card(path)


def load_agent_cached(path: str | os.PathLike[str]) -> tuple[Any, dict[str, Any]]:
    """The agent at ``path`` and its model card, loaded once per file version (path, mtime, size).

    The app replans on every slider move; loading an SB3 zip takes tens of ms, so it is cached.
    :raises InputError: the file is missing or not an agent.
    """
    p = Path(path)
    try:
        st = p.stat()
    except OSError as err:
        raise InputError("agent", f"cannot read {p}: {err.strerror or err}") from None
    return _cached_agent(str(p.resolve()), st.st_mtime_ns, st.st_size)


def _filtered_candidates(env: Any, model: Any, obs: np.ndarray, k: int = 1) -> tuple[list[int], bool]:
    """The agent's best-Q actions whose leg and way home are safe (``lookahead_safe``), best first:
    the first such action anywhere in the ranking, then up to ``k - 1`` more among the agent's
    ``4 k`` best. If none is safe: the vertiport at the agent's preferred level alone, or [] if
    there is nothing to do. Second value: the filter overrode the agent's first choice."""
    from uam_studio.planning.agents.dqn.masked import ranked_actions  # torch: at call time (see above)

    ranked = ranked_actions(model, obs)
    safe: list[int] = []
    for i, a in enumerate(ranked):  # each probe flies up to two legs: stop as soon as possible
        if safe and (len(safe) == k or i >= 4 * k):
            break
        if env.lookahead_safe(a):
            safe.append(int(a))
    overridden = not safe or safe[0] != ranked[0]
    if not safe:  # nothing safe: head home at the agent's preferred level, or stop
        safe = [int(a) for a in ranked if a // N_ALTITUDES == VERTIPORT_SLOT][:1]
    return safe, overridden


ROLLOUT_BASES = ("agent", "greedy")


def _base_action(env: Any, model: Any, obs: np.ndarray, base: str) -> int | None:
    """The next action of a rollout base policy: the filtered agent (``"agent"``) or the greedy
    baseline's rule (``"greedy"``, :meth:`UAMPlanningEnv.greedy_action`); None to stop."""
    if base == "greedy":
        return env.greedy_action()
    choice, _ = _filtered_candidates(env, model, obs)
    return choice[0] if choice else None


def _continuation_return(env: Any, model: Any, action: int, base: str = "agent") -> float:
    """Reward of taking ``action`` on a clone of ``env`` and then following ``base`` (see
    :func:`_base_action`) to the end."""
    twin = env.clone()
    obs, total, terminated, truncated, _ = twin.step(action)
    while not (terminated or truncated):
        nxt = _base_action(twin, model, obs, base)
        if nxt is None:
            break
        obs, r, terminated, truncated, _ = twin.step(nxt)
        total += r
    return float(total)


def rollout_agent(mission: Mission, agent: Any, predictor: Any = None,
                  messages: list[str] | None = None, shield: bool = True, lookahead: int = 0,
                  bases: tuple[str, ...] = ROLLOUT_BASES) -> Plan:
    """Fly a DQN agent greedily on ``mission`` (physics battery) and return its plan.

    :param agent: an agent zip path, or a trained :class:`~uam_studio.planning.agents.dqn.masked.MaskedDQN` (its
        health features are taken to be the physics-only fallback, as in ``uam-studio train dqn``)

    With ``shield`` (default) the agent's actions are filtered: at each step it takes its best-Q
    valid action whose leg *and* the way home stay above the cut-off on the planning battery
    (:meth:`UAMPlanningEnv.lookahead_safe`; here the physics model of the mission's cell), and
    returns home (or stops) when none is. Without it, the raw greedy policy (the paper's setting).

    ``lookahead`` K > 0 (with the filter) is *policy rollout*, a one-step policy improvement: at
    each step the candidates (the agent's K best safe actions, plus the greedy rule's action when
    ``"greedy"`` is in ``bases``) are each tried on a copy of the episode and followed to the end
    by each base policy in ``bases`` (``"agent"``: the filtered agent; ``"greedy"``: the greedy
    baseline's rule, :meth:`UAMPlanningEnv.greedy_action`); the candidate whose best continuation
    earns the most reward (the agent's own objective, ties to the higher Q) is taken. Each base's
    own next action is always a candidate, so the plan never earns less reward than any base policy
    alone would from the start (rollout with several base heuristics); each step costs up to
    (K + 1) x len(bases) extra episodes.

    The mission must already be servable (at most ``N_MAX`` destinations, a cell that finishes the
    take-off); :func:`plan_mission` checks that first. Health features: the predictor's ``health``
    if the agent was trained on Dynaformer features, else the physics-only fallback.
    ``messages`` (if given) receives notes about mismatches; the plan's own messages are in the plan.
    """
    from uam_studio.planning.agents.dqn.masked import greedy_action  # torch: at call time (see above)

    notes = messages if messages is not None else []
    if not bases or any(b not in ROLLOUT_BASES for b in bases):
        raise InputError("bases", f"{bases!r}: allowed a non-empty tuple of {', '.join(ROLLOUT_BASES)}")
    if isinstance(agent, (str, os.PathLike)):
        model, card = load_agent_cached(agent)
    else:
        model, card = agent, {}
    scenario = mission.scenario
    health_fn = None
    if card.get("health") == "dynaformer":
        if predictor is not None and callable(getattr(predictor, "health", None)):
            health_fn = predictor.health
        else:
            notes.append("the agent was trained on Dynaformer health features but no Dynaformer is "
                         "loaded; using the physics-only health features")
    trained_for = card.get("scenario")
    if trained_for is not None and trained_for != scenario:
        notes.append(f"the agent was trained for scenario {trained_for}, the mission is {scenario}")
    env = UAMPlanningEnv(mission=mission, scenario=scenario, backend="physics", health_fn=health_fn)
    if env.observation_space != model.observation_space or env.action_space != model.action_space:
        raise InputError("agent", f"{agent}: incompatible with this environment (agent expects "
                                  f"observations {model.observation_space.shape} and {model.action_space})")
    obs, _ = env.reset(seed=0)
    done = truncated = False
    filtered = 0
    while not done:
        if not shield:
            action = greedy_action(model, obs)
        else:
            # with lookahead: the filtered agent's choice (its best-Q safe action) and the next safe ones
            candidates, overridden = _filtered_candidates(env, model, obs, max(1, lookahead))
            filtered += overridden
            if not candidates:
                break
            choice = candidates[0]
            if lookahead > 0 and "greedy" in bases:
                g = env.greedy_action()
                if g is not None and g not in candidates:
                    candidates.append(g)
            if len(candidates) > 1:
                gains = [max(_continuation_return(env, model, a, b) for b in bases) for a in candidates]
                choice = candidates[int(np.argmax(gains))]  # argmax keeps the first (best-Q) of ties
            action = choice
        obs, _, terminated, truncated, _ = env.step(action)
        done = terminated or truncated
    plan = env.episode_plan(("dqn+rollout" if lookahead > 0 else "dqn+shield") if shield else "dqn")
    if filtered:
        notes.append(f"safety filter: {filtered} of the agent's choices would not have left a safe way home; "
                     "replaced by its next-best safe choice")
    if truncated:
        notes.append(f"the agent did not finish within {env.max_steps} legs")
    return plan
