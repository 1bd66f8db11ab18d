"""Flight model: a leg (distance km, altitude m, wind kt) -> pack power (kW) -> per-cell current (A)."""

from uam_studio.flight.context import TAKEOFF_CONTEXT_S
from uam_studio.flight.profile import (
    CLIMB_GROUND_SPEED_MPS,
    PHASES,
    InfeasibleLegError,
    LegProfile,
    leg_charge_c,
    leg_charges_c,
    leg_current,
    leg_feasible,
    leg_profile,
    min_leg_distance_km,
)
from uam_studio.flight.scaling import (
    EQUIVALENT_CELL_COUNT,
    NOMINAL_CELL_VOLTAGE_V,
    power_kw_to_cell_current_a,
)
from uam_studio.flight.tables import (
    ALTITUDE_RANGE_M,
    CRUISE_TABLE_DISTANCE_KM,
    TABLE_PHASES,
    WIND_RANGE_KTS,
    cruise_airspeed_mps,
    cruise_duration_s,
    cruise_ground_speed_mps,
    cruise_power_kw,
    cruise_rows,
    phase_duration_s,
    phase_power_kw,
    phase_rows,
)
from uam_studio.lazy_exports import lazy_getattr

__all__ = [
    "TAKEOFF_CONTEXT_S",
    "ALTITUDE_RANGE_M",
    "CLIMB_GROUND_SPEED_MPS",
    "CRUISE_TABLE_DISTANCE_KM",
    "EQUIVALENT_CELL_COUNT",
    "NOMINAL_CELL_VOLTAGE_V",
    "PHASES",
    "TABLE_PHASES",
    "WIND_RANGE_KTS",
    "InfeasibleLegError",
    "LegProfile",
    "cruise_airspeed_mps",
    "cruise_duration_s",
    "cruise_ground_speed_mps",
    "cruise_power_kw",
    "cruise_rows",
    "leg_current",
    "leg_feasible",
    "leg_charge_c",
    "leg_charges_c",
    "leg_profile",
    "min_leg_distance_km",
    "phase_duration_s",
    "phase_power_kw",
    "phase_rows",
    "power_kw_to_cell_current_a",
]

# the sweeps behind the notebooks' figures: imported when first used
_LAZY = {
    "altitude_profiles": "uam_studio.flight.sweeps",
    "breakeven_distance_km": "uam_studio.flight.sweeps",
    "charge_line": "uam_studio.flight.sweeps",
    "charge_table": "uam_studio.flight.sweeps",
    "wind_profiles": "uam_studio.flight.sweeps",
}
__all__ += sorted(_LAZY)
__getattr__ = lazy_getattr(__name__, _LAZY)
