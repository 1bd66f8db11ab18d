"""How much the VTC6 identification's held-out answer depends on where its local fit starts.

    OMP_NUM_THREADS=1 python benchmarks/bench_identify_starts.py --data ../shared/data/cmu_evtol
    OMP_NUM_THREADS=1 python benchmarks/bench_identify_starts.py --data ../shared/data/cmu_evtol --hold-out none

``uam-studio identify vtc6`` runs one local least-squares fit from one start (``vtc6_start``). This
benchmark runs the same fit (same data, same hold-out) from that start and from ``--starts - 1`` others,
drawn log-uniformly within a decade of it (seeds 1, 2, ...), and scores each solution on VAH01's real
1 Hz mission flown by power, as ``uam-studio evaluate real`` does. The reference, in the same run, is
the bundled procedure's own start. It prints each solution's cost (the fit's objective) beside its
held-out voltage RMSE and landing-voltage error, then what the lowest cost found predicts.

It also measures, without any model, the landing's polarization of the real cells: (C/5 voltage at the
same charge out - measured voltage) / current (mohm), VAH01's 1 Hz landing against VAH07's first
missions' landings (30 s samples), with VAH07's first C/5 discharge as the open-circuit curve of both.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

from uam_studio.battery.parameters import Cell, CellParameters
from uam_studio.battery.real.cmu_data import (
    LANDING,
    MISSION_FILE,
    MissionLog,
    data_folder,
    last_rest,
    load_cell_log,
    mission_cycle,
    reference_discharges,
    resampled_missions,
)
from uam_studio.battery.real.cmu_replay import (
    HOLD_OUTS,
    IDENTIFICATION_FILE,
    START_Q_MAX,
    START_R0,
    vtc6_fit_segments,
    vtc6_start,
)
from uam_studio.battery.real.identify import BOUNDS, identify_cell
from uam_studio.studies.real_cells import physics_row

_SCALED = ("kn", "kp", "t_sn_s", "t_sp_s", "r0_activation_k", "k_activation_k", "thermal_tau_s")


def drawn_start(rng: np.random.Generator) -> tuple[CellParameters, float, float]:
    """A start within a decade of :func:`vtc6_start` (each kinetic and time constant), a surface share
    of 0.02-0.5, a diffusion time constant of 2-1000 s, q_max within 12% and R0 within 2x."""
    base = vtc6_start()
    kw = {n: float(np.clip(getattr(base, n) * 10 ** rng.uniform(-1, 1), *BOUNDS[n])) for n in _SCALED}
    kw["vol_s_fraction"] = float(rng.uniform(0.02, 0.5))
    drawn = replace(base, **kw)
    tau_s = 10 ** rng.uniform(np.log10(2.0), 3.0)
    drawn = replace(drawn, t_diffusion_s=tau_s * (1.0 / drawn.vol_b + 1.0 / drawn.vol_s))
    return drawn, START_Q_MAX * 10 ** rng.uniform(-0.05, 0.05), START_R0 * 10 ** rng.uniform(-0.3, 0.3)


def landing_polarization(folder, mission: MissionLog) -> list[tuple[str, float, float, float, float]]:
    """(log, charge out C, current A, temperature C, polarization mohm) of landing samples: VAH01's
    (``mission``, its 1 Hz log) and those of VAH07's first four missions."""
    life = load_cell_log(folder / IDENTIFICATION_FILE)
    ref = reference_discharges(life)[0]
    c5_v = life.voltage_v[ref.start:ref.stop]
    c5_out = np.r_[0.0, np.cumsum(life.current_a[ref.start:ref.stop]) * life.dt_s][:-1]
    rows = []
    log = mission.log
    out = np.cumsum(log.current_a)  # 1 s samples from a full cell
    for k in np.flatnonzero(log.segment == LANDING)[5::15]:
        rows.append(("VAH01 (1 Hz)", out[k], log.current_a[k], log.temperature_c[k],
                     1000 * (np.interp(out[k], c5_out, c5_v) - log.voltage_v[k]) / log.current_a[k]))
    for j, m in enumerate(resampled_missions(life)[:4]):
        rest = last_rest(life, m.index[0])
        out0 = np.interp(-life.voltage_v[rest], -c5_v, c5_out)  # charge out of the rested start (C)
        span = np.arange(rest, m.index[-1] + 1)
        out = out0 + np.r_[0.0, np.cumsum(life.current_a[span][:-1] * np.diff(life.time_s[span]))]
        for k, seg in zip(m.index, m.segment):
            if seg == LANDING:
                q = out[k - rest]
                rows.append((f"VAH07 mission {j}", q, life.current_a[k], life.temperature_c[k],
                             1000 * (np.interp(q, c5_out, c5_v) - life.voltage_v[k]) / life.current_a[k]))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=None, help="the dataset's folder (default $UAM_STUDIO_CMU_DATA)")
    ap.add_argument("--starts", type=int, default=12, help="fits, the bundled procedure's start included")
    ap.add_argument("--hold-out", default="landing", choices=HOLD_OUTS)
    args = ap.parse_args()
    folder = data_folder(args.data)
    mission = mission_cycle(load_cell_log(folder / MISSION_FILE))
    segments = vtc6_fit_segments(folder, hold_out=args.hold_out)
    rows = []
    t_all = time.perf_counter()
    for k in range(args.starts):
        start, q0, r0 = (vtc6_start(), START_Q_MAX, START_R0) if k == 0 else drawn_start(np.random.default_rng(k))
        t0 = time.perf_counter()
        fit = identify_cell(segments, start, q0, r0, max_nfev=300)
        row = physics_row("fit", args.hold_out, Cell("fit", fit.cell, fit.q_max, fit.r0), mission)
        rows.append((fit.cost, k, row["rmse_mv_power"], row["landing_min_err_mv_power"], fit, time.perf_counter() - t0))
    print(f"VTC6 identification from {args.starts} starts, held out: {args.hold_out}; scored on VAH01's mission "
          f"flown by power (start 0: the bundled procedure's; others: seeds 1-{args.starts - 1})")
    print(" start   cost x1e6 V^2   RMSE mV   landing mV   q_max C   R0 ohm   diffusion tau s   surface share   fit s")
    for cost, k, rmse, land, fit, sec in sorted(rows, key=lambda r: r[0]):
        print(f"{k:6d} {1e6 * cost:15.1f} {rmse:9.1f} {land:+12.1f} {fit.q_max:9.0f} {fit.r0:8.4f} "
              f"{fit.cell.diffusion_tau_s:17.1f} {fit.cell.vol_s_fraction:15.3f} {sec:7.0f}")
    best = min(rows, key=lambda r: r[0])
    own = next(r for r in rows if r[1] == 0)
    near = [r for r in rows if r[0] <= 1.05 * best[0]]
    print(f"\nlowest cost found: start {best[1]}, RMSE {best[2]:.1f} mV, landing {best[3]:+.1f} mV")
    print(f"reference, the bundled procedure's start: cost {own[0] / best[0]:.2f}x the lowest, RMSE {own[2]:.1f} mV, "
          f"landing {own[3]:+.1f} mV")
    print(f"solutions within 5% of the lowest cost: {len(near)} of {len(rows)}, landing "
          f"{min(r[3] for r in near):+.1f} to {max(r[3] for r in near):+.1f} mV, RMSE "
          f"{min(r[2] for r in near):.1f} to {max(r[2] for r in near):.1f} mV")
    print(f"(fits {time.perf_counter() - t_all:.0f} s)")
    print("\nlanding polarization, model-free: (C/5 voltage at the same charge out - measured V) / current")
    print("log                   charge out C   current A   temperature C   polarization mohm")
    for name, q, i, temp, pol in landing_polarization(folder, mission):
        print(f"{name:20s} {q:14.0f} {i:11.1f} {temp:15.1f} {pol:19.1f}")


if __name__ == "__main__":
    main()
