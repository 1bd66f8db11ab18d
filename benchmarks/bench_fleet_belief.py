"""Does each aircraft's belief band hold its pack's truth over a life? (the fleet's health intervals)

A fleet flies day after day under the health-aware dispatcher; after every day, for each pack in service:

- is its true q_max (C) inside the belief's two-sided band of +-1.64 std (nominal 90%), and above the
  dispatcher's cautious side (belief - 1.64 std, nominal 95% one-sided)? In the varied world (the default) the
  pack's other parameters are its own, and the belief holds the q_max its model sees in it, not this one.
- on a probe round trip (a request half the regime's reach away, calm air), does the belief's 90% interval of the
  lowest voltage (``HealthBelief.lowest_voltage``: the health's sigma points and the model-error term learned from
  the pack's logbook, on the fleet's declared configuration) hold the voltage the pack really gives?

Prints the coverage per regime (with a one-sided binomial test of each side's 5% miss rate) and the worst miss.

    python benchmarks/bench_fleet_belief.py [--days 30] [--seeds 20 21] [--world model]
"""

from __future__ import annotations

import argparse

from scipy.stats import binomtest

from uam_studio.battery.health import HealthBelief
from uam_studio.battery.health.config import fleet_belief_config
from uam_studio.fleet.day import Fleet, day_of_life_seed, simulate_day
from uam_studio.fleet.demand import Request, poisson_demand
from uam_studio.fleet.dispatch import EOD_V, round_trip
from uam_studio.fleet.packs import NOISE_V
from uam_studio.planning.operations.world import DEFAULT_WORLD, WORLDS
from uam_studio.risk import HEALTH_Z

# the NASA packs' regimes of bench_fleet_bound.py (about 90 cycles to 80%: spreads of 54 and 80 cycles)
REGIMES = {"default (45 km, 54 cycles)": (45.0, 54.0), "far (70 km, 80 cycles)": (70.0, 80.0)}


def _p(k: int, n: int) -> float:
    return binomtest(k, n, 0.05, alternative="greater").pvalue if n else 1.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=30)
    ap.add_argument("--seeds", type=int, nargs="+", default=[20, 21], help="never used in tuning")
    ap.add_argument("--world", choices=WORLDS, default=DEFAULT_WORLD)
    args = ap.parse_args()
    for name, (far, spread) in REGIMES.items():
        inside = above = n = 0
        worst = 0.0
        low = high = 0
        probe = Request(0.0, "probe", far / 2, 0.0, 1)
        for seed in args.seeds:
            fleet = Fleet.new(6, seed, spread, world=args.world)
            config = fleet_belief_config(fleet.law)
            for d in range(args.days):
                s = day_of_life_seed(seed, d)
                simulate_day(fleet, poisson_demand(s, max_km=far), "aware", s)
                for t, b, ok, book in zip(fleet.truth, fleet.beliefs, fleet.in_service, fleet.logbooks):
                    if not ok:
                        continue
                    z = (t.q_max - b.health.q_max_c) / b.health.q_max_sd_c
                    n += 1
                    inside += abs(z) <= HEALTH_Z
                    above += z >= -HEALTH_Z
                    worst = max(worst, abs(z))
                    true = round_trip(probe, t.q_max, t.r0, 0.0, 0.0, t.params)
                    cur = true.current_a if true.eod_s is None else round_trip(probe, 9000.0, 0.02, 0.0, 0.0).current_a
                    lo, _, hi = HealthBelief(NOISE_V, EOD_V, logbook=book, config=config).lowest_voltage([cur], 0)
                    v = float(true.min_voltage_v)
                    low += v < lo
                    high += v > hi
        print(f"{name}, world {args.world}: {n} pack-days ({len(args.seeds)} seeds x {args.days} days): true q_max "
              f"inside the 90% band {inside / n:.1%}, above the cautious side {above / n:.1%}; worst miss {worst:.1f} "
              f"std; the probe round trip's lowest voltage inside the belief's 90% interval {(n - low - high) / n:.1%}"
              f" (below {low}, p {_p(low, n):.2f}; above {high}, p {_p(high, n):.2f}; goal 85-95%, each side "
              "p >= 0.05)")


if __name__ == "__main__":
    main()
