"""``uam-studio simulate``: fly a route of a mission file and print its voltage and end of discharge per leg."""

from __future__ import annotations

import argparse
import json
import sys

from uam_studio.cli.common import EXIT_OK, Command, parse_floats, parse_list
from uam_studio.wording import charging_cycles_text


def _add_simulate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("mission", metavar="MISSION.json", help="mission file (see assets/example_mission.json)")
    p.add_argument("--route", required=True, help="comma-separated node names, e.g. A,B,vertiport")
    p.add_argument("--altitudes", required=True, help="cruise altitude (m) of each leg, e.g. 500,1000,500")
    p.add_argument("--q-max", type=float, default=None, help="override the mission's q_max (C)")
    p.add_argument("--r0", type=float, default=None, help="override the mission's r0 (ohm)")
    p.add_argument("--eod-v", type=float, default=None, help="override the mission's EOD cut-off (V)")
    p.add_argument("--dt", type=float, default=1.0, help="sample step (s), default 1")
    p.add_argument("--json", action="store_true", help="print the simulation as JSON")


def _run_simulate(args: argparse.Namespace) -> int:
    from uam_studio.planning import load_mission, simulate_route

    route = parse_list("route", args.route)
    altitudes = parse_floats("altitudes", args.altitudes)
    mission = load_mission(args.mission)
    sim = simulate_route(mission, route, altitudes, q_max=args.q_max, r0=args.r0, eod_v=args.eod_v, dt_s=args.dt)
    if args.json:
        json.dump(sim.to_dict(), sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
        return EXIT_OK

    def fmt(x: float | None, spec: str) -> str:
        return "-" if x is None else format(x, spec)

    name_w = max([len("from"), len("to")] + [len(g.from_node) for g in sim.legs] + [len(g.to) for g in sim.legs])
    print(
        f"{mission.name}: q_max {sim.q_max:g} C, r0 {sim.r0:g} ohm, EOD {sim.eod_v:g} V, dt {sim.dt_s:g} s"
    )
    print(f"{'leg':>3}  {'from':<{name_w}}  {'to':<{name_w}}  {'km':>6}  {'alt m':>6}  "
          f"{'start s':>8}  {'end s':>8}  {'min V':>6}")
    for i, g in enumerate(sim.legs, 1):
        print(f"{i:>3}  {g.from_node:<{name_w}}  {g.to:<{name_w}}  {g.distance_km:>6.1f}  {g.altitude_m:>6g}  "
              f"{fmt(g.start_s, '.0f'):>8}  {fmt(g.end_s, '.0f'):>8}  {fmt(g.min_voltage_v, '.3f'):>6}")
    recharges = charging_cycles_text(sim.charging_cycles)
    if sim.safe and not sim.complete:
        print(f"EOD: not reached ({recharges}, min {sim.min_voltage_v:.3f} V); NOT A COMPLETE PLAN: the route "
              f"ends at {sim.legs[-1].to}, not back at the vertiport")
    elif sim.safe:
        print(f"EOD: not reached; safe ({recharges}, min {sim.min_voltage_v:.3f} V)")
    else:
        lost = sum(not g.reached for g in sim.legs)
        print(f"EOD: reached at {sim.eod_s:.0f} s; UNSAFE ({lost} of {len(sim.legs)} legs not completed)")
    return EXIT_OK


COMMAND = Command(
    "fly a route of a mission and report voltage and end of discharge",
    _add_simulate_arguments,
    _run_simulate,
)
