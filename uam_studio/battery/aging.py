"""How a cell ages with use: the aging law's form and its fitted numbers (one place for them).

With ``efc`` the equivalent full cycles delivered (discharge throughput over the cell's first capacity) and
``T`` the cell's temperature (C):

- capacity fraction ``c(efc, T) = 1 - a * exp(ea_k * (1/T_ref - 1/T)) * efc ** b`` (of the first capacity;
  ``T_ref`` 25 C);
- resistance ratio ``r(efc) = 1 + k_r * efc`` (of the first resistance).

:data:`AGING_LAW` is fitted to the CMU eVTOL lives (VTC6 cells; ``python -m uam_studio.fleet.aging``),
:data:`NASA_AGING_LAW` to the NASA PCoE lives of the paper's cell (``python -m uam_studio.fleet.nasa_aging``):
both fits read all their lives (in-sample numbers; each life's held-out error is in ``benchmarks/RESULTS.md``,
"Packs that age" and "NASA lives in the fleet's aging law").
The fitting lives in :mod:`uam_studio.fleet`; the health belief (:mod:`uam_studio.battery.health.belief`) ages a
pack's belief by these laws between flights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from uam_studio.battery.parameters import ZERO_C
from uam_studio.errors import check_range

__all__ = ["AGING_LAW", "END_OF_LIFE_FRACTION", "MAX_EFC", "NASA_AGING_LAW", "T_REF_C", "AgingLaw"]

END_OF_LIFE_FRACTION = 0.8  # a pack retires below 80% of its first capacity
T_REF_C = 25.0  # C: the law's reference temperature
MAX_EFC = 1e5  # equivalent full cycles: far past any pack's life


@dataclass(frozen=True)
class AgingLaw:
    """Capacity fade and resistance growth against equivalent full cycles (module docstring).

    ``a`` (fade scale), ``b`` (fade exponent), ``ea_k`` (activation energy over R, K: 0 = no
    temperature effect), ``k_r`` (resistance growth per equivalent full cycle)."""

    a: float
    b: float
    ea_k: float
    k_r: float

    def _scale(self, temperature_c: float) -> float:
        t = check_range("temperature_c", float(temperature_c), -20.0, 60.0, " C")
        return self.a * math.exp(self.ea_k * (1.0 / (T_REF_C + ZERO_C) - 1.0 / (t + ZERO_C)))

    def capacity_fraction(self, efc: float | np.ndarray, temperature_c: float = T_REF_C) -> np.ndarray:
        """Capacity (fraction of the first) after ``efc`` equivalent full cycles at ``temperature_c`` (C),
        never below 0."""
        e = np.clip(np.asarray(efc, dtype=float), 0.0, MAX_EFC)
        return np.clip(1.0 - self._scale(temperature_c) * e ** self.b, 0.0, 1.0)

    def resistance_ratio(self, efc: float | np.ndarray) -> np.ndarray:
        """Resistance (ratio to the first) after ``efc`` equivalent full cycles."""
        return 1.0 + self.k_r * np.clip(np.asarray(efc, dtype=float), 0.0, MAX_EFC)

    def cycles_to(self, fraction: float = END_OF_LIFE_FRACTION, temperature_c: float = T_REF_C) -> float:
        """Equivalent full cycles until the capacity falls to ``fraction`` of the first."""
        f = check_range("fraction", float(fraction), 0.0, 1.0)
        return float(min(MAX_EFC, ((1.0 - f) / self._scale(temperature_c)) ** (1.0 / self.b)))


# Fitted by `python -m uam_studio.fleet.aging` on the four CMU lives (all of them: in-sample numbers;
# the held-out error of each cell is the leave-one-cell-out fit, benchmarks/RESULTS.md, "Packs that age").
AGING_LAW = AgingLaw(a=0.00365567, b=0.646114, ea_k=175.433, k_r=0.00204851)
# Fitted by uam_studio.fleet.nasa_aging.fit_nasa_law on all 25 NASA lives of the paper's cell (in-sample).
NASA_AGING_LAW = AgingLaw(a=0.0213434, b=0.49731, ea_k=-778.876, k_r=0.00145988)
