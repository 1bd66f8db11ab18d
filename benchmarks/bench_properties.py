"""Every valid mission, every policy: crashes, NaN and unsafe plans over many drawn missions.

    OMP_NUM_THREADS=1 python benchmarks/bench_properties.py --n 2000 [--policies attention greedy dqn oracle]
                                                            [--seed 29000]

Missions come from :func:`uam_studio.planning.missions.generate.any_valid_mission` (anywhere in the
documented ranges: 1-20 destinations in a 70 km square, near-duplicates and points by the vertiport,
winds -39..39 kt, the paper's health box, all scenarios; 1-8 for the DQN). For each policy it counts:
plans, one-line planning errors (a cause in the mission), crashes (any other exception), JSON with NaN,
plans below the cut-off on the physics model, and, where the oracle is exact, missions where another
policy reached more priority than the oracle (the reference: the exact oracle on the same missions).
Goal (issue 29): 0 crashes and 0 NaN in 2,000 missions per policy. Seeds 29000+ are used by no
training or calibration.
"""

from __future__ import annotations

import argparse
import collections
import json
import time
import traceback

import numpy as np

from uam_studio.errors import InputError
from uam_studio.planning import plan_mission
from uam_studio.planning.legs import N_MAX
from uam_studio.planning.missions.check import check_plan
from uam_studio.planning.missions.generate import any_valid_mission


def run(policy: str, n: int, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    counts = collections.Counter()
    examples: dict[str, str] = {}
    t0 = time.perf_counter()
    for _ in range(n):
        mission = any_valid_mission(rng, max_dest=N_MAX if policy == "dqn" else 20)
        try:
            res = plan_mission(mission, policy=policy)
        except InputError as err:
            counts["planning error"] += 1
            if "\n" in str(err):
                counts["multi-line error"] += 1
            continue
        except Exception as err:  # a crash: the point of this benchmark
            counts["crash"] += 1
            examples.setdefault("crash", f"{type(err).__name__}: {err}\n{traceback.format_exc(limit=-3)}")
            continue
        counts["plan"] += 1
        try:
            json.dumps(res.to_dict(), allow_nan=False)
        except ValueError:
            counts["NaN in JSON"] += 1
        if res.route and not (res.safe and check_plan(mission, res.route, res.altitudes_m).safe):
            counts["unsafe"] += 1
    return {"policy": policy, "n": n, "counts": dict(counts), "examples": examples,
            "s_per_mission": (time.perf_counter() - t0) / n}


def dominance(n: int, seed: int) -> dict:
    """Missions of 1-8 destinations: does any policy reach more priority than the exact oracle?"""
    rng = np.random.default_rng(seed)
    beaten = collections.Counter()
    exact = 0
    for _ in range(n):
        mission = any_valid_mission(rng, max_dest=N_MAX)
        try:
            oracle = plan_mission(mission, policy="oracle")
        except InputError:
            continue
        if not oracle.exact:
            continue
        exact += 1
        for policy in ("attention", "greedy", "dqn"):
            try:
                other = plan_mission(mission, policy=policy)
            except InputError:
                continue
            if other.reached_priority > oracle.reached_priority:
                beaten[policy] += 1
    return {"exact missions": exact, "oracle beaten": dict(beaten)}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--policies", nargs="+", default=["attention", "greedy", "dqn", "oracle"])
    ap.add_argument("--dominance", type=int, default=300, help="missions of the oracle-dominance check")
    ap.add_argument("--seed", type=int, default=29000)
    args = ap.parse_args()
    print(f"{'policy':10s} {'missions':>8s} {'plans':>6s} {'errors':>7s} {'crashes':>8s} {'NaN':>4s} {'unsafe':>7s} "
          f"{'s/mission':>9s}")
    for k, policy in enumerate(args.policies):
        r = run(policy, args.n, args.seed + k)
        c = r["counts"]
        print(f"{policy:10s} {r['n']:8d} {c.get('plan', 0):6d} {c.get('planning error', 0):7d} {c.get('crash', 0):8d} "
              f"{c.get('NaN in JSON', 0):4d} {c.get('unsafe', 0):7d} {r['s_per_mission']:9.3f}", flush=True)
        for name, text in r["examples"].items():
            print(f"  first {name}: {text}")
    if args.dominance:
        print("exact-oracle dominance:", dominance(args.dominance, args.seed + 100))


if __name__ == "__main__":
    main()
