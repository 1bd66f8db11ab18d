"""The planners, in one place: what every other module needs to know about each one.

:data:`PLANNERS` maps a policy name (``plan_mission(policy=...)``, ``uam-studio plan --policy``, the
app's planner menu) to its :class:`PlannerInfo`: its label, the agent file it reads, how many
destinations it plans, which options apply, whether the in-flight operator can re-plan with it, and the
function that plans with it (``"module:function"``, imported when first used, so that this catalogue
imports no planner, and no planner's torch).

Adding a planner: write its plan function (``(mission, *, agent_path, predictor, lookahead) -> Plan``,
taking only the keywords its entry says it uses), then add its entry here; a learned one that can be
retrained also names its :class:`~uam_studio.planning.agents.trainer.Trainer`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from uam_studio.errors import InputError
from uam_studio.planning.legs import N_MAX
from uam_studio.planning.missions.mission import MAX_DESTINATIONS

__all__ = ["IN_FLIGHT_PLANNERS", "LEARNED_POLICIES", "PAPER_PLANNER", "PLANNERS", "POLICIES", "REFERENCE_PLANNER",
           "PlannerInfo", "planner_info"]


@dataclass(frozen=True, kw_only=True)
class PlannerInfo:
    """One planner.

    :param name: the policy name.
    :param label: as the app's planner menu shows it.
    :param plan: ``"module:function"`` of its plan function, returning a
        :class:`~uam_studio.planning.missions.check.Plan`.
    :param agent_file: the bundled file it reads (``{scenario}`` is the mission's scenario), or None for a
        planner that reads no agent file (then ``agent_path`` is refused).
    :param max_destinations: the most destinations it plans (the paper's DQN: its action space's 8).
    :param fixed_slots: its action space has :data:`~uam_studio.planning.legs.N_MAX` destination slots
        whatever the mission's size (the leg table it plans on is padded to them).
    :param lookahead: ``plan_mission``'s policy-rollout ``lookahead`` applies (0-8).
    :param reads_predictor: its agent may read the Dynaformer's prediction (the plan function then takes
        ``predictor``).
    :param reports_exact: its plan says whether it is proven optimal (``stats["exact"]``; the oracle: exact
        up to 8 destinations, a reference solver's plan past them).
    :param in_flight: the operator (:mod:`~uam_studio.planning.operations`) can re-plan with it in flight.
    :param trainer: ``"module:Class"`` of its :class:`~uam_studio.planning.agents.trainer.Trainer` (retraining
        it in the app and finding its retrained files), or None: it cannot be retrained.
    :param train_label: as the Retrain tab's planner buttons show it.
    :param paper: it is the paper's agent (:data:`PAPER_PLANNER`: the Retrain tab's first planner).
    """

    name: str
    label: str
    plan: str
    agent_file: str | None = None
    max_destinations: int = MAX_DESTINATIONS
    fixed_slots: bool = False
    lookahead: bool = False
    reads_predictor: bool = False
    reports_exact: bool = False
    in_flight: bool = False
    trainer: str | None = None
    train_label: str = ""
    paper: bool = False

    @property
    def learned(self) -> bool:
        """It plans with a trained network read from an agent file."""
        return self.agent_file is not None

    def bundled_file(self, scenario: str) -> str | None:
        """The bundled agent file's name for a mission of ``scenario``, or None (no agent file)."""
        return None if self.agent_file is None else self.agent_file.format(scenario=scenario)

    def plan_function(self) -> Callable[..., object]:
        """Its plan function (imported now)."""
        return _imported(self.plan)

    def trainer_class(self) -> type | None:
        """Its :class:`~uam_studio.planning.agents.trainer.Trainer` class (imported now), or None."""
        return None if self.trainer is None else _imported(self.trainer)


def _imported(ref: str) -> Any:
    """The object a ``"module:name"`` reference names, its module imported now."""
    module, _, attr = ref.partition(":")
    return getattr(importlib.import_module(module), attr)


PLANNERS: dict[str, PlannerInfo] = {p.name: p for p in (
    PlannerInfo(name="attention", label="Attention (bundled, default)", agent_file="attention_planner.pt",
                plan="uam_studio.planning.agents.attention.decode:plan_with_weights", in_flight=True,
                trainer="uam_studio.planning.agents.attention.retrain:AttentionTrainer",
                train_label="Attention (default)"),
    PlannerInfo(name="dqn", label="DQN (paper, up to 8)", agent_file="dqn_{scenario}.zip",
                plan="uam_studio.planning.agents.dqn.rollout:dqn_plan", max_destinations=N_MAX,
                fixed_slots=True, lookahead=True, reads_predictor=True,
                trainer="uam_studio.planning.agents.dqn.retrain:DQNTrainer", train_label="DQN (paper)",
                paper=True),
    PlannerInfo(name="oracle", label="Oracle (exact up to 8)", plan="uam_studio.planning.solvers.oracle:oracle_plan",
                reports_exact=True, in_flight=True),
    PlannerInfo(name="greedy", label="Greedy", plan="uam_studio.planning.solvers.greedy:greedy_plan"),
)}
POLICIES = tuple(PLANNERS)  # the default first
LEARNED_POLICIES = tuple(n for n, p in PLANNERS.items() if p.learned)
IN_FLIGHT_PLANNERS = tuple(n for n, p in PLANNERS.items() if p.in_flight)  # the operator's (the first: its default)
REFERENCE_PLANNER = next(n for n, p in PLANNERS.items() if p.reports_exact)  # what the others are compared to
PAPER_PLANNER = next(n for n, p in PLANNERS.items() if p.paper)  # the paper's agent


def planner_info(name: str, field: str = "policy", among: tuple[str, ...] | None = None) -> PlannerInfo:
    """The planner called ``name``.

    :raises InputError: (field ``field``) for a name not in ``among`` (default: every planner of
        :data:`PLANNERS`), listing the allowed ones.
    """
    among = tuple(PLANNERS) if among is None else among
    if name not in among:
        raise InputError(field, f"{name!r} is not a policy; allowed: {', '.join(among)}")
    return PLANNERS[name]
