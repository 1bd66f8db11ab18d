"""The price of safety: flights at each declared risk, their breach rate against the risk, and what they serve.

    OMP_NUM_THREADS=1 python benchmarks/bench_risk.py [--n 60] [--risks 0.01 0.05 0.1 0.2] [--world model]

For each declared risk (``fly_mission(risk=)``, :func:`uam_studio.risk.caution`), the same ``--n`` flights: fresh
missions of 4-8 destinations, half single-charge (``study_missions(n, 58000)``) and half multi-charge (58001), world
seeds and packs 58100+, each with a change of every later leg's wind drawn from the declared envelope
(N(0, ``WEATHER_CHANGE_SD_KT``), clipped to +-60 kt) at a time drawn uniformly in 60-900 s (seed 58200; a change
drawn after a flight ended is dropped and the flight flown without it). None of these seeds tuned anything.

Prints per risk: the breach rate with its 95% Clopper-Pearson interval and a one-sided binomial test of "at most the
declared risk" (p >= 0.05: consistent), and the priority served against the hindsight reference (a breach scores 0),
beside the pre-flight plan flown blind. Runs on two processes.
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from scipy.stats import binomtest

from uam_studio.errors import InputError
from uam_studio.planning.operations import fly_mission, parse_event
from uam_studio.planning.operations.world import DEFAULT_WORLD, WORLDS
from uam_studio.risk import WEATHER_CHANGE_SD_KT
from uam_studio.studies.flying import study_missions


def _fly(job: tuple) -> tuple[float, str, int, int, int, bool, bool]:
    risk, mission, seed, event, world = job
    try:
        rec = fly_mission(mission, seed=seed, pack=seed, events=[parse_event(event)], risk=risk, world=world)
    except InputError as err:  # the change came after the flight: flown without it
        if err.field != "event":
            raise
        rec = fly_mission(mission, seed=seed, pack=seed, risk=risk, world=world)
    return (risk, rec.scenario, rec.reached_priority, rec.hindsight.priority, rec.static.priority, rec.breached,
            rec.static.breached)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=60, help="flights per risk level (half single-, half multi-charge)")
    ap.add_argument("--risks", type=float, nargs="+", default=[0.01, 0.05, 0.1, 0.2])
    ap.add_argument("--world", choices=WORLDS, default=DEFAULT_WORLD)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    half = args.n // 2
    missions = study_missions(half, 58000, "single_charge") + study_missions(args.n - half, 58001, "multi_charge")
    rng = np.random.default_rng(58200)
    changes = np.clip(rng.normal(0.0, WEATHER_CHANGE_SD_KT, len(missions)), -60.0, 60.0)
    times = rng.uniform(60.0, 900.0, len(missions))
    events = [f"wind{c:+.0f}@{t:.0f}" for c, t in zip(changes, times)]
    jobs = [(r, m, 58100 + k, events[k], args.world) for r in args.risks for k, m in enumerate(missions)]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(pool.map(_fly, jobs))
    print(f"world {args.world}; {len(missions)} flights per level ({half} single-charge, {args.n - half} multi-charge),"
          f" a change of N(0, {WEATHER_CHANGE_SD_KT:.1f} kt) in each")
    print("| declared risk | flights | breaches | breach rate (95% CI) | p (at most the risk) | priority / hindsight "
          "| single-charge | blind plan / hindsight (its breaches) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in args.risks:
        sub = [x for x in rows if x[0] == r]
        n, k = len(sub), sum(x[5] for x in sub)
        test = binomtest(k, n, r, alternative="greater")
        ci = binomtest(k, n).proportion_ci(0.95)  # two-sided
        hind = sum(x[3] for x in sub)
        single = [x for x in sub if x[1] == "single_charge"]
        one = sum(x[2] for x in single) / max(sum(x[3] for x in single), 1)
        print(f"| {r:g} | {n} | {k} | {k / n:.3f} ({ci.low:.3f}-{ci.high:.3f}) | {test.pvalue:.2f} | "
              f"{sum(x[2] for x in sub) / hind:.3f} | {one:.3f} | {sum(x[4] for x in sub) / hind:.3f} "
              f"({sum(x[6] for x in sub)}) |")
    print(f"({time.perf_counter() - t0:.0f} s, {args.workers} processes)")


if __name__ == "__main__":
    main()
