"""The price of safety: flights at each declared risk, their breach rate against the risk, and what they serve.

    OMP_NUM_THREADS=1 python benchmarks/bench_risk.py [--n 60] [--risks 0.01 0.05 0.1 0.2] [--logbook-flights 3]
        [--world model] [--informed]

For each declared risk (``fly_mission(risk=)``, :func:`uam_studio.risk.caution`), the same ``--n`` flights of
:func:`uam_studio.planning.operations.safety_price.price_of_safety`: fresh missions of 5-8 destinations, half
single-charge (held-out seed 58000) and half multi-charge (58001), world seeds and packs 58100+, each with a change
of every later leg's wind drawn from the declared envelope (N(0, ``WEATHER_CHANGE_SD_KT``), clipped to +-60 kt) at a
time drawn uniformly in 60-900 s (seed 58200; a change drawn after a flight ended is dropped and the flight flown
without it); with ``--logbook-flights`` k, each pack's logbook holds k earlier flights of its mission (seeds
58300+). None of these seeds tuned anything.

Prints per risk: the breach rate with its 95% Clopper-Pearson interval and a one-sided binomial test of "at most the
declared risk" (p >= 0.05: consistent), and the priority served against the hindsight reference (a breach scores 0),
pooled and on single-charge missions, against the pre-flight plan flown blind (its breaches score 0). Runs on two
processes.

``--informed`` flies the same flights with a reference no operator can be: the operator told its true cell at every
decision (``bench_weather.InformedOperator``, checked from the take-off on; in the model world that cell is exactly
the world's), the winds still only believed: what the cautions cost when the health is known.
"""

from __future__ import annotations

import argparse
import functools
import time
from concurrent.futures import ProcessPoolExecutor

from uam_studio.planning.operations.safety_price import (
    RiskFlight,
    fly_study_flight,
    format_levels,
    group_tests,
    price_of_safety,
    risk_flights,
    risk_levels,
)
from uam_studio.planning.operations.world import DEFAULT_WORLD, WORLDS
from uam_studio.risk import RISK_LEVELS, WEATHER_CHANGE_SD_KT


def _informed(job: tuple) -> RiskFlight:
    from bench_weather import InformedOperator  # this folder's: a reference, not library code

    risk, mission, seed, event, world = job
    op = functools.partial(InformedOperator, q_max=mission.battery.q_max, r0=mission.battery.r0, check_at_takeoff=True)
    return fly_study_flight(risk, mission, seed, event, world, operator=op)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=60, help="flights per risk level (half single-, half multi-charge)")
    ap.add_argument("--risks", type=float, nargs="+", default=list(RISK_LEVELS))
    ap.add_argument("--logbook-flights", type=int, default=0, help="earlier flights in each pack's logbook")
    ap.add_argument("--world", choices=WORLDS, default=DEFAULT_WORLD)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--informed", action="store_true", help="the reference told its true cell (module docstring)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    if args.informed:
        jobs = [(r, m, seed, event, args.world) for r in args.risks for m, seed, event in risk_flights(args.n)]
        with ProcessPoolExecutor(args.workers) as pool:
            flights = list(pool.map(_informed, jobs))
        print("the reference told its true cell at every decision (not an operator)")
    else:
        flights = price_of_safety(args.risks, args.n, args.logbook_flights, args.world, args.workers)
    half = args.n // 2
    print(f"world {args.world}; {args.n} flights per level ({half} single-charge, {args.n - half} multi-charge), a "
          f"change of N(0, {WEATHER_CHANGE_SD_KT:.1f} kt) in each; logbook: {args.logbook_flights} earlier flights")
    print(format_levels(risk_levels(flights)))
    print(group_tests(flights))
    print(f"({time.perf_counter() - t0:.0f} s, {args.workers} processes)")


if __name__ == "__main__":
    main()
