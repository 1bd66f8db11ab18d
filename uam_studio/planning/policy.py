"""One entry point for planning a mission with any policy: :func:`plan_mission`.

The CLI (``uam-studio plan``) and the Panel app call only this function. It

1. runs the chosen planner: ``"oracle"`` (exact, :func:`~uam_studio.planning.oracle.oracle_plan`),
   ``"greedy"`` (baseline, :func:`~uam_studio.planning.greedy.greedy_plan`) or ``"dqn"`` (a trained
   masked DQN agent rolled out greedily in a :class:`~uam_studio.planning.env.UAMPlanningEnv` built
   on this mission with the physics battery);
2. re-checks the route with the physics model (:func:`~uam_studio.planning.check.check_plan`):
   ``reached``, ``charging_cycles``, ``safe`` and ``min_voltage_v`` always come from this check,
   whoever planned the route;
3. predicts the route's voltage with the Dynaformer, sortie by sortie (context: the first 20 s of
   the take-off as the physics model flies it for this cell; profile: the route's current since the
   last recharge), and concatenates the sorties.

The result is a plain-JSON dict (see :func:`plan_mission`). Hard missions (no destinations, more
than 8, unreachable destinations, a cell that cannot finish the take-off) and a missing Dynaformer
give messages, never exceptions; bad input (an invalid mission, an unknown policy, out-of-range
``q_max``/``r0``, an explicit ``agent_path`` that cannot be loaded) and a missing bundled agent
(``dqn`` without ``agent_path``, :func:`bundled_agent_path`) raise :class:`~uam_studio.errors.InputError`.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any

import numpy as np

from uam_studio.bundled import bundled_path, require_bundled
from uam_studio.errors import InputError
from uam_studio.planning.check import Plan, PlanCheck, check_plan
from uam_studio.planning.mission import SCENARIOS, VERTIPORT, Mission, load_mission, mission_from_dict

POLICIES = ("dqn", "oracle", "greedy")
MAX_POINTS = 2000  # samples per series in the result (JSON size)
DECIMALS = 4

__all__ = ["MAX_POINTS", "POLICIES", "bundled_agent_path", "load_agent_cached", "plan_mission",
           "rollout_agent"]


def bundled_agent_path(scenario: str) -> Path:
    """The bundled DQN agent of ``scenario``, ``dqn_<scenario>.zip`` (:func:`uam_studio.bundled.bundled_path`:
    the user folder's ``pretrained/`` first, then the package data); it may not exist."""
    return bundled_path(f"dqn_{scenario}.zip")


# ----------------------------------------------------------------------------- helpers


def _as_mission(mission: Any) -> Mission:
    if isinstance(mission, Mission):
        return mission
    if isinstance(mission, (str, os.PathLike)):
        return load_mission(mission)
    return mission_from_dict(mission)


def _round_list(a: np.ndarray) -> list[float]:
    a = np.nan_to_num(np.asarray(a, dtype=float), nan=0.0, posinf=0.0, neginf=0.0)
    return [float(x) for x in np.round(a, DECIMALS)]


def _round_opt(x: float | None) -> float | None:
    return None if x is None else round(float(x), DECIMALS)


def _sample_index(n: int, keep: list[int]) -> np.ndarray:
    """At most ``MAX_POINTS`` indices of ``n`` samples, evenly spread, always with the first, last and ``keep``."""
    if n <= MAX_POINTS:
        return np.arange(n)
    base = np.linspace(0, n - 1, MAX_POINTS - len(keep)).round().astype(int)
    return np.unique(np.concatenate([base, np.asarray(keep, dtype=int)]))


def _dedupe(messages: list[str]) -> list[str]:
    out: list[str] = []
    for m in messages:
        if m and m not in out:
            out.append(m)
    return out


# ----------------------------------------------------------------------------- DQN rollout


def _dqn_route(mission: Mission, agent_path: str | os.PathLike[str] | None, predictor: Any,
               messages: list[str], lookahead: int = 0) -> tuple[list[str], list[float]]:
    """Roll the agent out greedily on ``mission`` (physics battery); messages for what went wrong."""
    from uam_studio.planning.actions import VERTIPORT_SLOT
    from uam_studio.planning.oracle import _too_close, prepare_mission

    setup = prepare_mission(mission, None, "dqn")  # the oracle's and greedy's preamble
    if setup.early is not None:
        messages.extend(setup.early.messages)
        return [], []
    messages.extend(setup.messages)
    mission, legs, scenario = setup.mission, setup.legs, setup.scenario
    dests = mission.destinations
    for k in range(len(dests) if scenario != "single_flight" else 1):
        reason = _too_close(legs, k)
        if reason is not None:
            messages.append(reason)
    servable = legs.feasible[VERTIPORT_SLOT, :len(dests), 0]
    if scenario == "single_flight":
        if len(dests) > 1:
            messages.append(f"single flight: planning the leg to {dests[0].name} only")
        servable = servable[:1]
    if not servable.any():
        return [], []

    path = bundled_agent_path(scenario) if agent_path is None else Path(agent_path)

    plan = rollout_agent(mission, path, predictor, messages, lookahead=lookahead)
    messages.extend(m for m in plan.messages if not m.startswith("end of discharge"))  # physics check says it
    return list(plan.route), list(plan.altitudes_m)


@functools.lru_cache(maxsize=8)
def _cached_agent(path: str, mtime_ns: int, size: int) -> tuple[Any, dict[str, Any]]:
    from uam_studio.planning.training import load_agent, load_card

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
    from uam_studio.planning.actions import N_ALTITUDES, VERTIPORT_SLOT
    from uam_studio.planning.training import ranked_actions

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

    :param agent: an agent zip path, or a trained :class:`~uam_studio.planning.dqn.MaskedDQN` (its
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
    from uam_studio.planning.env import UAMPlanningEnv
    from uam_studio.planning.training import greedy_action

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


# ----------------------------------------------------------------------------- Dynaformer prediction


def _load_predictor(predictor: Any, messages: list[str]) -> Any:
    if predictor is False:
        return None
    if predictor is not None:
        return predictor
    try:
        from uam_studio.dynaformer import WeightsError, load_pretrained
    except ImportError as err:  # torch missing
        messages.append(f"Dynaformer unavailable ({err}); showing the physics model only")
        return None
    try:
        return load_pretrained()
    except WeightsError as err:
        messages.append(f"no Dynaformer weights ({err}); showing the physics model only")
        return None


def _predict(check: PlanCheck, predictor: Any, messages: list[str]) -> np.ndarray | None:
    """Dynaformer voltage on the physics route's time grid, sortie by sortie, or None."""
    from uam_studio.planning.env import CONTEXT_S, observe_takeoff

    sim = check.sim
    assert sim is not None
    ci, cv = observe_takeoff(sim.q_max, sim.r0)
    ci, cv = ci[:CONTEXT_S], cv[:CONTEXT_S]
    cuts = [0]
    for leg in sim.legs:
        if leg.reached and leg.to == VERTIPORT and leg.end_s is not None:
            cuts.append(int(round(leg.end_s / sim.dt_s)))
    n = sim.current_a.size
    cuts = sorted({c for c in cuts if c < n} | {n})
    parts = []
    try:
        for a, b in zip(cuts[:-1], cuts[1:]):
            v = np.asarray(predictor.predict(ci, cv, sim.current_a[a:b], dt_s=sim.dt_s), dtype=float)
            parts.append(v.reshape(-1)[: b - a])
    except (InputError, ValueError, RuntimeError) as err:
        messages.append(f"Dynaformer prediction failed ({' '.join(str(err).split())}); "
                        "showing the physics model only")
        return None
    return np.concatenate(parts) if parts else np.zeros(0)


# ----------------------------------------------------------------------------- entry point


def plan_mission(
    mission: Mission | dict | str | os.PathLike[str],
    policy: str = "dqn",
    q_max: float | None = None,
    r0: float | None = None,
    agent_path: str | os.PathLike[str] | None = None,
    predictor: Any = None,
    lookahead: int = 0,
) -> dict[str, Any]:
    """Plan ``mission`` with ``policy``, check it with the physics model, predict it with the Dynaformer.

    :param mission: a :class:`Mission`, a dict in the mission JSON format, or a path to a mission file.
    :param policy: ``"dqn"``, ``"oracle"`` or ``"greedy"``.
    :param q_max: override the mission's q_max (C).
    :param r0: override the mission's r0 (ohm).
    :param agent_path: the DQN agent (default: the bundled ``dqn_<scenario>.zip``, :func:`bundled_agent_path`;
        its absence raises InputError).
    :param predictor: a Dynaformer predictor (``predict(context_current_a, context_voltage_v, current_a,
        dt_s)``), None for the bundled one (its absence is a message), or False to skip the prediction.
    :param lookahead: dqn only: policy rollout over the agent's K best safe actions (and the greedy
        rule's action) per step, continued by the filtered agent and by the greedy rule
        (:func:`rollout_agent`); 0 (default) for the filtered agent alone; 0-8.
    :return: plain-JSON dict with exactly the keys ``policy``, ``route`` (node names, ``"vertiport"``
        = recharge), ``altitudes_m``, ``charging_cycles``, ``reached`` (names), ``reached_priority``,
        ``predicted`` (``{"time_s", "voltage_v"}`` or None), ``physics`` (``{"time_s", "voltage_v",
        "eod_s"}``), ``safe``, ``min_voltage_v`` (None for an empty route) and ``messages``. Series
        are rounded to 4 decimals and thinned to at most :data:`MAX_POINTS` samples (the lowest
        physics and predicted voltages are always kept).
    :raises InputError: bad input or a missing bundled agent (see the module docstring); never for a
        hard mission.
    """
    if policy not in POLICIES:
        raise InputError("policy", f"{policy!r} is not a policy; allowed: {', '.join(POLICIES)}")
    if isinstance(lookahead, bool) or not isinstance(lookahead, (int, np.integer)) or not 0 <= lookahead <= 8:
        raise InputError("lookahead", f"{lookahead!r} is out of range; allowed integers in [0, 8]")
    m = _as_mission(mission)
    if q_max is not None or r0 is not None:
        m = m.with_battery(q_max, r0)
    if m.scenario not in SCENARIOS:  # pragma: no cover - Mission validates it
        raise InputError("scenario", f"{m.scenario!r} is not a scenario")
    if policy == "dqn" and agent_path is None:  # an install without the agent: an error, not an empty plan
        require_bundled(f"dqn_{m.scenario}.zip", "agent", "agent",
                        "plan with the oracle or greedy policy, or give an agent file")
    messages: list[str] = []

    pred_model = _load_predictor(predictor, messages)
    if policy == "oracle":
        from uam_studio.planning.oracle import oracle_plan

        plan = oracle_plan(m)
        route, alts = list(plan.route), list(plan.altitudes_m)
        messages.extend(plan.messages)
    elif policy == "greedy":
        from uam_studio.planning.greedy import greedy_plan

        plan = greedy_plan(m)
        route, alts = list(plan.route), list(plan.altitudes_m)
        messages.extend(plan.messages)
    else:
        route, alts = _dqn_route(m, agent_path, pred_model, messages, int(lookahead))

    check = check_plan(m, route, alts)
    reached = list(check.sim.reached) if check.sim is not None else []
    if not check.safe:
        messages.append(check.message)
    prio = {d.name: d.priority for d in m.destinations}

    physics: dict[str, Any] = {"time_s": [], "voltage_v": [], "eod_s": None}
    predicted: dict[str, Any] | None = None
    if check.sim is not None:
        sim = check.sim
        v_pred = _predict(check, pred_model, messages) if pred_model is not None else None
        if v_pred is not None and v_pred.size != sim.voltage_v.size:
            messages.append(f"Dynaformer returned {v_pred.size} samples for {sim.voltage_v.size}; "
                            "showing the physics model only")
            v_pred = None
        keep = [int(np.argmin(sim.voltage_v))] + ([int(np.argmin(v_pred))] if v_pred is not None else [])
        idx = _sample_index(sim.time_s.size, keep)
        t = _round_list(sim.time_s[idx])
        physics = {"time_s": t, "voltage_v": _round_list(sim.voltage_v[idx]), "eod_s": _round_opt(sim.eod_s)}
        if v_pred is not None:
            predicted = {"time_s": list(t), "voltage_v": _round_list(v_pred[idx])}

    return {
        "policy": policy,
        "route": [str(r) for r in route],
        "altitudes_m": [float(a) for a in alts],
        "charging_cycles": int(check.sim.charging_cycles) if check.sim is not None else 0,
        "reached": reached,
        "reached_priority": int(sum(prio[n] for n in reached)),
        "predicted": predicted,
        "physics": physics,
        "safe": bool(check.safe),
        "min_voltage_v": _round_opt(check.min_voltage_v),
        "messages": _dedupe(messages),
    }
