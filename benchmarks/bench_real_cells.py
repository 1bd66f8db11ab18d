"""The battery, health and safety models on real VTC6 cells (the CMU eVTOL dataset, issue "Real cells").

    OMP_NUM_THREADS=1 python benchmarks/bench_real_cells.py --data ../shared/data/cmu_evtol

Prints the validation table of ``uam-studio evaluate real`` (held-out refits included), then the goals
against it. The reference rows are measured in the same run: the NASA default cell on the same real
mission (the size of the mismatch), and the dataset's own integrated capacities.

Goals: physics model on the real mission (identified cell, held out) RMSE <= 15 mV and landing-voltage
error <= 20 mV; on both held-out parameter sets and contexts 20/60/120 s, no missed breach at cut-offs
3.0-3.3 V, the measured landing minimum inside the 90% interval in 5 of 6, median width <= 250 mV
(issue 38); health fit from 120 s within 30 mV with the measurement inside its 90% interval; the
Dynaformer within 1.5x of the physics fit's error; capacity within 3% over each cell's life.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from uam_studio.studies.real_cells import (
    SET_BUNDLED,
    SET_CELL,
    SET_LANDING,
    format_report,
    held_out_summary,
    real_cell_report,
)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=None, help="the dataset's folder (default $UAM_STUDIO_CMU_DATA)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    report = real_cell_report(args.data, refit=True)
    wall = time.perf_counter() - t0
    print(format_report(report))
    print(f"\n(whole report {wall:.0f} s)\n\ngoals:")
    held = [r for r in report.physics if r["model"] == "VTC6 refit"]
    for r in held:
        ok = r["rmse_mv_power"] <= 15 and abs(r["landing_min_err_mv_power"]) <= 20
        print(f"  physics, held out {r['held out']}: RMSE {r['rmse_mv_power']:.1f} mV (goal 15), landing "
              f"{r['landing_min_err_mv_power']:+.1f} mV (goal 20): {'met' if ok else 'NOT met'}")
    nasa = next(r for r in report.physics if r["model"].startswith("NASA 18650"))
    vtc6 = report.physics[0]
    print(f"  reference: the NASA default cell's RMSE {nasa['rmse_mv_power']:.0f} mV before its cut-off at "
          f"{nasa['cutoff_s_power']:.0f} s; ratio to the bundled VTC6 set "
          f"{nasa['rmse_mv_power'] / vtc6['rmse_mv_power']:.0f}x")
    summary = held_out_summary(report)
    held_sets = [SET_LANDING, SET_CELL]
    missed = sum(summary[k]["missed_breaches"] for k in held_sets)
    inside = sum(summary[k]["inside"] for k in held_sets)
    widths = [1000 * (r["high_v"] - r["low_v"]) for r in report.health if r["set"] in held_sets]
    print(f"  held-out sets ({', '.join(held_sets)}), contexts 20/60/120 s: missed breaches {missed} of "
          f"{sum(summary[k]['cases'] for k in held_sets)} (goal 0): {'met' if missed == 0 else 'NOT met'}; "
          f"inside in {inside} of {len(widths)} (goal 5): {'met' if inside >= 5 else 'NOT met'}; median width "
          f"{np.median(widths):.0f} mV (goal 250): {'met' if np.median(widths) <= 250 else 'NOT met'}")
    ref = summary[SET_BUNDLED]
    print(f"  reference, the bundled set (in-sample: it read this landing): missed {ref['missed_breaches']}, inside "
          f"{ref['inside']} of {ref['contexts']}, median width {ref['median_width_mv']:.0f} mV")
    h120 = next(r for r in report.health if r["context_s"] == 120 and r["set"] == SET_LANDING)
    print(f"  health fit 120 s ({SET_LANDING}, fleet prior): {h120['error_mv']:+.1f} mV (goal 30), inside its 90% "
          f"interval: {h120['inside']}: {'met' if abs(h120['error_mv']) <= 30 and h120['inside'] else 'NOT met'}")
    for r in report.health_likelihood:
        if r["context_s"] == 120 and r["set"] == SET_LANDING:  # the reference: the likelihood alone, same run
            print(f"  reference: health fit 120 s without the prior: {r['error_mv']:+.1f} mV, inside: {r['inside']}")
    dynaformers = [("as bundled (NASA cell)", report.dynaformer, SET_BUNDLED)]
    dynaformers += [(f"fine-tuned on the {label} set (held out)",
                     [r for r in report.dynaformer_held_out if r["set"] == label], label) for label in held_sets]
    dynaformers.append(("fine-tuned on the bundled VTC6 set (in-sample)", report.dynaformer_vtc6, SET_BUNDLED))
    for what, rows, health_set in dynaformers:
        if not rows:
            print(f"  Dynaformer {what}: no rows")
            continue
        for d in rows:
            if "error_mv" not in d:
                print(f"  Dynaformer {what} {d['context_s']} s: refused: {d['error']}")
                continue
            ref = next(r for r in report.health if r["context_s"] == d["context_s"] and r["set"] == health_set)
            ratio = abs(d["error_mv"]) / max(abs(ref["error_mv"]), 1e-9)
            same = abs(d["error_mv"]) / max(abs(d["physics_error_mv"]), 1e-9)
            print(f"  Dynaformer {what} {d['context_s']} s: {d['error_mv']:+.1f} mV, inside its 90% band: "
                  f"{d['inside']}; {ratio:.1f}x the physics fit's on the set it reads ({health_set}, "
                  f"{ref['error_mv']:+.1f} mV; goal 1.5x): {'met' if ratio <= 1.5 else 'NOT met'}; reference: "
                  f"its own fit flown along the same current {d['physics_error_mv']:+.1f} mV ({same:.1f}x)")
    for key, what in (("_whole", "whole discharge"), ("", "part above 3.4 V")):
        errs = np.array([r[f"error_pct{key}"] for r in report.capacity])
        print(f"  capacity from the {what}: worst {np.nanmax(np.abs(errs)):.2f}% over {len(errs)} reference "
              f"discharges (goal 3%): {'met' if np.nanmax(np.abs(errs)) <= 3 else 'NOT met'}")


if __name__ == "__main__":
    main()
