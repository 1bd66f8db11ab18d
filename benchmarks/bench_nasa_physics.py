"""The physics method on real NASA lives: the identified NASA 18650 (``NASA_IDENTIFIED``, fitted on B0005's
first three discharges only) predicting each discharge's time to the cut-off from the cell's earlier
discharges and its planned current, beside the history predictor and persistence measured in the same run.

    python benchmarks/bench_nasa_physics.py [--data DIR] [--cell B0007 ...] [--cutoff-v 3.0] [--context-s 300]

B0005 is left out (the identification read it). Errors are in % of the true time left at the prediction
instant (``context_s`` after the first loaded sample), as ``uam-studio evaluate nasa`` scores; the same
discharges for every method (those with a physics prediction, a history prediction and a true time past the
context). Printed per condition group (``bench_nasa_eod.GROUPS``): median and p95 |error| and bias of each,
the physics method's medians over the history predictor's (the Dynaformer goal's yardstick: RESULTS), and
the run time of each method.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from bench_nasa_eod import GROUPS

from uam_studio.battery.parameters import NASA_IDENTIFIED
from uam_studio.battery.real.nasa_data import load_nasa_folder, nasa_folder
from uam_studio.battery.real.nasa_eval import evaluate_nasa
from uam_studio.battery.real.nasa_model import bundled_model
from uam_studio.battery.real.nasa_physics import IDENTIFY_CELL, predict_life


def _group(cell: str) -> str:
    return next((g for g, cells in GROUPS.items() if cell in cells), "other")


def _stats(e: list[float]) -> str:
    a = np.abs(e)
    return f"{np.median(a):7.2f} {np.percentile(a, 95):7.2f} {np.median(e):+7.2f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--cell", nargs="*", default=None)
    ap.add_argument("--cutoff-v", type=float, default=3.0)
    ap.add_argument("--context-s", type=float, default=300.0)
    args = ap.parse_args()
    cells = load_nasa_folder(nasa_folder(args.data), None, args.cutoff_v)
    t0 = time.perf_counter()
    model = bundled_model(args.context_s, args.cutoff_v)
    scored = [c for c in cells if c.name != IDENTIFY_CELL and (not args.cell or c.name in args.cell)]
    hist = {(r.cell, r.discharge): r for r in evaluate_nasa(scored, model, [c for c in cells
                                                                           if c.name in model.trained_on])}
    t_hist = time.perf_counter() - t0
    t0 = time.perf_counter()
    phys = {(c.name, p.index): p for c in scored for p in predict_life(c, NASA_IDENTIFIED, args.cutoff_v,
                                                                          args.context_s)}
    t_phys = time.perf_counter() - t0
    errs: dict[str, dict[str, list[float]]] = {}
    for key, p in phys.items():
        h = hist.get(key)
        if p.median_s is None or h is None or p.true_s is None or p.true_s <= args.context_s:
            continue
        left = p.true_s - args.context_s
        g = errs.setdefault(_group(key[0]), {"physics": [], "history": [], "persistence": []})
        g["physics"].append(100 * (p.median_s - p.true_s) / left)
        g["history"].append(100 * (h.median_s - p.true_s) / left)
        if h.persistence_s is not None:
            g["persistence"].append(100 * (h.persistence_s - p.true_s) / left)
    print(f"{len(scored)} cells ({IDENTIFY_CELL} left out: the identification read it); {args.context_s:.0f} s "
          f"context, {args.cutoff_v} V; |error| in % of the time left")
    print(f"{'group':36s} {'n':>4s} | {'physics med p95 bias':>23s} | {'history med p95 bias':>23s} | "
          f"{'persistence med p95 bias':>23s} | phys/hist med")
    total: dict[str, list[float]] = {"physics": [], "history": [], "persistence": []}
    for g in [*GROUPS, "other"]:
        if g not in errs:
            continue
        e = errs[g]
        for k in total:
            total[k] += e[k]
        pers = _stats(e["persistence"]) if e["persistence"] else f"{'-':>23s}"
        ratio = np.median(np.abs(e["physics"])) / max(np.median(np.abs(e["history"])), 1e-9)
        print(f"{g:36s} {len(e['physics']):4d} | {_stats(e['physics'])} | {_stats(e['history'])} | {pers} | "
              f"{ratio:6.2f}")
    ratio = np.median(np.abs(total["physics"])) / np.median(np.abs(total["history"]))
    print(f"{'all':36s} {len(total['physics']):4d} | {_stats(total['physics'])} | {_stats(total['history'])} | "
          f"{_stats(total['persistence'])} | {ratio:6.2f}")
    print(f"run time: physics {t_phys:.0f} s, history predictor {t_hist:.0f} s")


if __name__ == "__main__":
    main()
