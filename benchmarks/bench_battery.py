"""Battery model speed and exactness: the compiled kernel against progpy, the numpy solver it replaced and a
naive numpy Euler loop, all in the same run.

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 python benchmarks/bench_battery.py

References measured here: progpy's ``simulate_to_threshold`` (per trajectory), the time-vectorised numpy
solver (``solver.integrate_current_vectorised``, in the chunked drop-at-cut-off loop ``simulate`` ran
before the kernel) and a naive step-by-step numpy Euler loop over the same equations. Goals (issue 88):
>= 1000x less time per trajectory than progpy at B = 1024 and >= 3x the numpy solver; one 1500 s leg from
a saved state <= 0.2 ms; a B = 1 whole discharge <= 1 ms; the kernel within 1e-9 V and 0 s of the numpy
solver on the agreement grid's profiles (tests/test_battery_reference.py). A process's first call is
timed in fresh processes, with numba's disk cache warm and cold.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _timing import best_of  # noqa: E402

from uam_studio.battery import BatteryState, full_charge, simulate  # noqa: E402
from uam_studio.battery.eod import first_below  # noqa: E402
from uam_studio.battery.parameters import DEFAULT_CELL  # noqa: E402
from uam_studio.battery.solver import integrate_current_vectorised, output_voltage, step  # noqa: E402
from uam_studio.battery.state import STATE_NAMES  # noqa: E402
from uam_studio.flight import leg_current  # noqa: E402


def vectorised_to_cutoff(current, q, r, eod_v=3.0, chunk=768):
    """The numpy solver as ``simulate`` ran it before the kernel: chunks of ``chunk`` steps, rows dropped
    once past the cut-off. Returns (voltage [B, T], index of the cut-off sample, T where none)."""
    b, t = current.shape
    q_total = DEFAULT_CELL.q_total(q)
    voltage = np.full((b, t), np.nan)
    state = full_charge(q).as_array()
    k_eod = np.full(b, t)
    alive = np.arange(b)
    with np.errstate(all="ignore"):
        for start in range(0, t, chunk):
            if alive.size == 0:
                break
            stop = min(t, start + chunk)
            v, seq = integrate_current_vectorised(current[alive, start:stop], BatteryState.from_array(state[alive]),
                                                  q_total[alive], r[alive], 1.0, DEFAULT_CELL)
            voltage[alive, start:stop] = v
            first = first_below(v, eod_v)
            hit = first >= 0
            state[alive] = np.stack([seq[n][:, -1] for n in STATE_NAMES], axis=-1)
            k_eod[alive[hit]] = start + first[hit]
            alive = alive[~hit]
    return voltage, k_eod


def exactness() -> tuple[float, int]:
    """Worst |dV| (V) on valid samples and worst |dEOD| (samples) between the kernel and the numpy solver,
    over the progpy agreement grid (q_max x R0) under every load profile of the reference test."""
    from test_battery_reference import PROFILES, Q_GRID, R_GRID

    points = np.array([(q, r) for q in Q_GRID for r in R_GRID])
    worst_v, worst_k = 0.0, 0
    for cur in PROFILES.values():
        batch = np.ascontiguousarray(np.broadcast_to(cur, (len(points), cur.size)))
        res = simulate(batch, q_max=points[:, 0], r0=points[:, 1])
        v_ref, k_ref = vectorised_to_cutoff(batch, points[:, 0].copy(), points[:, 1].copy())
        k_new = np.where(res.eod_reached, np.argmin(res.valid, axis=1), cur.size)
        worst_k = max(worst_k, int(np.abs(k_new - k_ref).max()))
        both = res.valid & (np.arange(cur.size)[None, :] < k_ref[:, None])
        worst_v = max(worst_v, float(np.abs(res.voltage_v - v_ref)[both].max()))
    return worst_v, worst_k


def first_call_s(cold: bool) -> float:
    """Seconds a fresh process takes to import the battery package and run its first simulation (numba's
    disk cache cold: a new, empty cache folder)."""
    code = ("import time; t = time.perf_counter(); import numpy as np; from uam_studio.battery import simulate; "
            "simulate(np.full(3000, 2.0)); print(time.perf_counter() - t)")
    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as cache:
        if cold:
            env["NUMBA_CACHE_DIR"] = cache
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


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
    t_numpy = best_of(lambda: vectorised_to_cutoff(current, q, r), repeat=2)

    q_total = DEFAULT_CELL.q_total(q)

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
    print(f"ours (compiled kernel, B={b}): {t_ours:.3f} s total, {per_ours * 1e3:.3f} ms per trajectory")
    print(f"numpy time-vectorised solver (B={b}): {t_numpy:.3f} s total, {t_numpy / b * 1e3:.3f} ms per trajectory")
    print(f"naive step-by-step numpy Euler (B={b}): {t_naive:.3f} s total, {t_naive / b * 1e3:.3f} ms per trajectory")
    if BatteryElectroChemEOD is not None:
        print(f"RATIO progpy/ours per trajectory: {per_progpy / per_ours:.0f}x (goal >= 1000x)")
    print(f"RATIO numpy solver/ours: {t_numpy / t_ours:.1f}x (goal >= 3x)")
    print(f"RATIO naive/ours: {t_naive / t_ours:.1f}x")

    # One 1500 s leg (~47 km at 1000 m) continued from a saved mid-mission state.
    leg = leg_current(47.0, 1000, 13)[:1500]
    first = simulate(leg_current(40.0, 1000, 0.0))
    state = first.final_state
    t_leg = best_of(lambda: simulate(leg, initial_state=state), repeat=200)
    print(f"one {leg.size} s leg from a saved state: {t_leg * 1e3:.3f} ms (goal <= 0.2 ms)")
    whole = np.full(5000, 2.0)
    t_one = best_of(lambda: simulate(whole), repeat=50)
    print(f"B=1 whole discharge at 2 A (EOD {simulate(whole).eod_s:.0f} s): {t_one * 1e3:.3f} ms (goal <= 1 ms)")

    worst_v, worst_k = exactness()
    print(f"kernel vs numpy solver over the agreement grid and profiles: max|dV| {worst_v:.2e} V (goal <= 1e-9), "
          f"max|dEOD| {worst_k} s (goal 0)")
    print(f"a fresh process's import + first simulation: {first_call_s(False):.2f} s with numba's disk cache, "
          f"{first_call_s(True):.2f} s with an empty cache (compiling)")


if __name__ == "__main__":
    main()
