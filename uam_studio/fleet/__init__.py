"""Fleet operations: packs that age with use (:mod:`uam_studio.fleet.aging`, the aging law fitted to the
CMU eVTOL lives)."""

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
