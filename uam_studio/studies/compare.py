"""How near optimal is a policy: every planner on the same missions, scored against the oracle.

Public API:

- :func:`compare_planners`: plan each mission with the oracle, the greedy baseline, the attention
  planner (the default of ``plan_mission``) and (optionally) a DQN agent, check every plan with the
  physics model, and return one :class:`PlanScore` per (mission, policy).
- :func:`summarize`: the figures the planning issue asks for, per policy: mean gap in reached
  priority to the oracle (single charge), share of missions with the oracle's number of charging
  cycles (multi charge), EOD-breach rate, and planning time.

Scoring rules (stated here because they change the numbers):

* a plan that breaches EOD under physics (``safe`` False) scores **0 priority** and counts as a
  breach: an unsafe plan is not a plan anyone may fly;
* the gap of one mission is ``(oracle - policy) / oracle`` in reached priority; missions where the
  oracle reaches nothing are skipped; the mean gap is the mean of those per-mission gaps;
* multi charge "same cycles" needs the policy to reach every destination the oracle reaches, safely,
  with the same number of charging cycles (fewer is impossible against an exact oracle).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from uam_studio.planning.missions.check import Plan, check_plan
from uam_studio.planning.missions.mission import Mission

__all__ = ["ROLLOUT_K", "PlanScore", "compare_planners", "per_mission_gaps", "summarize"]

ROLLOUT_K = 6  # candidate actions per step of the dqn_rollout policy


@dataclass(frozen=True)
class PlanScore:
    """One planner on one mission, checked with the physics model.

    :param mission: mission name
    :param policy: ``"oracle"``, ``"greedy"``, ``"attention"``, ``"dqn"`` or a variant (see
        :func:`compare_planners`)
    :param reached_priority: priority reached safely (0 for an unsafe plan)
    :param reached: destinations reached safely (0 for an unsafe plan)
    :param charging_cycles: charging cycles of the checked route
    :param safe: the route never goes below the cut-off under physics
    :param min_voltage_v: lowest physics voltage on the route (V), None for an empty route
    :param plan_s: wall time of planning (s), the physics check excluded
    """

    mission: str
    policy: str
    reached_priority: int
    reached: int
    charging_cycles: int
    safe: bool
    min_voltage_v: float | None
    plan_s: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _score(mission: Mission, plan: Plan, plan_s: float, policy: str) -> PlanScore:
    check = check_plan(mission, plan.route, plan.altitudes_m)
    prio = {d.name: d.priority for d in mission.destinations}
    reached = check.sim.reached if check.safe and check.sim is not None else ()
    cycles = int(check.sim.charging_cycles) if check.sim is not None else 0
    return PlanScore(mission.name, policy, int(sum(prio[n] for n in reached)), len(reached), cycles,
                     bool(check.safe), check.min_voltage_v, float(plan_s))


def compare_planners(
    missions: Iterable[Mission],
    agent_path: str | os.PathLike[str] | None = None,
    policies: Sequence[str] = ("oracle", "greedy", "dqn"),
    progress: Callable[[int], Any] | None = None,
) -> list[PlanScore]:
    """Plan every mission with every policy and score the plans with the physics model.

    :param missions: the missions (their own scenario, battery and cut-off are used)
    :param agent_path: DQN agent (zip path or trained model), needed for the ``dqn`` policies (the
        ``attention`` policies use the bundled attention planner)
    :param policies: any of ``"oracle"``, ``"greedy"``, ``"attention"`` (the bundled attention planner as
        ``plan_mission(m, "attention")`` runs it: beam search behind the physics safety filter, 1-20
        destinations), ``"attention_raw"`` (the network's own best choice at every step, no search, no
        filter), ``"dqn"`` (the agent with the safety filter of
        :func:`~uam_studio.planning.agents.dqn.rollout.rollout_agent`, as ``uam-studio plan --policy dqn`` runs it) and
        ``"dqn_raw"`` (the agent's own greedy choices, the paper's setting) and ``"dqn_rollout"``
        (the filtered agent improved by policy rollout over its ``ROLLOUT_K`` best safe actions and
        the greedy rule's action, each continued by the filtered agent and by the greedy rule), and
        ``"dqn_rollout_agent"`` (the same rollout with the filtered agent as its only base policy)
    :param progress: called with the number of missions done so far (e.g. a tqdm ``update``)
    :return: one :class:`PlanScore` per mission and policy, missions in order
    """
    from uam_studio.errors import InputError
    from uam_studio.planning.agents.attention.decode import attention_plan, load_policy_cached
    from uam_studio.planning.agents.dqn.rollout import rollout_agent
    from uam_studio.planning.solvers.greedy import greedy_plan
    from uam_studio.planning.solvers.oracle import oracle_plan

    if any(p.startswith("dqn") for p in policies) and agent_path is None:
        raise InputError("agent_path", "needed to compare the dqn policy")
    planners: dict[str, Callable[[Mission], Plan]] = {
        "oracle": oracle_plan,
        "greedy": greedy_plan,
        "attention": lambda m: attention_plan(m, load_policy_cached()),
        "attention_raw": lambda m: attention_plan(m, load_policy_cached(), beam_width=1, safety_filter=False),
        "dqn": lambda m: rollout_agent(m, agent_path, shield=True),
        "dqn_raw": lambda m: rollout_agent(m, agent_path, shield=False),
        "dqn_rollout": lambda m: rollout_agent(m, agent_path, shield=True, lookahead=ROLLOUT_K),
        "dqn_rollout_agent": lambda m: rollout_agent(m, agent_path, shield=True, lookahead=ROLLOUT_K,
                                                     bases=("agent",)),
    }
    for p in policies:
        if p not in planners:
            raise InputError("policies", f"{p!r} is not a policy; allowed: {', '.join(planners)}")
    scores: list[PlanScore] = []
    for i, mission in enumerate(missions):
        for p in policies:
            t0 = time.perf_counter()
            plan = planners[p](mission)
            scores.append(_score(mission, plan, time.perf_counter() - t0, p))
        if progress is not None:
            progress(i + 1)
    return scores


def per_mission_gaps(scores: Sequence[PlanScore], reference: str = "oracle") -> dict[str, list[float]]:
    """Per policy, the gap ``(reference - policy) / reference`` in reached priority of every mission
    where the reference reaches something (fractions, missions in order)."""
    by_mission: dict[str, dict[str, PlanScore]] = {}
    for s in scores:
        by_mission.setdefault(s.mission, {})[s.policy] = s
    out: dict[str, list[float]] = {}
    for m in by_mission.values():
        ref = m.get(reference)
        if ref is None or ref.reached_priority <= 0:
            continue
        for p, s in m.items():
            out.setdefault(p, []).append((ref.reached_priority - s.reached_priority) / ref.reached_priority)
    return out


def summarize(scores: Sequence[PlanScore], reference: str = "oracle") -> dict[str, dict[str, float]]:
    """Per policy: the figures of merit against ``reference`` (see the module docstring).

    :return: ``{policy: {"missions", "mean_priority", "mean_gap", "p90_gap", "worst_gap",
        "same_cycles", "mean_cycles", "eod_breach_rate", "median_plan_s", "max_plan_s"}}``;
        gaps are fractions (0.05 = 5%), ``same_cycles`` the share of missions with the reference's
        cycle count and every reference destination reached safely.
    """
    by_mission: dict[str, dict[str, PlanScore]] = {}
    for s in scores:
        by_mission.setdefault(s.mission, {})[s.policy] = s
    policies = sorted({s.policy for s in scores})
    out: dict[str, dict[str, float]] = {}
    for p in policies:
        rows = [m for m in by_mission.values() if p in m]
        gaps = []
        same = []
        for m in rows:
            ref = m.get(reference)
            if ref is None:
                continue
            if ref.reached_priority > 0:
                gaps.append((ref.reached_priority - m[p].reached_priority) / ref.reached_priority)
            same.append(m[p].safe and m[p].reached >= ref.reached
                        and m[p].charging_cycles == ref.charging_cycles)
        own = [m[p] for m in rows]
        t = np.array([s.plan_s for s in own]) if own else np.zeros(1)
        out[p] = {
            "missions": len(own),
            "mean_priority": float(np.mean([s.reached_priority for s in own])) if own else 0.0,
            "mean_reached": float(np.mean([s.reached for s in own])) if own else 0.0,
            "mean_gap": float(np.mean(gaps)) if gaps else 0.0,
            "p90_gap": float(np.percentile(gaps, 90)) if gaps else 0.0,
            "worst_gap": float(np.max(gaps)) if gaps else 0.0,
            "same_cycles": float(np.mean(same)) if same else 0.0,
            "mean_cycles": float(np.mean([s.charging_cycles for s in own])) if own else 0.0,
            "eod_breach_rate": float(np.mean([not s.safe for s in own])) if own else 0.0,
            "median_plan_s": float(np.median(t)),
            "max_plan_s": float(np.max(t)),
        }
    return out
