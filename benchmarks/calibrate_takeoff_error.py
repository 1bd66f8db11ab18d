"""The take-off belief's first-leg error on calibration flights that no benchmark flies: what sets the take-off's
model-error term (``uam_studio.battery.health.config.PAPER_BELIEF``).

    OMP_NUM_THREADS=1 python benchmarks/calibrate_takeoff_error.py [--n 40] [--world varied]

New packs (no logbook), single-charge missions ``study_missions(n, 57000, "single_charge")``, world seeds and packs
57100 + k, no weather change, in ``--world`` (default the varied world, the default world). For each flight that
flew a leg: the first leg's lowest voltage the world gave minus the take-off belief's median
(``takeoff_belief.first_leg_min_voltage_median_v``), and whether the belief's 90% interval held it. Printed: the
miss's mean, median, std and quantiles, the part of its variance the belief's health and wind already hold (the
interval's width above the median without the model-error term), the model-error term the flights call for (each
side's, from the miss's 5% and 95% quantiles), and the coverage of the interval as it is. ``bench_weather.py fresh``
then measures the term on its own missions (seed 56000).
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's uam_studio

from uam_studio.planning.operations import fly_mission  # noqa: E402
from uam_studio.studies.flying import study_missions  # noqa: E402

Z90 = 1.6448536269514722  # the 95% quantile of N(0, 1): a 90% interval's half width in std


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=40, help="calibration missions (single-charge, seed 57000)")
    ap.add_argument("--world", default="varied", choices=["varied", "model"])
    args = ap.parse_args()
    misses, held_sd, terms, lows, inside, below = [], [], [], [], 0, 0
    for k, mission in enumerate(study_missions(args.n, 57000, "single_charge")):
        rec = fly_mission(mission, seed=57100 + k, pack=57100 + k, world=args.world, references=False)
        tb = rec.takeoff_belief
        if rec.first_leg_min_voltage_v is None or "first_leg_min_voltage_90_v" not in tb:
            continue
        lo, hi = tb["first_leg_min_voltage_90_v"]
        med, got, term = tb["first_leg_min_voltage_median_v"], rec.first_leg_min_voltage_v, tb["model_error_v"]
        misses.append(got - med)
        above_sd = (hi - med) / Z90  # the interval's std above the median: the health's, the wind's and the term's
        held_sd.append(math.sqrt(max(above_sd ** 2 - term ** 2, 0.0)))  # the health's and the wind's part
        terms.append(term)
        lows.append(tb.get("model_error_low_v", term))
        inside += lo <= got <= hi
        below += got < lo
    m = np.array(misses) * 1e3
    n = m.size
    rest = math.sqrt(max(float(np.mean(m ** 2)) - float(np.mean(np.square(held_sd) * 1e6)), 0.0))
    rest_centred = math.sqrt(max(float(np.var(m)) - float(np.mean(np.square(held_sd) * 1e6)), 0.0))
    print(f"{n} flights ({args.world} world, new packs, seed 57000 / worlds 57100+)")
    print(f"  miss (world - believed median), mV: mean {m.mean():+.1f}, median {np.median(m):+.1f}, "
          f"std {m.std(ddof=1):.1f}; 5/25/75/95%: {', '.join(f'{q:+.1f}' for q in np.percentile(m, [5, 25, 75, 95]))}")
    held = 1e3 * math.sqrt(statistics.fmean(np.square(held_sd)))
    lo5, hi95 = np.percentile(m, [5, 95])
    side = [math.sqrt(max((q / Z90) ** 2 - held ** 2, 0.0)) for q in (lo5, hi95)]
    above, below_now = 1e3 * statistics.fmean(terms), 1e3 * statistics.fmean(lows)
    print(f"  held by the health and the wind (rms): {held:.1f} mV; model-error term now {above:.1f} mV above the "
          f"median, {below_now:.1f} mV below")
    print(f"  the rest (the term the flights call for): {rest:.1f} mV (rms) about the median, {rest_centred:.1f} mV "
          f"about the mean miss; from the 5% / 95% quantiles: {side[0]:.1f} mV below, {side[1]:.1f} mV above")
    print(f"  the 90% interval as it is: holds {inside} / {n} ({inside / max(n, 1):.1%}); below {below}, "
          f"above {n - inside - below}")


if __name__ == "__main__":
    main()
