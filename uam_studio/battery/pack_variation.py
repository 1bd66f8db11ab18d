"""How one pack differs from its cell type's model in what a health belief does not estimate.

A health belief estimates two numbers of a pack, q_max (C) and R0 (ohm); the model it fits them on holds every
other parameter at its cell type's value. A real pack is not its model: its diffusion, surface/bulk split, rate
constants, overpotential and ohmic time constants, open-circuit curve and heat all differ a little from the next
pack's. :func:`pack_params` draws one pack's parameter set around its type's: each parameter of
:data:`PACK_SPREAD` times ``exp(sd * z)``, and the positive electrode's reference potential (the open-circuit
curve) plus ``OCV_SHIFT_SD_V * z``, each z standard normal clipped to +-:data:`SPREAD_CLIP`, seeded by the pack's
number: the same pack, the same parameters, flight after flight.

Where each spread comes from. The NASA 18650 was identified on the first three discharges of each of the three
24 C, 2 A lives of the shared NASA PCoE set (B0005, B0007, B0018; ``python benchmarks/pack_spread.py --data
PATH``, the same identification as ``uam-studio identify nasa-cell``). The std of the logarithm over the three
fits is taken where the three fits agree within a factor of 2.5 (the surface share of the volume 0.24, the diffusion
time 0.37 (its largest over its smallest 2.1), the thermal mass 0.085, R0's activation 0.14). Where they do not (the
rate constants, the overpotential and ohmic time constants, the cooling time (2.7), the rate constants'
activation), the three sit in different basins of a flat fit, by factors of 2.7 to 1000 that no pair of packs of one
type differs by; there the spread is an assumption, :data:`WEAK_SPREAD` (0.25). The open-circuit curve is identified
with its 13 coefficients, which move with its reference potential (2.76-4.11 V over the three): no pack differs by
that; its shift, 5 mV, is an assumption too.
Three lives make a crude spread: it is a stated world, not a measured distribution of packs.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from uam_studio.battery.parameters import CellParameters
from uam_studio.errors import check_seed

__all__ = ["OCV_SHIFT_SD_V", "PACK_SPREAD", "SPREAD_CLIP", "WEAK_SPREAD", "pack_params"]

WEAK_SPREAD = 0.25  # std of log: a parameter the three identified lives do not pin down (an assumption)
PACK_SPREAD: dict[str, float] = {  # std of the logarithm of each parameter from pack to pack
    "vol_s_fraction": 0.24,  # identified: B0005 / B0007 / B0018 0.064 / 0.089 / 0.056
    "t_diffusion_s": 0.37,  # identified: 7.0e6 / 9.3e6 / 4.5e6 s
    "thermal_mass": 0.085,  # identified: 33.8 / 32.0 / 28.6 J/K
    "r0_activation_k": 0.14,  # identified: 3056 / 2512 / 3303 K (0 in progpy's set: no effect there)
    "kn": WEAK_SPREAD,
    "kp": WEAK_SPREAD,
    "t_sn_s": WEAK_SPREAD,
    "t_sp_s": WEAK_SPREAD,
    "t_ohmic_s": WEAK_SPREAD,
    "thermal_tau_s": WEAK_SPREAD,
    "k_activation_k": WEAK_SPREAD,
}
OCV_SHIFT_SD_V = 0.005  # V: std of the shift of the open-circuit curve (u0p), an assumption
SPREAD_CLIP = 2.0  # std: no parameter is drawn further out


def pack_params(params: CellParameters, pack: int) -> CellParameters:
    """Pack number ``pack``'s parameter set around its type's ``params`` (module docstring). The health
    parameters (q_max, R0) are not in it: they are the pack's own, set elsewhere.

    :raises InputError: (field ``pack``) for a pack number that is not an integer 0 to 2^63 - 1.
    """
    pack = check_seed("pack", pack)
    rng = np.random.default_rng([pack, 0x9ACC])
    z = np.clip(rng.standard_normal(len(PACK_SPREAD) + 1), -SPREAD_CLIP, SPREAD_CLIP)
    changes: dict[str, Any] = {name: float(getattr(params, name)) * float(np.exp(sd * zk))
                               for (name, sd), zk in zip(PACK_SPREAD.items(), z)}
    return replace(params, **changes, u0p=float(params.u0p + OCV_SHIFT_SD_V * z[-1]))
