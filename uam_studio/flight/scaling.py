"""Pack-to-cell scaling: the one constant that turns pack power (kW) into per-cell current (A).

The paper's pack is 10S50P 18650 cells, but read literally its 265 kW take-off power
would be 530 W per cell, which no 18650 can deliver. We therefore treat the pack as
``EQUIVALENT_CELL_COUNT`` = 25,000 equivalent cells at 3.7 V nominal, so that

* the peak pack power, 273.53 kW (climb at 500 m), maps to 2.96 A per cell, inside
  the 0.05-3 A current range the published Dynaformer was trained on, and
* a fresh cell (q_max = 7600 C) flies roughly 2-3 legs of 30 nm at 1000 m
  (about 2350-4050 C per leg depending on wind).

Every module converts pack power with :func:`power_kw_to_cell_current_a`; do not
re-derive the scale elsewhere.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

EQUIVALENT_CELL_COUNT = 25_000
NOMINAL_CELL_VOLTAGE_V = 3.7


def power_kw_to_cell_current_a(power_kw: ArrayLike) -> np.ndarray | float:
    """Per-cell current (A) for a pack power (kW): ``P * 1000 / (N * 3.7 V)``.

    Scalars give a float, arrays an array of the same shape.
    """
    current = (
        np.asarray(power_kw, dtype=float)
        * 1000.0
        / (EQUIVALENT_CELL_COUNT * NOMINAL_CELL_VOLTAGE_V)
    )
    return float(current) if current.ndim == 0 else current
