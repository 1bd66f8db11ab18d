"""Agreement with NASA progpy over the whole (q_max, R0) grid under every load profile of
``tests/test_battery_reference.py`` (the test checks three grid points per profile, the whole grid once).

    python benchmarks/bench_progpy_agreement.py      # needs the `reference` extra (progpy); about 2 min

Prints, per profile, the worst voltage and EOD difference over the 12 grid points and the time of our
batched solver against progpy's ``simulate_to_threshold`` on the same runs. Goal: |dV| <= 1 mV,
|dEOD| <= 1 s everywhere.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_battery_reference import PROFILES, Q_GRID, R_GRID, agreement, progpy_run  # noqa: E402

from uam_studio.battery import simulate  # noqa: E402


def main() -> None:
    points = [(q, r) for q in Q_GRID for r in R_GRID]
    qs, rs = np.array(points).T
    ok = True
    for name, cur in PROFILES.items():
        t0 = time.perf_counter()
        worst_dv, worst_deod = agreement(cur, points)
        t_both = time.perf_counter() - t0
        t0 = time.perf_counter()
        simulate(np.broadcast_to(cur, (qs.size, cur.size)), q_max=qs, r0=rs)
        t_ours = time.perf_counter() - t0
        t0 = time.perf_counter()
        progpy_run(cur, *points[0])
        t_ref_one = time.perf_counter() - t0
        ok &= worst_dv <= 1e-3 and worst_deod <= 1.0
        print(f"{name:11s} 12 grid points: max|dV| {worst_dv * 1e3:7.4f} mV, max|dEOD| {worst_deod:4.1f} s; "
              f"ours (batched, 12) {t_ours * 1e3:7.1f} ms, progpy one run {t_ref_one:5.2f} s "
              f"(all 12 with progpy {t_both:5.1f} s)")
    print("goal (|dV| <= 1 mV, |dEOD| <= 1 s on every point):", "met" if ok else "NOT met")


if __name__ == "__main__":
    main()
