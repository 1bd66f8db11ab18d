"""A class run of the attention planner's retraining (the Retrain tab's defaults), timed and scored.

Trains with :func:`~uam_studio.planning.agents.attention.retrain.retrain_attention` at the tab's
defaults (150 random missions of 2-6 destinations solved by the exact oracle, 20 epochs, one core)
from random weights, scoring each epoch on the example mission; then scores the trained network on
held-out missions (seeds ``[31000, k]``, never used in training; 3-8 destinations, single charge)
against, in the same run, the exact oracle and the bundled planner. Plans are scored on the
physics model; an unsafe plan scores 0.

    OMP_NUM_THREADS=1 python benchmarks/bench_retrain_attention.py [--missions 150 --epochs 20 --held-out 20]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from uam_studio.planning.agents.attention.decode import load_policy, load_policy_cached
from uam_studio.planning.agents.attention.retrain import attention_setup, map_score, retrain_attention
from uam_studio.planning.missions.generate import random_mission
from uam_studio.planning.missions.mission import load_mission
from uam_studio.planning.solvers.oracle import oracle_plan

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--missions", type=int, default=150)
    ap.add_argument("--epochs", type=int, default=20)
    ap.add_argument("--held-out", type=int, default=20)
    args = ap.parse_args()
    torch.set_num_threads(1)
    example = load_mission(ROOT / "assets" / "example_mission.json")
    epochs: list = []
    stages: dict[str, float] = {}
    t0 = time.perf_counter()

    def progress(stage: str, done: int, total: int) -> None:
        if done == total:
            stages[stage] = time.perf_counter() - t0

    with tempfile.TemporaryDirectory() as tmp:
        res = retrain_attention(attention_setup(args.missions, args.epochs), Path(tmp) / "run", mission=example,
                                on_epoch=epochs.append, on_progress=progress)
        wall = time.perf_counter() - t0
        net, _ = load_policy(res.path)
    oracle_ex = oracle_plan(example).reached_priority
    print(f"class run: {args.missions} missions solved by the oracle in {stages.get('oracle', float('nan')):.0f} s, "
          f"{args.epochs} epochs; {wall:.0f} s in all (one core)")
    print("epoch  loss   agree  priority(search)  priority(first choices)   [example mission; exact oracle "
          f"{oracle_ex}]")
    for e in epochs:
        ev = e.evaluation
        print(f"{e.epoch:>5} {e.loss:6.3f} {e.accuracy:6.3f} {ev['priority']:>17} {ev['priority_net']:>24}")

    bundled = load_policy_cached()
    totals = np.zeros(5)
    for k in range(args.held_out):
        m = random_mission(np.random.default_rng([31000, k]), (3, 8), "single_charge", name=f"held-out {k}")
        ours, theirs = map_score(m)(net), map_score(m)(bundled)
        totals += [oracle_plan(m).reached_priority, ours["priority"], ours["priority_net"], theirs["priority"],
                   theirs["priority_net"]]
    o = totals[0]
    print(f"held-out missions ({args.held_out}, seeds [31000, k], 3-8 destinations): total priority")
    print(f"  exact oracle {o:.0f}; class run {totals[1]:.0f} ({totals[1] / o:.3f}), first choices alone "
          f"{totals[2]:.0f} ({totals[2] / o:.3f}); bundled planner {totals[3]:.0f} ({totals[3] / o:.3f}), "
          f"first choices alone {totals[4]:.0f} ({totals[4] / o:.3f})")


if __name__ == "__main__":
    main()
