"""Fleet operations: packs that age with use (:mod:`uam_studio.fleet.aging`, the law's form and its fit to the
CMU eVTOL lives; :mod:`~uam_studio.fleet.nasa_aging`, its fit to the NASA PCoE lives, the fleet's default),
a day's demand (:mod:`~uam_studio.fleet.demand`), what dispatchers know and how they decide
(:mod:`~uam_studio.fleet.dispatch`), the day and the life as a SimPy simulation in a hidden world
(:mod:`~uam_studio.fleet.day`) and many lives at once on Dask (:mod:`~uam_studio.fleet.study`).

The aging names are imported here; the day, the demand and the studies when first used (they import SimPy
and the planner).
"""

from uam_studio.fleet.aging import (
    AGING_LAW,
    END_OF_LIFE_FRACTION,
    AgingLaw,
    LifePoints,
    PackHealth,
    fit_aging_law,
    leave_one_cell_out,
    life_points,
)
from uam_studio.lazy_exports import lazy_getattr

_LAZY = {
    "NASA_AGING_LAW": "uam_studio.fleet.nasa_aging",
    "CapacityBelief": "uam_studio.fleet.nasa_aging",
    "Fleet": "uam_studio.fleet.day",
    "DayResult": "uam_studio.fleet.day",
    "PACK_LAWS": "uam_studio.fleet.day",
    "simulate_day": "uam_studio.fleet.day",
    "simulate_life": "uam_studio.fleet.day",
    "fly_day_of_life": "uam_studio.fleet.day",
    "poisson_demand": "uam_studio.fleet.demand",
    "load_demand": "uam_studio.fleet.demand",
    "DISPATCHERS": "uam_studio.fleet.dispatch",
    "fleet_study": "uam_studio.fleet.study",
    "summarize": "uam_studio.fleet.study",
}

__all__ = ["AGING_LAW", "CapacityBelief", "DISPATCHERS", "DayResult", "END_OF_LIFE_FRACTION", "AgingLaw", "Fleet",
           "LifePoints", "NASA_AGING_LAW", "PACK_LAWS", "PackHealth", "fit_aging_law", "fleet_study",
           "fly_day_of_life", "leave_one_cell_out", "life_points", "load_demand", "poisson_demand", "simulate_day",
           "simulate_life", "summarize"]


__getattr__ = lazy_getattr(__name__, _LAZY)
