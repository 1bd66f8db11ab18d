"""The fleet's price of safety: the health-aware dispatcher at each declared risk (``uam-studio fleet --risk``).

Each day starts from one fleet state (a fresh fleet of 6, packs aged as the regime says, the varied world) and one
demand, as in ``bench_fleet_bound.py``; the health-aware dispatcher flies it from a copy at each declared risk, and
``uam_studio.fleet.day.hindsight_bound`` bounds it once from the same state. Prints per regime and risk: the round
trips flown, the breaches (the cell reaching its cut-off on a flight) with their 95% interval and the one-sided
binomial p of "at most the declared risk", and the stars per day with their share of the bound.

The dispatcher's risk is per round trip: the health at ``risk_z(risk)`` std to its weak side and each leg's wind at
the quantile of a fifth of the risk (:func:`uam_studio.risk.caution`).

    python benchmarks/bench_fleet_risk.py [--days 30] [--seed 900] [--risks 0.01 0.05 0.1 0.2]
"""

from __future__ import annotations

import argparse
import copy
import time

from scipy.stats import binomtest

from uam_studio.fleet.day import Fleet, hindsight_bound, simulate_day
from uam_studio.fleet.demand import poisson_demand
from uam_studio.risk import RISK_LEVELS

# name: (farthest request km, pack age spread cycles, chargers): bench_fleet_bound.py's first two regimes
REGIMES = {"default (45 km, 54 cycles, 2 chargers)": (45.0, 54.0, 2),
           "far (70 km, 80 cycles, 2 chargers)": (70.0, 80.0, 2)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=30)
    ap.add_argument("--seed", type=int, default=900, help="first seed (fleet and demand), never used in tuning")
    ap.add_argument("--risks", type=float, nargs="+", default=list(RISK_LEVELS))
    args = ap.parse_args()
    t0 = time.perf_counter()
    for name, (far, spread, chargers) in REGIMES.items():
        flights = {r: 0 for r in args.risks}
        breaches = {r: 0 for r in args.risks}
        stars = {r: 0 for r in args.risks}
        bound = 0
        for k in range(args.days):
            seed = args.seed + k
            fleet, demand = Fleet.new(6, seed, spread), poisson_demand(seed, max_km=far)
            bound += hindsight_bound(copy.deepcopy(fleet), demand, seed, chargers)
            for r in args.risks:
                day = simulate_day(copy.deepcopy(fleet), demand, "aware", seed, chargers, risk=r)
                flights[r] += day.flights
                breaches[r] += day.breaches
                stars[r] += day.priority
        print(f"{name}: {args.days} days from seed {args.seed}; bound {bound / args.days:.1f} stars/day")
        print("  risk | round trips | breaches | rate (95% CI) | p (at most the risk) | stars/day | of the bound")
        for r in args.risks:
            n, b = flights[r], breaches[r]
            test = binomtest(b, n, r, alternative="greater") if n else None
            ci = binomtest(b, n, r).proportion_ci(0.95) if n else None  # two-sided (Clopper-Pearson)
            rate = f"{b / n:.2%} ({ci.low:.2%}-{ci.high:.2%})" if test and ci else "-"
            print(f"  {r:g} | {n} | {b} | {rate} | {test.pvalue if test else 1.0:.2f} | {stars[r] / args.days:.1f} | "
                  f"{stars[r] / max(bound, 1):.1%}")
    print(f"run time {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
