"""Batched Daigle & Kulkarni (2013) Li-ion electrochemistry model of one 18650 cell.

Public API: :func:`simulate` (current in A), :func:`simulate_constant_power`
(power in W), :class:`SimulationResult`, :class:`BatteryState`, :func:`full_charge`; health from
measured current and voltage (:mod:`uam_studio.battery.fit`): :func:`fit_health` ->
:class:`HealthEstimate` (q_max in C, R0 in ohm, covariance; :mod:`uam_studio.battery.health_estimate`),
:func:`eod_interval_s`, :func:`voltage_band` (:mod:`uam_studio.battery.fit_intervals`).
"""

from .fit import fit_health, fit_health_batch
from .fit_intervals import eod_interval_s, eod_intervals, voltage_band
from .health_estimate import HealthEstimate
from .parameters import (
    DEFAULT_CELL,
    DEFAULT_EOD_V,
    DEFAULT_Q_MAX,
    DEFAULT_R0,
    PAPER_Q_RANGE,
    PAPER_R0_RANGE,
    CellParameters,
)
from .simulate import (
    EOD_RANGE,
    Q_MAX_RANGE,
    R0_RANGE,
    SimulationResult,
    rest_voltage,
    simulate,
    simulate_constant_power,
)
from .state import STATE_NAMES, BatteryState, full_charge

__all__ = [
    "BatteryState", "CellParameters", "DEFAULT_CELL", "DEFAULT_EOD_V", "DEFAULT_Q_MAX", "DEFAULT_R0",
    "EOD_RANGE", "HealthEstimate", "PAPER_Q_RANGE", "PAPER_R0_RANGE", "Q_MAX_RANGE", "R0_RANGE", "STATE_NAMES", "SimulationResult",
    "eod_interval_s", "eod_intervals", "fit_health", "fit_health_batch", "full_charge", "rest_voltage",
    "simulate", "simulate_constant_power", "voltage_band",
]
