"""The Planner state's planner comparison: which planners are compared on the shown plan's mission, the
rows known at once, the others computed in the background, and their results as they arrive.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable
from typing import Any

from uam_studio.app.planner.comparison import (
    COMPARE_DELAY_S,
    COMPARE_LABELS,
    DEFAULT_POLICY,
    ORACLE_REFERENCE_LABEL,
    PAPER_POLICY,
    cached_row,
    cancel_comparisons,
    compare_row,
    comparison_runner,
    store_row,
)
from uam_studio.app.planner.mission import mission_digest
from uam_studio.app.planner.plans import PlanRequest
from uam_studio.app.services import AGENT_PREFIX, LEARNED_POLICIES, agent_policy, default_policy
from uam_studio.planning.legs import N_MAX


class PlannerComparison:
    """The planner comparison of :class:`~uam_studio.app.planner.state.PlannerState` (its
    ``comparison``), mixed into the state: it reads the state's ``compare`` mode, ``dispatch``,
    ``plan_request`` and :meth:`policy_label`, and keeps ``_compare_key`` and ``_compare_timer``."""

    # the state's, declared for the type checker (PlannerState sets them; ``comparison`` is also written here)
    compare: str
    dispatch: Callable[[Callable[[], None]], None]
    plan_request: PlanRequest | None
    comparison: dict[str, Any] | None
    policy_label: Callable[[str], str]
    _compare_key: tuple | None
    _compare_timer: threading.Timer | None

    def _compare_specs(self, req: PlanRequest) -> dict[str, tuple[str, str]]:
        """Row name -> (policy value, label): the agent (the selected learned planner: the attention
        planner, the paper's DQN or a retrained agent; with greedy or the oracle selected, the
        default learned planner), the default attention planner beside any other agent, the paper's DQN
        beside an attention agent, greedy and the oracle."""
        from uam_studio.planning.solvers.oracle import EXACT_MAX

        if req.policy in LEARNED_POLICIES or req.policy.startswith(AGENT_PREFIX):
            agent = req.policy
        else:
            agent = default_policy(req.mission.scenario)
            agent = agent if agent in LEARNED_POLICIES else "attention"
        oracle = "Oracle (exact)" if len(req.mission.destinations) <= EXACT_MAX else ORACLE_REFERENCE_LABEL
        label = COMPARE_LABELS.get(agent) or self.policy_label(agent)
        specs = {"agent": (agent, label)}
        if agent != DEFAULT_POLICY:  # the default planner is always in the table (beside DQN or a retrained agent)
            specs["default"] = (DEFAULT_POLICY, COMPARE_LABELS[DEFAULT_POLICY])
        if agent_policy(agent)[0] != PAPER_POLICY:  # a (retrained) DQN is the paper's method
            specs["paper"] = (PAPER_POLICY, COMPARE_LABELS[PAPER_POLICY])
        return {**specs, "greedy": ("greedy", "Greedy"), "oracle": ("oracle", oracle)}

    def _update_comparison(self) -> None:
        """Compare the shown plan's mission across planners: rows known to this process at once, the
        others computed as :attr:`compare` says (their rows stay ``pending`` until then)."""
        req = self.plan_request
        if self.compare == "off" or req is None:
            return
        specs = self._compare_specs(req)
        key = (req.mission, specs["agent"][0])
        if key == self._compare_key:
            return  # e.g. only the policy changed between greedy and the oracle: same rows
        self._stop_comparison()
        self._compare_key = key
        rows: dict[str, dict[str, Any]] = {}
        missing = []
        for name, (value, label) in specs.items():
            preq = PlanRequest(req.mission, value)
            if name == "paper" and len(req.mission.destinations) > N_MAX:
                rows[name] = {"label": label, "policy": value, "status": "unavailable",
                              "error": f"the paper's DQN holds at most {N_MAX} destinations"}
                continue
            row = cached_row(preq)
            rows[name] = {"label": label, "policy": value, **(row or {"status": "pending", "error": None})}
            if row is None:
                missing.append((name, preq))
        self.comparison = {"scenario": req.mission.scenario, "inputs": mission_digest(req.mission),
                           "rows": rows}
        if not missing:
            return
        if self.compare == "inline":
            for name, preq in missing:
                row = compare_row(preq.mission, preq.policy)
                store_row(preq, row)
                self._comparison_result(key, name, row)
            return
        tasks = [(preq, functools.partial(self._on_row, key, name)) for name, preq in missing]
        runner = comparison_runner(self.compare)
        timer = threading.Timer(COMPARE_DELAY_S, runner.submit, args=(id(self), tasks))
        timer.daemon = True
        self._compare_timer = timer
        timer.start()

    def _stop_comparison(self) -> None:
        if self._compare_timer is not None:
            self._compare_timer.cancel()
            self._compare_timer = None
        if self.compare in ("process", "thread"):
            cancel_comparisons(self.compare, id(self))

    def _on_row(self, key: tuple, name: str, row: dict[str, Any]) -> None:
        self.dispatch(functools.partial(self._comparison_result, key, name, row))

    def _comparison_result(self, key: tuple, name: str, row: dict[str, Any]) -> None:
        if key != self._compare_key or self.comparison is None:
            return  # the mission changed meanwhile
        rows = dict(self.comparison["rows"])
        rows[name] = {**rows[name], **row}
        self.comparison = {**self.comparison, "rows": rows}

    def comparison_pending(self) -> bool:
        """Some comparison row is still being computed."""
        c = self.comparison
        return c is not None and any(r.get("status") == "pending" for r in c["rows"].values())
