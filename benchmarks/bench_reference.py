"""The oracle's reference solver for large missions (OR-Tools routing, re-checked on physics) against
the exact oracle where that is within reach, and against the greedy baseline where it is not.

    python benchmarks/bench_reference.py [--n-small 12] [--n-large 8] [--seed 9191]

1. Held-out missions of 6-8 destinations (seeds ``seed`` and ``seed + 1``, never used elsewhere):
   the reference (:func:`uam_studio.planning.solvers.reference.reference_plan`) against the exact
   oracle (:func:`~uam_studio.planning.solvers.oracle.oracle_plan`): single charge, the priority gap
   (mean, worst); multi charge, the number of sorties (charging cycles) and destinations reached.
2. Held-out missions of 18-20 destinations (seeds ``seed + 2`` and ``seed + 3``): the reference against
   greedy: priority, sorties, time per plan.

Every plan is re-flown on the physics model (``check_plan``); an unsafe plan scores 0.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Iterator

import numpy as np

from uam_studio.planning.missions.check import check_plan
from uam_studio.planning.missions.generate import held_out_missions
from uam_studio.planning.solvers.greedy import greedy_plan
from uam_studio.planning.solvers.oracle import oracle_plan
from uam_studio.planning.solvers.reference import reference_plan


def _run(planner, m) -> tuple[int, int, int, float, bool]:
    """(priority, sorties, destinations reached, seconds, safe) of one plan, scored on physics."""
    t0 = time.perf_counter()
    p = planner(m)
    dt = time.perf_counter() - t0
    check = check_plan(m, p.route, p.altitudes_m)
    reached = check.sim.reached if check.sim is not None and check.safe else ()
    prio = {d.name: d.priority for d in m.destinations}
    cycles = check.sim.charging_cycles if check.sim is not None else 0
    return sum(prio[n] for n in reached), cycles, len(reached), dt, check.safe


def _scores(n: int, seed: int, n_dest: tuple[int, int], base) -> Iterator[tuple[str, np.ndarray, np.ndarray]]:
    """Per scenario (missions of seeds ``seed``, ``seed + 1``): the scenario, ``base``'s and the reference's
    :func:`_run` columns, each [5, n]."""
    for scenario, s in (("single_charge", seed), ("multi_charge", seed + 1)):
        rows = [(*_run(base, m), *_run(reference_plan, m))
                for m in held_out_missions(n, s, n_dest=n_dest, scenario=scenario)]
        a = np.array(rows, dtype=float)
        yield scenario, a[:, :5].T, a[:, 5:].T


def small(n: int, seed: int) -> None:
    print(f"== 6-8 destinations: reference vs exact oracle ({n} missions per scenario, seeds {seed}, {seed + 1})")
    for scenario, (o_prio, o_cyc, o_n, o_t, _), (r_prio, r_cyc, r_n, r_t, r_safe) in _scores(
            n, seed, (6, 8), oracle_plan):
        print(f"{scenario}: reference safe on {int(r_safe.sum())}/{n}; time per plan: exact median "
              f"{np.median(o_t):.2f} s (max {o_t.max():.2f} s), reference median {np.median(r_t):.2f} s "
              f"(max {r_t.max():.2f} s)")
        if scenario == "single_charge":
            gap = np.where(o_prio > 0, 1.0 - r_prio / np.maximum(o_prio, 1), 0.0)
            print(f"  priority: exact {o_prio.sum():.0f}, reference {r_prio.sum():.0f}; gap per mission mean "
                  f"{100 * gap.mean():.2f}%, worst {100 * gap.max():.2f}%; "
                  f"equal on {int((r_prio == o_prio).sum())}/{n}")
        else:
            print(f"  sorties: exact {o_cyc.sum():.0f}, reference {r_cyc.sum():.0f}; the exact number on "
                  f"{int((r_cyc == o_cyc).sum())}/{n} (worst +{(r_cyc - o_cyc).max():.0f}); destinations reached "
                  f"equal on {int((r_n == o_n).sum())}/{n}")


def large(n: int, seed: int) -> None:
    print(f"== 18-20 destinations: reference vs greedy ({n} missions per scenario, seeds {seed}, {seed + 1})")
    for scenario, (g_prio, g_cyc, g_n, g_t, g_safe), (r_prio, r_cyc, r_n, r_t, r_safe) in _scores(
            n, seed, (18, 20), greedy_plan):
        print(f"{scenario}: safe greedy {int(g_safe.sum())}/{n}, reference {int(r_safe.sum())}/{n}; time per plan: "
              f"greedy median {np.median(g_t):.2f} s, reference median {np.median(r_t):.2f} s "
              f"(max {r_t.max():.2f} s)")
        if scenario == "single_charge":
            gain = np.where(g_prio > 0, r_prio / np.maximum(g_prio, 1) - 1.0, 0.0)
            print(f"  priority: greedy {g_prio.sum():.0f}, reference {r_prio.sum():.0f} "
                  f"({100 * (r_prio.sum() / max(g_prio.sum(), 1) - 1):+.1f}%); per mission mean "
                  f"{100 * gain.mean():+.1f}%, reference >= greedy on {int((r_prio >= g_prio).sum())}/{n}")
        else:
            print(f"  sorties: greedy {g_cyc.sum():.0f}, reference {r_cyc.sum():.0f}; reference fewer on "
                  f"{int((r_cyc < g_cyc).sum())}/{n}, more on {int((r_cyc > g_cyc).sum())}/{n}; destinations "
                  f"reached: greedy {g_n.sum():.0f}, reference {r_n.sum():.0f}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n-small", type=int, default=12, help="6-8 destination missions per scenario (default 12)")
    p.add_argument("--n-large", type=int, default=8, help="18-20 destination missions per scenario (default 8)")
    p.add_argument("--seed", type=int, default=9191, help="first of the four seeds (default 9191)")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    if args.n_small > 0:
        small(args.n_small, args.seed)
    if args.n_large > 0:
        large(args.n_large, args.seed + 2)
    print(f"total {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
