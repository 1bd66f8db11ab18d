"""Plans and their physics check.

A :class:`Plan` is what every planner returns (the oracle, the greedy baseline, a
DQN rollout): a route of node names (``"vertiport"`` recharges) with one cruise
altitude per leg, what it reaches, and human-readable ``messages`` for everything
it could not do. :func:`check_plan` flies a route through the *physics* battery
model (:func:`uam_studio.planning.missions.route.simulate_route`) and says whether it stays
above the end-of-discharge cut-off, and if not, where it fails. Every plan, from
any policy, should go through it before anyone trusts it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from uam_studio.planning.missions.mission import Mission
from uam_studio.planning.missions.route import RouteSimulation, simulate_route


@dataclass(frozen=True)
class Plan:
    """A planner's answer.

    :param policy: who made it (``"oracle"``, ``"greedy"``, ``"dqn"``...).
    :param route: node names after the implicit start at the vertiport; ``"vertiport"``
        is a landing that recharges. Empty if nothing can be flown.
    :param altitudes_m: cruise altitude (m) of each leg, same length as ``route``.
    :param reached: destinations reached, in visiting order.
    :param reached_priority: sum of their priorities (1-3 each).
    :param charging_cycles: landings at the vertiport (as :func:`simulate_route` counts them).
    :param messages: one line each: what could not be done and why, or notes.
    :param stats: planner-specific numbers (timings, label counts, voltages...).
    :param check: the physics check of the route (:func:`make_plan` keeps it, so that a caller need
        not fly the route again), or None.
    """

    policy: str
    route: tuple[str, ...] = ()
    altitudes_m: tuple[float, ...] = ()
    reached: tuple[str, ...] = ()
    reached_priority: int = 0
    charging_cycles: int = 0
    messages: tuple[str, ...] = ()
    stats: dict[str, Any] = field(default_factory=dict)
    check: PlanCheck | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "route", tuple(self.route))
        object.__setattr__(self, "altitudes_m", tuple(float(a) for a in self.altitudes_m))
        object.__setattr__(self, "reached", tuple(self.reached))
        object.__setattr__(self, "messages", tuple(self.messages))

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON dict."""
        return {
            "policy": self.policy,
            "route": list(self.route),
            "altitudes_m": list(self.altitudes_m),
            "reached": list(self.reached),
            "reached_priority": int(self.reached_priority),
            "charging_cycles": int(self.charging_cycles),
            "messages": list(self.messages),
            "stats": dict(self.stats),
        }


@dataclass(frozen=True, eq=False)
class PlanCheck:
    """Result of :func:`check_plan`.

    :param safe: True if the whole route stays at or above the cut-off (an empty route is safe).
    :param min_voltage_v: lowest voltage (V) over the route (the failing sample included), None if empty.
    :param margin_v: ``min_voltage_v - eod_v`` (V; negative when unsafe), None if empty.
    :param fail_leg: 0-based index of the leg where the voltage first falls below the cut-off, else None.
    :param fail_to: the node that leg was flying to, else None.
    :param fail_time_s: time (s from the first take-off) of the first sample below the cut-off, else None.
    :param message: one line, e.g. ``"unsafe: voltage falls below 3.00 V at 2412 s on leg 3 to Napa"``
        (legs counted from 1 in messages).
    :param sim: the physics :class:`RouteSimulation` (None for an empty route).
    """

    safe: bool
    min_voltage_v: float | None
    margin_v: float | None
    fail_leg: int | None
    fail_to: str | None
    fail_time_s: float | None
    message: str
    sim: RouteSimulation | None


def check_plan(
    mission: Mission,
    route: Sequence[str],
    altitudes_m: Sequence[float],
    q_max: float | None = None,
    r0: float | None = None,
    eod_v: float | None = None,
) -> PlanCheck:
    """Fly ``route`` at ``altitudes_m`` with the physics model and report whether it is safe.

    ``q_max`` (C), ``r0`` (ohm) and ``eod_v`` (V) default to the mission's.

    :raises InputError: for a malformed route (unknown node, altitude count mismatch, a leg
        too short for its altitude...), as :func:`simulate_route` does.
    """
    route = list(route)
    altitudes_m = list(altitudes_m)
    if not route and not altitudes_m:
        return PlanCheck(True, None, None, None, None, None, "empty plan: nothing is flown", None)
    sim = simulate_route(mission, route, altitudes_m, q_max=q_max, r0=r0, eod_v=eod_v)
    v_min = sim.min_voltage_v
    margin = v_min - sim.eod_v
    if sim.safe:
        n = len(sim.legs)
        msg = (f"safe: minimum {v_min:.2f} V, {margin:.2f} V above the {sim.eod_v:.2f} V cut-off "
               f"({n} leg{'s' * (n != 1)}, {sim.charging_cycles} landing{'s' * (sim.charging_cycles != 1)} "
               "at the vertiport)")
        return PlanCheck(True, v_min, margin, None, None, None, msg, sim)
    k = next(i for i, leg in enumerate(sim.legs) if not leg.reached)
    to = sim.legs[k].to
    assert sim.eod_s is not None  # a leg not reached: the cut-off was crossed
    msg = f"unsafe: voltage falls below {sim.eod_v:.2f} V at {sim.eod_s:.0f} s on leg {k + 1} to {to}"
    return PlanCheck(False, v_min, margin, k, to, float(sim.eod_s), msg, sim)


def make_plan(
    mission: Mission,
    policy: str,
    route: Sequence[str],
    altitudes_m: Sequence[float],
    messages: Sequence[str] = (),
    stats: dict[str, Any] | None = None,
) -> Plan:
    """A :class:`Plan` whose ``reached``, priority and cycles come from the physics check of the route.

    The check's outcome is added to ``stats`` (``safe``, ``min_voltage_v``, ``margin_v``,
    ``flight_time_s``) and, if unsafe, its message to ``messages``.
    """
    check = check_plan(mission, route, altitudes_m)
    stats = dict(stats or {})
    msgs = list(messages)
    reached: tuple[str, ...] = ()
    cycles = 0
    if check.sim is not None:
        reached, cycles = check.sim.reached, check.sim.charging_cycles
        stats.setdefault("flight_time_s", float(check.sim.time_s[-1]))
    stats.update(safe=check.safe, min_voltage_v=check.min_voltage_v, margin_v=check.margin_v)
    if not check.safe:
        msgs.append(check.message)
    prio = {d.name: d.priority for d in mission.destinations}
    return Plan(policy, tuple(route), tuple(altitudes_m), reached, sum(prio[n] for n in reached),
                cycles, tuple(msgs), stats, check)
