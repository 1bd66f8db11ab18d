"""Does each aircraft's belief band hold its pack's truth over a life? (the fleet's health intervals)

A fleet flies day after day under the health-aware dispatcher; after every day, for each pack in service,
is its true q_max (C) inside the belief's two-sided band of +-1.64 std (nominal 90%), and is it above the
dispatcher's cautious side (belief - 1.64 std, nominal 95% one-sided)? Prints the coverage per regime,
and the worst miss in std.

    python benchmarks/bench_fleet_belief.py [--days 30] [--seeds 20 21]
"""

from __future__ import annotations

import argparse

from uam_studio.fleet.day import Fleet, day_of_life_seed, simulate_day
from uam_studio.fleet.demand import poisson_demand
from uam_studio.risk import HEALTH_Z

# the NASA packs' regimes of bench_fleet_bound.py (about 90 cycles to 80%: spreads of 54 and 80 cycles)
REGIMES = {"default (45 km, 54 cycles)": (45.0, 54.0), "far (70 km, 80 cycles)": (70.0, 80.0)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=30)
    ap.add_argument("--seeds", type=int, nargs="+", default=[20, 21], help="never used in tuning")
    args = ap.parse_args()
    for name, (far, spread) in REGIMES.items():
        inside = above = n = 0
        worst = 0.0
        for seed in args.seeds:
            fleet = Fleet.new(6, seed, spread)
            for d in range(args.days):
                s = day_of_life_seed(seed, d)
                simulate_day(fleet, poisson_demand(s, max_km=far), "aware", s)
                for t, b, ok in zip(fleet.truth, fleet.beliefs, fleet.in_service):
                    if not ok:
                        continue
                    z = (t.q_max - b.health.q_max_c) / b.health.q_max_sd_c
                    n += 1
                    inside += abs(z) <= HEALTH_Z
                    above += z >= -HEALTH_Z
                    worst = max(worst, abs(z))
        print(f"{name}: {n} pack-days ({len(args.seeds)} seeds x {args.days} days): true q_max inside the "
              f"90% band {inside / n:.1%}, above the cautious side {above / n:.1%}; worst miss {worst:.1f} std")


if __name__ == "__main__":
    main()
