"""How a DQN fine-tuning run starts: its first episodes against a run from random weights.

    python benchmarks/bench_fine_tune.py [--steps 600] [--episodes 40] [--seed 123]

Three short runs on the example mission (``assets/example_mission.json``, a random cell each
episode, the app's Retrain settings): from random weights (the reference), fine-tuning the bundled
single-charge agent with SB3's uniform random warm-up, and fine-tuning with the agent's own
epsilon-greedy warm-up (:data:`~uam_studio.planning.agents.dqn.training.FINE_TUNE`, the default). Prints
the mean reached priority and reward of the first ``--episodes`` episodes of each, and the ratios to
the reference.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from uam_studio.planning.agents.dqn.training import train_dqn
from uam_studio.planning.agents.retrain import training_setup
from uam_studio.planning.missions.mission import load_mission

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=600)
    p.add_argument("--episodes", type=int, default=40)
    p.add_argument("--seed", type=int, default=123)
    args = p.parse_args(argv)
    mission = load_mission(ROOT / "assets" / "example_mission.json")
    bundled = str(ROOT / "pretrained" / "dqn_single_charge.zip")
    runs = (("random weights (reference)", None, None), ("fine-tune, uniform random warm-up", bundled, True),
            ("fine-tune, the agent's own warm-up (default)", bundled, False))
    ref = None
    for name, init, random_warmup in runs:
        cfg, env_fn = training_setup(mission=mission, steps=args.steps, seed=args.seed, init_agent=init)
        if random_warmup is not None:
            cfg = replace(cfg, random_warmup=random_warmup)
        episodes: list = []
        t0 = time.perf_counter()
        train_dqn(cfg, env_fn, callback=episodes.append)
        first = episodes[:args.episodes]
        prio = float(np.mean([e.reached_priority for e in first]))
        reward = float(np.mean([e.reward for e in first]))
        ref = ref or (prio, reward)
        print(f"{name}: first {len(first)} episodes: mean priority {prio:.2f} (x{prio / ref[0]:.2f} the reference), "
              f"mean reward {reward:+.2f}; learning_starts {cfg.learning_starts}, random warm-up "
              f"{cfg.random_warmup}; {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
