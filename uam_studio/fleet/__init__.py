"""Fleet operations: packs that age with use (:mod:`uam_studio.fleet.aging`, the aging law fitted to the
CMU eVTOL lives), a day's demand (:mod:`~uam_studio.fleet.demand`), what dispatchers know and how they
decide (:mod:`~uam_studio.fleet.dispatch`), the day and the life as a SimPy simulation in a hidden world
(:mod:`~uam_studio.fleet.day`) and many lives at once on Dask (:mod:`~uam_studio.fleet.study`)."""

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

__all__ = ["AGING_LAW", "END_OF_LIFE_FRACTION", "AgingLaw", "LifePoints", "PackHealth", "fit_aging_law",
           "leave_one_cell_out", "life_points"]
