"""``uam-studio plan``: plan a mission with the attention planner, the DQN agent, the oracle or the greedy
baseline, checked with the physics model."""

from __future__ import annotations

import argparse
import json
import sys

from uam_studio.cli.common import EXIT_INPUT, EXIT_OK, CliExit, Command
from uam_studio.errors import InputError


def _add_plan_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("mission", metavar="MISSION.json", help="mission file (see assets/example_mission.json)")
    p.add_argument("--policy", choices=["attention", "dqn", "oracle", "greedy"], default="attention",
                   help="attention (the bundled learned planner, default; 1-20 destinations), dqn (the paper's "
                        "agent; at most 8 destinations), oracle (knows the cell; exact up to 8 destinations, "
                        "an OR-Tools reference, not proven optimal, for 9-20) or greedy (baseline)")
    p.add_argument("--agent", default=None, metavar="FILE",
                   help="attention: a weights file (default: the bundled pretrained/attention_planner.pt); "
                        "dqn: an agent zip (default: the bundled pretrained/dqn_<scenario>.zip)")
    p.add_argument("--lookahead", type=int, default=0, metavar="K",
                   help="dqn: improve the agent by policy rollout over its K best safe actions and the "
                        "greedy rule's action per step, each continued by the agent and by the greedy rule "
                        "(0 = off, default; 6 is what benchmarks/RESULTS.md, \"Planning\", measures; costs up to "
                        "2(K + 1) extra episodes per step)")
    p.add_argument("--q-max", type=float, default=None, help="override the mission's q_max (C)")
    p.add_argument("--r0", type=float, default=None, help="override the mission's r0 (ohm)")
    p.add_argument("--json", action="store_true", help="print the plan as JSON")


_PLAN_FLAGS = {"agent_path": "--agent", "lookahead": "--lookahead", "policy": "--policy"}
"""``plan_mission``'s field names -> the ``plan`` command's flags, for its one-line errors."""


def _run_plan(args: argparse.Namespace) -> int:
    from uam_studio.planning import load_mission
    from uam_studio.planning.planner import plan_mission
    from uam_studio.planning.safety import takeoff_attempt

    mission = load_mission(args.mission)  # a Mission holds 1-20 destinations: checked in the mission
    try:
        res = plan_mission(mission, args.policy, q_max=args.q_max, r0=args.r0, agent_path=args.agent,
                           lookahead=args.lookahead)
    except InputError as err:  # plan_mission's checks, in the words of the flags
        flag = _PLAN_FLAGS.get(err.field)
        if flag is None:
            raise
        raise CliExit(f"{flag}{str(err)[len(err.field):]}", EXIT_INPUT) from None
    if args.json:
        json.dump(res.to_dict(), sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
        return EXIT_OK
    battery = mission.with_battery(args.q_max, args.r0).battery
    print(f"{mission.name} ({mission.scenario}), policy {res.policy}: q_max {battery.q_max:g} C, "
          f"r0 {battery.r0:g} ohm, EOD {mission.eod_v:g} V")
    if res.route:
        legs = " -> ".join(f"{n} ({a:g} m)" for n, a in zip(res.route, res.altitudes_m))
        print(f"route: vertiport -> {legs}")
    else:
        print("route: none (nothing is flown)")
    reached = ", ".join(res.reached) or "none"
    print(f"reached: {reached} (priority {res.reached_priority})")
    print(f"charging cycles: {res.charging_cycles}")
    if not res.route:
        attempt = takeoff_attempt(mission.with_battery(args.q_max, args.r0))
        if attempt is not None:
            print(f"safe: NO, the cell cannot take off: below EOD {attempt['eod_s']:.0f} s into the take-off "
                  "and climb (nothing is flown)")
        else:
            print("safe: nothing is flown (no destination can be reached and flown home above the cut-off)")
    elif res.safe:
        print(f"safe: yes, min {res.min_voltage_v:.3f} V")
    else:
        print(f"safe: NO, end of discharge at {res.physics['eod_s']:.0f} s (min {res.min_voltage_v:.3f} V)")
    if res.predicted is not None and res.predicted["voltage_v"]:
        print(f"Dynaformer: predicted min {min(res.predicted['voltage_v']):.3f} V")
    for m in res.messages:
        print(f"note: {m}")
    return EXIT_OK


COMMAND = Command(
    "plan a mission with a policy (attention, dqn, oracle, greedy), checked with the physics model",
    _add_plan_arguments,
    _run_plan,
)
