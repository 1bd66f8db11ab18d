"""Battery model speed: batched full discharges and one leg from a saved state.

References measured in the same run: progpy's ``simulate_to_threshold`` (per
trajectory) and a naive step-by-step Euler loop over the same equations.
Goals (issue #2): >= 300x less time per trajectory than progpy at B = 1024
(aim 1000x); one 1500 s leg from a saved state <= 2 ms.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _timing import best_of  # noqa: E402

from uam_studio.battery import full_charge, simulate  # noqa: E402
from uam_studio.battery.parameters import DEFAULT_CELL  # noqa: E402
from uam_studio.battery.solver import step  # noqa: E402
from uam_studio.flight import leg_current  # noqa: E402


def main() -> None:
    rng = np.random.default_rng(0)
    b, horizon = 1024, 12000
    amps = rng.uniform(1.0, 3.0, b)
    q = rng.uniform(5000, 8000, b)
    r = rng.uniform(0.017, 0.2, b)
    current = np.repeat(amps[:, None], horizon, axis=1)
    res = simulate(current, q_max=q, r0=r)
    print(f"batch: B={b}, horizon {horizon} s, EOD reached by {int(res.eod_reached.sum())}/{b}, "
          f"median EOD {np.nanmedian(res.eod_s):.0f} s")
    t_ours = best_of(lambda: simulate(current, q_max=q, r0=r), repeat=3)
    per_ours = t_ours / b

    # Naive loop: explicit Euler one step at a time, batched over B, until all reach EOD.
    q_total = DEFAULT_CELL.q_total(q)
    from uam_studio.battery.solver import output_voltage

    def naive():
        x = full_charge(q)
        alive = np.ones(b, bool)
        for _ in range(horizon):
            x = step(x, amps, q_total, r, 1.0, DEFAULT_CELL)
            alive &= output_voltage(x.__dict__, q_total, DEFAULT_CELL) >= 3.0
            if not alive.any():
                break
    t_naive = best_of(naive, repeat=1)

    try:
        from progpy.models import BatteryElectroChemEOD
    except ImportError:
        print("progpy not installed: install the 'reference' extra for the progpy ratio")
        BatteryElectroChemEOD = None
    if BatteryElectroChemEOD is not None:
        n_ref = 6
        t0 = time.perf_counter()
        for k in range(n_ref):
            m = BatteryElectroChemEOD(qMobile=q[k], Ro=r[k])
            i_k = float(amps[k])
            m.simulate_to_threshold(lambda t, x=None, i_k=i_k, m=m: m.InputContainer({"i": i_k}), dt=1.0)
        per_progpy = (time.perf_counter() - t0) / n_ref
        print(f"progpy simulate_to_threshold: {per_progpy * 1e3:.1f} ms per trajectory (mean of {n_ref})")
    print(f"ours (time-vectorised, B={b}): {t_ours:.3f} s total, {per_ours * 1e3:.3f} ms per trajectory")
    print(f"naive step-by-step Euler (B={b}): {t_naive:.3f} s total, {t_naive / b * 1e3:.3f} ms per trajectory")
    if BatteryElectroChemEOD is not None:
        print(f"RATIO progpy/ours per trajectory: {per_progpy / per_ours:.0f}x (goal >= 300x, aim 1000x)")
    print(f"RATIO naive/ours: {t_naive / t_ours:.1f}x")

    # One 1500 s leg (~47 km at 1000 m) continued from a saved mid-mission state.
    leg = leg_current(47.0, 1000, 13)[:1500]
    first = simulate(leg_current(40.0, 1000, 0.0))
    state = first.final_state
    t_leg = best_of(lambda: simulate(leg, initial_state=state), repeat=50)
    print(f"one {leg.size} s leg from a saved state: {t_leg * 1e3:.3f} ms (goal <= 2 ms)")


if __name__ == "__main__":
    main()
