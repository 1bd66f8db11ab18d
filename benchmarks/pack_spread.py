"""Where the varied world's pack-to-pack spreads come from (``uam_studio.battery.pack_variation``): the NASA 18650
identified on the first three discharges of each 24 C, 2 A life of the shared NASA PCoE set, and the std of each
parameter's logarithm over those fits.

    python benchmarks/pack_spread.py --data ../shared/data/nasa_pcoe    # about a minute

It runs the identification of ``uam-studio identify nasa-cell`` (``nasa_physics.identify_nasa``, which reads B0005)
on B0005, B0007 and B0018 in turn, prints each fit and, per parameter, the std of log over the three and the ratio
of the largest to the smallest: a ratio above 2.5 marks a parameter the fits do not pin down (they sit in different
basins of a flat fit), for which ``pack_variation`` takes its stated assumption instead. The reference potential
``u0p`` is identified together with the open-circuit curve's 13 coefficients, which move with it: its spread is no
pack's difference either, and ``pack_variation`` assumes the curve's shift.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from uam_studio.battery.real import nasa_physics
from uam_studio.battery.real.identify import identify_cell
from uam_studio.battery.real.nasa_data import load_nasa_cell, nasa_folder

LIVES = ("B0005", "B0007", "B0018")  # the 24 C, 2 A lives of the shared set
PINNED_RATIO = 2.5  # largest over smallest fit: above it, the fits disagree by more than packs of one type do
NAMES = ("vol_s_fraction", "t_diffusion_s", "thermal_mass", "r0_activation_k", "kn", "kp", "t_sn_s", "t_sp_s",
         "t_ohmic_s", "thermal_tau_s", "k_activation_k", "u0p")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="a NASA PCoE folder (default: $UAM_STUDIO_NASA_DATA)")
    args = ap.parse_args()
    folder = nasa_folder(args.data)
    fits = {}
    for name in LIVES:
        cell = load_nasa_cell(folder / f"{name}.csv.gz")
        segs = [nasa_physics.fit_segment(cell.discharges[i]) for i in nasa_physics.IDENTIFY_DISCHARGES]
        fit = identify_cell(segs, nasa_physics._start(), 7000.0, 0.1, max_nfev=300)
        fits[name] = {n: float(getattr(fit.cell, n)) for n in NAMES}
        print(f"{name}: q_max {fit.q_max:.0f} C, R0 {fit.r0:.4f} ohm; "
              + ", ".join(f"{n} {v:.4g}" for n, v in fits[name].items()))
    print("| parameter | " + " | ".join(LIVES) + " | std of log | max / min |")
    print("|---|" + "---|" * (len(LIVES) + 2))
    for n in NAMES:
        v = np.array([fits[c][n] for c in LIVES])
        sd = float(np.std(np.log(v), ddof=1))
        loose = v.max() / v.min() > PINNED_RATIO or not math.isfinite(sd)
        note = " moves with the curve's coefficients" if n == "u0p" else " not pinned down" if loose else ""
        print(f"| {n} | " + " | ".join(f"{x:.4g}" for x in v) + f" | {sd:.3f} | {v.max() / v.min():.2f} |" + note)


if __name__ == "__main__":
    main()
