"""Flying a mission in real time: the hidden world, the operator that sees only the forecast and its
sensors, and the flight loop that records both sides.

Public API: :func:`fly_mission` -> :class:`FlightRecord` (its references: :class:`ReferenceFlight`, or later:
:func:`with_references`; the part a weather change leaves as it was: :func:`flight_before`), :class:`World`,
:class:`Operator`, :func:`parse_event` (``"wind+30@1200"``), :class:`WindEvent`, :func:`record_csv` (the record's series
as CSV); the price of safety: :func:`price_of_safety`, :func:`risk_levels`, :func:`format_levels`.
"""

from uam_studio.planning.operations.decision import Decision
from uam_studio.planning.operations.fly import (
    FlightRecord,
    ReferenceFlight,
    breach_cause,
    flight_before,
    fly_mission,
    position_at,
    record_csv,
    with_references,
)
from uam_studio.planning.operations.operator import WEATHER_RESERVE_KT, Operator
from uam_studio.planning.operations.pack_history import simulate_logbook
from uam_studio.planning.operations.safety_price import format_levels, price_of_safety, risk_levels
from uam_studio.planning.operations.world import (
    DEFAULT_FORECAST_SIGMA_KT,
    DEFAULT_SENSOR_NOISE_MA,
    DEFAULT_SENSOR_NOISE_MV,
    Readings,
    WindEvent,
    World,
    parse_event,
)

__all__ = [
    "DEFAULT_FORECAST_SIGMA_KT", "DEFAULT_SENSOR_NOISE_MA", "DEFAULT_SENSOR_NOISE_MV", "Decision",
    "FlightRecord", "Operator", "Readings", "ReferenceFlight", "WEATHER_RESERVE_KT", "WindEvent", "World",
    "flight_before", "fly_mission", "parse_event", "breach_cause", "position_at", "record_csv", "simulate_logbook",
    "format_levels", "price_of_safety", "risk_levels", "with_references",
]
