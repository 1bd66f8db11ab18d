"""The Gymnasium env's queries on its episode, which leave the episode unchanged: the safety look-ahead
of an action, the greedy rule's next action, a what-if clone, the action mask, the episode as a
:class:`~uam_studio.planning.missions.check.Plan` and as text (``render``). :class:`EpisodeQueries` is a
base of :class:`~uam_studio.planning.env.environment.UAMPlanningEnv`, which holds the episode's state.
"""

from __future__ import annotations

import copy
from typing import TypeVar

import gymnasium as gym
import numpy as np

from uam_studio.planning.env.backends import BatteryBackend
from uam_studio.planning.episode import Episode
from uam_studio.planning.legs import N_ACTIONS, N_ALTITUDES, N_MAX, VERTIPORT_SLOT, LegTable
from uam_studio.planning.missions.check import Plan
from uam_studio.planning.missions.mission import Mission

_Env = TypeVar("_Env", bound="EpisodeQueries")


class EpisodeQueries:
    """What :class:`~uam_studio.planning.env.environment.UAMPlanningEnv` answers about its episode
    without stepping it (planners' look-ahead, rendering, the plan so far)."""

    # the episode's state, set by UAMPlanningEnv (its __init__ and reset())
    render_mode: str | None
    scenario: str
    max_steps: int
    backend: BatteryBackend
    mission: Mission | None
    _episode: Episode
    _legs: LegTable
    _health: np.ndarray
    _node: int
    _visited: np.ndarray
    _mask: np.ndarray
    _obs: np.ndarray
    _voltage: float
    _steps: int
    _cycles: int
    _route: list[str]
    _alts: list[float]
    _reached: list[str]
    _reached_priority: int
    _return: float
    _eod: bool
    _invalid: bool
    _stranded: bool
    _done: bool

    def render(self) -> str | None:
        """With ``render_mode="ansi"``: the episode so far as text (scenario, mission, step, state,
        the legs flown with their altitudes, destinations reached, charging cycles, voltage, return).
        Without a render mode: None, with a gymnasium warning."""
        if self.render_mode is None:
            gym.logger.warn("render() without a render mode; create the env with render_mode='ansi'")
            return None
        if self.mission is None:
            return f"{self.scenario}: no episode yet (call reset())\n"
        if self._eod:
            state = "end of discharge"
        elif self._stranded:
            state = "stranded (no safe way home)"
        elif self._invalid:
            state = "invalid action"
        elif self._done:
            state = "done" if not self._mask.any() else "truncated"
        else:
            state = "running"
        legs = "".join(f" -> {n} ({a:g} m)" for n, a in zip(self._route, self._alts))
        reached = ", ".join(self._reached) or "none"
        return (f"{self.scenario} | {self.mission.name} | step {self._steps}/{self.max_steps} | {state}\n"
                f"route: vertiport{legs}\n"
                f"reached: {reached} (priority {self._reached_priority}); charging cycles {self._cycles}\n"
                f"voltage {self._voltage:.3f} V (cut-off {self.mission.eod_v:g} V); return {self._return:.2f}\n")

    def lookahead_safe(self, action: int) -> bool:
        """Would this env's battery fly ``action``'s leg and then the way home, never below the cut-off?

        The way home is the leg from the target back to the vertiport at its least-charge feasible
        level (nothing more for an action that lands at the vertiport, or in single flight, which
        ends at the destination). It is flown on a copy of the
        backend (physics or Dynaformer: what this env believes), so the episode is not changed. A
        planner uses it as a safety filter (:func:`uam_studio.planning.agents.dqn.rollout.rollout_agent`).
        """
        a = int(action)
        if self._done or not (0 <= a < N_ACTIONS and self._mask[a]):
            return False
        target, ai = divmod(a, N_ALTITUDES)
        probe = copy.copy(self.backend)
        if probe.fly_leg(self._legs.current(self._node, target, ai)).eod:
            return False
        return self._home_reachable(probe, target)

    def _home_reachable(self, backend: BatteryBackend, node: int) -> bool:
        """Could ``backend`` (left unchanged) fly from ``node`` home at the least-charge level?"""
        if node == VERTIPORT_SLOT or self._episode.rules.one_leg:  # single flight: no way back
            return True
        home = self._legs.cheapest_level(node, VERTIPORT_SLOT)
        if home is None:
            return False
        return not copy.copy(backend).fly_leg(self._legs.current(node, VERTIPORT_SLOT, home)).eod

    def greedy_action(self) -> int | None:
        """The greedy baseline's next action in this episode (the rule of
        :func:`uam_studio.planning.solvers.greedy.greedy_plan`, on this env's battery): the unvisited
        destination with the best priority / distance from here whose leg, at its least-charge
        level, and the way home are safe (:meth:`lookahead_safe`); else the vertiport at its
        least-charge level; None when there is nothing left to do (at the vertiport, nothing fits)."""
        if self._done:
            return None
        legs, node = self._legs, self._node
        todo = [int(k) for k in np.flatnonzero(self._episode.targets(node, self._visited)[0, :N_MAX])]
        for k in legs.greedy_order(node, todo):
            level = legs.cheapest_level(node, k)
            if level is not None and self.lookahead_safe(k * N_ALTITUDES + level):
                return k * N_ALTITUDES + level
            if self._episode.rules.one_leg:
                return None
        if node == VERTIPORT_SLOT or self._episode.rules.one_leg:
            return None
        level = legs.cheapest_level(node, VERTIPORT_SLOT)
        return None if level is None else VERTIPORT_SLOT * N_ALTITUDES + level

    def clone(self: _Env) -> _Env:
        """An independent copy of the episode so far (what-if planning): stepping it leaves this env
        unchanged. The mission's leg table (read-only profiles and charges) is shared."""
        twin = copy.copy(self)
        twin.backend = copy.copy(self.backend)
        for name in ("_visited", "_mask", "_obs"):
            setattr(twin, name, getattr(self, name).copy())
        for name in ("_route", "_alts", "_reached"):
            setattr(twin, name, list(getattr(self, name)))
        return twin

    def action_masks(self) -> np.ndarray:
        """Boolean valid-action mask, shape (36,) (the sb3-contrib ``MaskablePPO`` convention)."""
        return self._mask.copy()

    def episode_plan(self, policy: str = "dqn") -> Plan:
        """The episode so far as a :class:`Plan` (as this env's backend saw it; check it with
        :func:`uam_studio.planning.missions.check.check_plan` for the physics verdict)."""
        msgs = []
        if self._eod:
            msgs.append(f"end of discharge on leg {len(self._route)} to {self._route[-1]} "
                        f"({self.backend.name} battery)")
        if self._invalid:
            msgs.append("the policy chose an invalid action")
        assert self.mission is not None  # reset() set it, as it set _eod read above
        missed = [d.name for d, seen in zip(self.mission.destinations, self._visited) if not seen]
        if missed and not self._episode.rules.one_leg:
            msgs.append(f"not visited: {', '.join(missed)}")
        stats = {"return": self._return, "steps": self._steps, "backend": self.backend.name,
                 "scenario": self.scenario, "health": [float(h) for h in self._health]}
        return Plan(policy, tuple(self._route), tuple(self._alts), tuple(self._reached),
                    self._reached_priority, self._cycles, tuple(msgs), stats)
