"""A pack's logbook: the belief at the next take-off from a logbook of 100 flights, against refitting every flight
(the naive loop the stored fits save), and the Fly tab's first flight for a new pack and for a pack with a logbook.

    OMP_NUM_THREADS=1 python benchmarks/bench_logbook.py [--flights 100]

Goal (issue 75): the belief from a 100-flight logbook (file read, belief built) in <= 1 s. The logbook's flights are
constant-current discharges of 1500 s from full (2 A, 5 mV / 20 mA sensors) of a cell that ages by the NASA law; the
reference refits each flight with ``fit_health`` as a logbook without stored fits would have to.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from _timing import best_of

from uam_studio.battery import simulate
from uam_studio.battery.aging import NASA_AGING_LAW
from uam_studio.battery.health import HealthBelief, Logbook
from uam_studio.battery.health.logbook import fit_flight
from uam_studio.classroom import asset_path
from uam_studio.planning import load_mission
from uam_studio.planning.operations import fly_mission
from uam_studio.planning.operations.pack_history import simulate_logbook


def _book(n: int) -> Logbook:
    book = Logbook(noise_v=0.005)
    rng = np.random.default_rng(75)
    for k in range(n):
        frac = float(NASA_AGING_LAW.capacity_fraction(0.2 * k))
        cur = np.full(1500, 2.0)
        volt = simulate(cur, 1.0, 7600.0 * frac, 0.117 * float(NASA_AGING_LAW.resistance_ratio(0.2 * k))).voltage_v
        m = volt.size
        book = book.appended(cur[:m] + rng.normal(0, 0.02, m), volt + rng.normal(0, 0.005, m))
    return book


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=100)
    args = ap.parse_args()
    t0 = time.perf_counter()
    book = _book(args.flights)
    build_s = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "pack.json"
        book.save(path)
        size_mb = path.stat().st_size / 1e6

        def belief() -> None:
            HealthBelief(0.005, 3.0, logbook=Logbook.load(path)).prior_health()

        ours = best_of(belief, 5)

        def refit() -> None:
            loaded = Logbook.load(path)
            for f in loaded.flights:
                fit_flight(f.current_a.astype(float), f.voltage_v.astype(float), f.dt_s, loaded.noise_v, loaded.eod_v)

        naive = best_of(refit, 1)
    met = "met" if ours <= 1.0 else "NOT met"
    print(f"{args.flights} flights ({size_mb:.1f} MB file; logging them with their fits took {build_s:.1f} s): "
          f"belief at the next take-off {ours * 1000:.0f} ms (goal <= 1 s: {met}); refitting every flight "
          f"{naive:.1f} s ({naive / ours:.0f}x)")
    # the Fly tab's first flight: a new pack, and a pack whose 3-flight logbook is simulated at its first flight
    mission = load_mission(asset_path("example_mission.json"))
    fly_mission(mission, seed=0)  # warm: the planner's weights
    new, logged, history = [], [], []
    for seed in range(3):
        t0 = time.perf_counter()
        fly_mission(mission, seed=seed)
        new.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        pack = simulate_logbook(mission, 3, seed)
        history.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        fly_mission(mission, seed=seed, logbook=pack)
        logged.append(time.perf_counter() - t0)
    a, b = statistics.median(new), statistics.median(logged)
    print(f"the Fly tab's flight of the example mission (median of 3): new pack {a:.2f} s; "
          f"with a 3-flight logbook {b:.2f} s ({b / a:.2f}x), "
          f"plus {statistics.median(history):.2f} s to simulate its history the first time a pack is chosen")


if __name__ == "__main__":
    main()
