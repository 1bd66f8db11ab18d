"""Tiny timing helpers shared by the benchmark scripts."""

from __future__ import annotations

import time
from collections.abc import Callable


def best_of(fn: Callable[[], object], repeat: int = 5) -> float:
    """Best wall time (s) of ``repeat`` calls (the least disturbed run)."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def percentile_ms(samples_s: list[float], q: float) -> float:
    s = sorted(samples_s)
    k = min(len(s) - 1, max(0, int(round(q / 100 * (len(s) - 1)))))
    return 1000 * s[k]
