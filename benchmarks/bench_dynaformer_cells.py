"""The Dynaformer per cell type: the VTC6 fine-tune's decoder against the NASA weights on VTC6 discharges.

    OMP_NUM_THREADS=2 python benchmarks/bench_dynaformer_cells.py [--n 200]

Held-out VTC6 discharges (power missions seed 777001, generic loads seed 777002; training used seed 0),
each decoded by both bundled weights given the exact health (q_max, R0), so only the decoder's own error
is measured: voltage RMSE before the 2.5 V floor and the 3.0 V EOD time's relative error. The NASA
weights are the reference in the same run (what the VTC6 would get without fine-tuning); the ratio is
printed. Goal (the card's): RMSE <= 20 mV and median EOD error <= 1% on the missions.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from uam_studio.battery.fit import crossing_times
from uam_studio.dynaformer import load_predictor
from uam_studio.dynaformer.data import make_dataset
from uam_studio.dynaformer.predictor import bundled_weights_path

SETS = (("missions", 1.0, 777_001), ("generic", 0.0, 777_002))


def decoder_errors(cell: str, ds, batch: int = 50) -> tuple[float, float, float, int]:
    """(RMSE mV, median RTE, p90 RTE, discharges reaching 3.0 V) of the bundled ``cell`` weights on ``ds``."""
    pred = load_predictor(bundled_weights_path(cell))
    pts = np.column_stack([ds.q_max, ds.r0])
    cur = ds.current_a.astype(float)
    t = np.arange(cur.shape[1])[None, :]
    truth, _ = crossing_times(np.where(t < ds.length[:, None], ds.voltage_v, 5.0), 1.0, 3.0)
    v = np.concatenate([pred._decode(None, cur[s:s + batch], skip_rest=True, points=pts[s:s + batch])
                        for s in range(0, len(ds), batch)])
    v = np.where(t < ds.length[:, None], v, 5.0)
    rmse = 1000 * float(np.sqrt(np.mean((v[ds.valid] - ds.voltage_v[ds.valid]) ** 2)))
    got, _ = crossing_times(v, 1.0, 3.0)
    ok = np.isfinite(truth)
    rte = np.abs(got[ok] - truth[ok]) / truth[ok]
    return rmse, float(np.median(rte)), float(np.quantile(rte, 0.9)), int(ok.sum())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=200, help="discharges per set")
    args = ap.parse_args()
    t0 = time.perf_counter()
    goals = []
    for name, flights, seed in SETS:
        ds = make_dataset(args.n, seed=seed, cell="vtc6", flight_fraction=flights)
        rows = {cell: decoder_errors(cell, ds) for cell in ("vtc6", "nasa18650")}
        for cell, (rmse, med, p90, n_eod) in rows.items():
            print(f"{name:8s} weights {cell:9s}: RMSE {rmse:6.1f} mV, EOD 3.0 V in {n_eod} of {args.n}: "
                  f"median RTE {med:.4f}, p90 {p90:.4f}")
        ratio = rows["nasa18650"][0] / rows["vtc6"][0]
        print(f"{name:8s} reference / fine-tuned RMSE: {ratio:.0f}x")
        if name == "missions":
            goals.append(rows["vtc6"][0] <= 20 and rows["vtc6"][1] <= 0.01)
    print(f"({time.perf_counter() - t0:.0f} s) goal (missions: RMSE <= 20 mV, median RTE <= 1%): "
          f"{'met' if all(goals) else 'NOT met'}")


if __name__ == "__main__":
    main()
