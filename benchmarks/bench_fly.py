"""Speed and quality of flying with surprises (issue "Fly the mission").

    python benchmarks/bench_fly.py speed [--n 5]          # one fly of 8-destination missions, per re-plan
    python benchmarks/bench_fly.py quality [--n 20]       # operator vs blind vs hindsight, 2 scenarios
    python benchmarks/bench_fly.py sweep [--n 8]          # forecast sigma x sensor noise
    python benchmarks/bench_fly.py events [--n 10]        # hindsight with a wind change, two definitions

``speed`` times :func:`uam_studio.planning.operations.fly_mission` end to end (the flight, the blind
plan and the hindsight oracle) and every decision, against the reference: one exact oracle plan of the
same mission with the true cell and forecast winds (what a planner with perfect knowledge pays once).
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from uam_studio.planning.solvers.oracle import oracle_plan
from uam_studio.studies.flying import fly_many, format_rows, study_missions, summarize, sweep


def speed(n: int) -> None:
    missions = study_missions(n, 60606, "single_charge", n_dest=(8, 8)) + \
        study_missions(n, 60607, "multi_charge", n_dest=(8, 8))
    fly_s, oracle_s, replans, first = [], [], [], []
    for k, m in enumerate(missions):
        t0 = time.perf_counter()
        rec = fly_many([m], first_seed=70_000 + k)[0]
        fly_s.append(time.perf_counter() - t0)
        replans += rec.replan_s[1:]
        first.append(rec.replan_s[0])
        t0 = time.perf_counter()
        oracle_plan(m)
        oracle_s.append(time.perf_counter() - t0)
    r = np.array(replans)
    print(f"{len(missions)} missions of 8 destinations ({n} single charge, {n} multi charge)")
    print(f"fly end to end (flight + blind plan + hindsight oracle): median {np.median(fly_s):.2f} s, "
          f"max {max(fly_s):.2f} s")
    print(f"first plan (after the take-off check): median {1000 * np.median(first):.0f} ms, "
          f"max {1000 * max(first):.0f} ms")
    print(f"re-plans at arrivals ({r.size}): median {1000 * np.median(r):.0f} ms, "
          f"p95 {1000 * np.percentile(r, 95):.0f} ms, max {1000 * r.max():.0f} ms (goal <= 250 ms)")
    print(f"reference, one exact oracle plan with perfect knowledge: median {1000 * np.median(oracle_s):.0f} ms")
    print(f"ratio re-plan median / oracle plan median: {np.median(r) / np.median(oracle_s):.2f}")


def quality(n: int) -> None:
    everything = []
    for scenario, seed in (("single_charge", 31337), ("multi_charge", 31338)):
        recs = fly_many(study_missions(n, seed, scenario), first_seed=7000)
        everything += recs
        _report(scenario, summarize(recs))
    _report("both scenarios", summarize(everything))


def events(n: int) -> None:
    """Flights with a scripted wind change (+25 kt at 600 s, -20 kt at 900 s) on fresh missions: the
    operator's priority against the hindsight reference as defined now (the winds of each leg's time;
    the best of the exact plan per wind period and the route flown, re-flown in the same world) and as
    it was (the exact oracle on the winds after the event, on every leg, never flown)."""
    from uam_studio.errors import InputError
    from uam_studio.planning.missions.mission import VERTIPORT
    from uam_studio.planning.operations import World, fly_mission, parse_event
    from uam_studio.planning.operations.world import actual_winds_mission

    rows = []
    ended_before: dict[str, int] = {}  # flights over before the change starts: not counted
    t0 = time.perf_counter()
    for text in ("wind+25@600", "wind-20@900"):
        for k, mission in enumerate(study_missions(n, 40400, "single_charge")):
            ev = [parse_event(text)]
            try:
                rec = fly_mission(mission, seed=5000 + k, events=ev)
            except InputError as err:  # the flight ended before the change (e.g. it never took off)
                if err.field != "event":
                    raise
                ended_before[text] = ended_before.get(text, 0) + 1
                continue
            world = World(mission, events=ev, seed=5000 + k)
            winds = {node: world.wind(node, float("inf")) for node in mission.node_names}
            old = oracle_plan(actual_winds_mission(mission, winds), mission.scenario)
            old_priority = sum(mission.node(x).priority for x in old.route if x != VERTIPORT)
            rows.append((text, rec.reached_priority, rec.breached, rec.hindsight.priority, old_priority))
    for text in ("wind+25@600", "wind-20@900"):
        sub = [r for r in rows if r[0] == text]
        flown = sum(r[1] for r in sub)
        below_old = sum(1 for r in sub if not r[2] and r[1] > r[4])
        below_new = sum(1 for r in sub if not r[2] and r[1] > r[3])
        print(f"{text}: {len(sub)} flights, operator priority {flown} (breaches {sum(r[2] for r in sub)}); "
              f"hindsight now {sum(r[3] for r in sub)} (ratio {flown / max(1, sum(r[3] for r in sub)):.3f}, "
              f"safe flights above it {below_new}); as before {sum(r[4] for r in sub)} (ratio "
              f"{flown / max(1, sum(r[4] for r in sub)):.3f}, safe flights above it {below_old}); "
              f"{ended_before.get(text, 0)} more ended before the change (not counted)")
    print(f"({time.perf_counter() - t0:.0f} s)")


def _report(label: str, s) -> None:
    print(f"{label}: {s.n} flights, operator/hindsight {s.ratio:.3f} "
          f"(priority {s.priority} of {s.hindsight_priority}), "
          f"blind/hindsight {s.blind_ratio:.3f}, operator breaches {s.breaches}, blind breaches {s.blind_breaches}, "
          f"operator >= blind on {s.not_worse_than_blind}/{s.n}, extra recharges {s.extra_cycles}, re-plan p95 "
          f"{1000 * s.replan_s_p95:.0f} ms")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("what", choices=["speed", "quality", "sweep", "events"])
    p.add_argument("--n", type=int, default=None)
    args = p.parse_args(argv)
    if args.what == "speed":
        speed(args.n or 5)
    elif args.what == "quality":
        quality(args.n or 20)
    elif args.what == "events":
        events(args.n or 10)
    else:
        t0 = time.perf_counter()
        print(format_rows(sweep(n=args.n or 8)))
        print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
