"""Leave one cell out over the CMU eVTOL dataset's four resampled lives (issue 38): each baseline
mission's landing predicted from the same cell's previous flight, on a VTC6 parameter set identified
without that cell (``uam_studio.studies.real_lives``).

    OMP_NUM_THREADS=1 python benchmarks/bench_real_lives.py --data ../shared/data/cmu_evtol [--every 1] [--max-nfev 100]

Prints, per held-out cell: missions, landing samples, coverage of the 90% interval at the sampled
times, median width, breaches and missed breaches (cut-offs 3.0-3.3 V x samples), for the calibrated
interval (the health draws' interval moved out, or in, by the conformal margin of the cell's own earlier
predictions) and, the
reference in the same run, the health-only interval. Goals: coverage 80-98% per cell, 0 missed breaches.
"""

from __future__ import annotations

import argparse
import time

from uam_studio.studies.real_lives import format_scores, leave_one_cell_out, totals_line


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=None, help="the dataset's folder (default $UAM_STUDIO_CMU_DATA)")
    ap.add_argument("--every", type=int, default=1, help="score every n-th mission (default all)")
    ap.add_argument("--max-nfev", type=int, default=100, help="identification evaluations per parameter set")
    args = ap.parse_args()
    t0 = time.perf_counter()
    scores = leave_one_cell_out(args.data, every=args.every, max_nfev=args.max_nfev)
    print(format_scores(scores))
    print(totals_line(scores))
    print(f"\n({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
