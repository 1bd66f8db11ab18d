"""``uam-studio fly``: fly a mission in a world the operator cannot see, re-planning from its sensors, and
print the flight log."""

from __future__ import annotations

import argparse
import json
import sys

from uam_studio.cli.common import EXIT_OK, Command, add_world_arguments, seed_arg
from uam_studio.wording import charging_cycles_text


def _add_fly_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("mission", metavar="MISSION.json", help="mission file: its battery is the true cell, its "
                                                           "winds the forecast")
    p.add_argument("--policy", choices=["attention", "oracle"], default="attention",
                   help="the operator's planner, on what it believes: attention (the learned planner; default) "
                        "or oracle (exact search, slower)")
    p.add_argument("--seed", type=seed_arg, default=0, help="seeds the forecast errors and the sensor noise")
    p.add_argument("--forecast-sigma", type=float, default=None, metavar="KT",
                   help="std of the forecast error of each node's wind (kt, 0-60; default 13)")
    p.add_argument("--sensor-noise-mv", type=float, default=None, metavar="MV",
                   help="voltage sensor noise std (mV, 0-100; default 5)")
    p.add_argument("--sensor-noise-ma", type=float, default=None, metavar="MA",
                   help="current sensor noise std (mA, 0-1000; default 20)")
    p.add_argument("--event", action="append", default=[], metavar="wind+KT@S",
                   help="scripted wind change, e.g. wind+30@1200: 30 kt more headwind on legs taking off "
                        "from t = 1200 s (repeatable)")
    p.add_argument("--reserve", type=float, default=None, metavar="KT",
                   help="weather reserve (kt, 0-60; default 25): every take-off keeps the next leg and the way home "
                        "safe under the operator's belief plus this much more headwind")
    p.add_argument("--q-max", type=float, default=None, help="override the true cell's q_max (C)")
    p.add_argument("--r0", type=float, default=None, help="override the true cell's r0 (ohm)")
    p.add_argument("--logbook", default=None, metavar="FILE",
                   help="the pack's logbook (uam-studio logbook new): its health belief starts from it (default: a "
                        "new pack, the fleet prior and the take-off's readings)")
    p.add_argument("--save-logbook", default=None, metavar="FILE",
                   help="write the pack's logbook with this flight appended (atomically; may be --logbook's file)")
    p.add_argument("--risk", type=float, default=None, metavar="P",
                   help="the flight's declared risk of reaching the cut-off (0.0001 to below 0.5; default 0.05): the "
                        "operator's health and wind margins and its weather reserve follow from it (over --reserve)")
    add_world_arguments(p, "the flight flies", pack="name the number its logbook was made with (logbook new --pack)")
    p.add_argument("--json", action="store_true", help="print the flight record as JSON")
    p.add_argument("--series", action="store_true", help="with --json: include the 1 Hz time series")


def _run_fly(args: argparse.Namespace) -> int:
    from uam_studio.battery.health import Logbook
    from uam_studio.planning import load_mission
    from uam_studio.planning.operations import fly_mission, parse_event

    events = [parse_event(e) for e in args.event]
    mission = load_mission(args.mission).with_battery(args.q_max, args.r0)
    book = Logbook.load(args.logbook) if args.logbook else None
    given = {"forecast_sigma_kt": args.forecast_sigma, "sensor_noise_mv": args.sensor_noise_mv,
             "sensor_noise_ma": args.sensor_noise_ma, "reserve_kt": args.reserve}
    # an option left out takes the library's default (uam_studio.planning.operations.defaults), not a copy
    rec = fly_mission(mission, args.policy, seed=args.seed, events=events, logbook=book, world=args.world,
                      pack=args.pack, risk=args.risk, **{k: v for k, v in given.items() if v is not None})
    if args.save_logbook:
        rec.logbook_after().save(args.save_logbook)
    if args.json:
        json.dump(rec.to_dict(series=args.series), sys.stdout, allow_nan=False)
        sys.stdout.write("\n")
        return EXIT_OK
    print(f"{mission.name} ({rec.scenario}): seed {rec.seed}, forecast sigma {rec.forecast_sigma_kt:g} kt, "
          f"sensor noise {rec.sensor_noise_mv:g} mV / {rec.sensor_noise_ma:g} mA, events: "
          f"{', '.join(rec.wind_events) or 'none'}, weather reserve {rec.reserve_kt:g} kt"
          + (f" (declared risk {rec.risk:g})" if rec.risk is not None else "") + f", world {rec.world} "
          f"(pack {rec.pack})")
    tb = rec.takeoff_belief
    if tb:
        print(f"take-off belief from the {tb['source']}" + (f" ({tb['flights']} flights)" if tb["flights"] else "")
              + f": q_max {tb['q_max_c']:.0f} +- {tb['q_max_sd_c']:.0f} C, R0 {tb['r0_ohm']:.4f} +- "
                f"{tb['r0_sd_ohm']:.4f} ohm")
        if "first_leg_min_voltage_90_v" in tb and rec.first_leg_min_voltage_v is not None:
            lo, hi = tb["first_leg_min_voltage_90_v"]
            print(f"first leg's lowest voltage: believed {lo:.3f}-{hi:.3f} V (90%; model error "
                  f"{1e3 * tb['model_error_v']:.1f} mV, {tb['model_error_share']:.0%} of its variance), the world gave "
                  f"{rec.first_leg_min_voltage_v:.3f} V")
    legs = iter(zip(rec.route, rec.altitudes_m, rec.actual_winds_kts, rec.forecast_winds_kts, rec.leg_end_s))
    for d in rec.events:
        print(f"t={d.time_s:>6.0f} s at {d.node}: {d.kind}: {d.reason}")
        print(f"           knows q_max {d.q_max_c:.0f} +- {d.q_max_sd_c:.0f} C, R0 {d.r0_ohm:.3f} +- "
              f"{d.r0_sd_ohm:.3f} ohm" + (f" (fit flagged: {', '.join(d.health_flags)})" if d.health_flags else "")
              + f", wind shift {d.wind_shift_kts:+.1f} kt "
                f"({d.wind_change or f'no change believed, p {d.wind_change_p:.2f}'})"
              + f"; plans {' -> '.join(d.route) or 'nothing more'}")
        if d.next_to is not None:
            to, alt, wind, forecast, end = next(legs)
            print(f"           flies to {to} at {alt:g} m: wind {wind:+.0f} kt (forecast {forecast:+.0f}), "
                  f"lands at {end:.0f} s")
    reached = ", ".join(rec.reached) or "none"
    verdict = (f"BREACHED the cut-off ({rec.breach_cause}): priority 0" if rec.breached
               else f"priority {rec.reached_priority}")
    print(f"flown: reached {reached}; {verdict}; {charging_cycles_text(rec.charging_cycles)}; "
          f"min {rec.min_voltage_v:.3f} V")
    print(f"blind pre-flight plan: {' -> '.join(rec.static.route) or 'nothing'}: "
          f"{'BREACHED, priority 0' if rec.static.breached else f'priority {rec.static.priority}'}")
    exact = "" if rec.hindsight.exact else (" at each leg's time; the best of the exact plans for each period of "
                                            "constant winds and the route flown")
    print(f"hindsight oracle (true cell, actual winds{exact}): priority {rec.hindsight.priority}")
    if args.save_logbook:
        print(f"logbook: {args.save_logbook} ({len(rec.logbook_before) + len(rec.flown_charges)} flights)")
    return EXIT_OK


COMMAND = Command(
    "fly a mission in a hidden world: the operator estimates health and wind from its sensors and "
    "re-plans at every arrival",
    _add_fly_arguments,
    _run_fly,
)
