"""Speed and quality of flying with surprises (issue "Fly the mission").

    python benchmarks/bench_fly.py speed [--n 5]          # one fly of 8-destination missions, per re-plan
    python benchmarks/bench_fly.py quality [--n 20]       # operator vs blind vs hindsight, 2 scenarios
    python benchmarks/bench_fly.py sweep [--n 8]          # forecast sigma x sensor noise

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


def _report(label: str, s) -> None:
    print(f"{label}: {s.n} flights, operator/hindsight {s.ratio:.3f} (priority {s.priority} of {s.hindsight_priority}), "
          f"blind/hindsight {s.blind_ratio:.3f}, operator breaches {s.breaches}, blind breaches {s.blind_breaches}, "
          f"operator >= blind on {s.not_worse_than_blind}/{s.n}, extra recharges {s.extra_cycles}, re-plan p95 "
          f"{1000 * s.replan_s_p95:.0f} ms")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("what", choices=["speed", "quality", "sweep"])
    p.add_argument("--n", type=int, default=None)
    args = p.parse_args(argv)
    if args.what == "speed":
        speed(args.n or 5)
    elif args.what == "quality":
        quality(args.n or 20)
    else:
        t0 = time.perf_counter()
        print(format_rows(sweep(n=args.n or 8)))
        print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
