"""Dynaformer inference speed on the CPU, with the physics model's time on the same work.

Goals (issue #3): one 3-hour mission prediction <= 20 ms; a batch of 64 <= 200 ms.
Goals (issue #18), on a noisy context (5 mV, 10 mA) of 120 s and of 600 s: the health estimate (physics
fit) plus the prediction of a 3-hour mission <= 20 ms; its 90% EOD interval <= 100 ms. References in
the same run: the take-off estimator's prediction, and the physics fit's own EOD and interval.
Usage: python benchmarks/bench_dynaformer.py [--weights FILE]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))
from _timing import best_of  # noqa: E402

from uam_studio.battery import simulate  # noqa: E402
from uam_studio.battery.health.fit import fit_health  # noqa: E402
from uam_studio.battery.health.intervals import eod_interval_s  # noqa: E402
from uam_studio.dynaformer import load_predictor  # noqa: E402
from uam_studio.dynaformer.data import flight_profile  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--weights", default=None)
    args = ap.parse_args()
    pred = load_predictor(args.weights)
    print(f"torch threads: {torch.get_num_threads()}, weights: {pred.source}")
    rng = np.random.default_rng(0)
    three_h = 3 * 3600
    prof = flight_profile(rng, three_h)
    prof = np.concatenate([prof, np.full(max(0, three_h - prof.size), 0.8)])  # pad to exactly 3 h
    ctx_v = simulate(prof[:20]).voltage_v
    t_one = best_of(lambda: pred.predict(prof[:20], ctx_v, prof), repeat=20)
    t_phys_one = best_of(lambda: simulate(prof, q_max=6500.0, r0=0.1), repeat=20)
    batch = np.stack([np.concatenate([p, np.full(three_h - p.size, 0.8)])
                      for p in (flight_profile(rng, three_h) for _ in range(64))])
    ctx_vb = simulate(batch[:, :20]).voltage_v
    t_b = best_of(lambda: pred.predict(batch[:, :20], ctx_vb, batch), repeat=5)
    t_phys_b = best_of(lambda: simulate(batch, q_max=np.full(64, 6500.0), r0=np.full(64, 0.1)), repeat=5)
    print(f"one 3 h mission ({three_h} samples): dynaformer {1e3 * t_one:.1f} ms (goal <= 20 ms), "
          f"physics {1e3 * t_phys_one:.1f} ms, RATIO physics/dynaformer {t_phys_one / t_one:.2f}x")
    print(f"batch of 64 x 3 h: dynaformer {1e3 * t_b:.1f} ms (goal <= 200 ms), physics {1e3 * t_phys_b:.1f} ms, "
          f"RATIO physics/dynaformer {t_phys_b / t_b:.2f}x")
    health_from_noisy_contexts(pred, prof, rng)


def health_from_noisy_contexts(pred, prof: np.ndarray, rng: np.random.Generator) -> None:
    """Issue #18 latencies: a 3 h mission from a noisy context (5 mV, 10 mA), best of 20 (ms)."""
    volt = simulate(prof, q_max=6500.0, r0=0.1, eod_v=2.5).voltage_v
    for ctx in (120, 600):
        ci = prof[:ctx] + rng.normal(size=ctx) * 0.010
        cv = volt[:ctx] + rng.normal(size=ctx) * 0.005
        mission = np.concatenate([ci, prof[ctx:]])
        t_fit = best_of(lambda: pred.health_estimate(ci, cv), repeat=20)  # noqa: B023
        t_pred = best_of(lambda: pred.predict(ci, cv, mission), repeat=20)  # noqa: B023
        t_int = best_of(lambda: pred.eod_interval_s(ci, cv, mission), repeat=20)  # noqa: B023
        t_band = best_of(lambda: pred.voltage_band(ci, cv, mission), repeat=20)  # noqa: B023
        t_take = best_of(lambda: pred.predict(ci, cv, mission, health_source="model"), repeat=20)  # noqa: B023
        t_phys = best_of(lambda: eod_interval_s(fit_health(ci, cv), mission), repeat=20)  # noqa: B023
        print(f"{ctx} s context, 5 mV: fit + prediction {1e3 * t_pred:.1f} ms (goal <= 20 ms; the fit alone "
              f"{1e3 * t_fit:.1f} ms), EOD interval {1e3 * t_int:.1f} ms (goal <= 100 ms), voltage band "
              f"{1e3 * t_band:.1f} ms; take-off estimator + prediction {1e3 * t_take:.1f} ms, physics fit + EOD "
              f"interval {1e3 * t_phys:.1f} ms")


if __name__ == "__main__":
    main()
