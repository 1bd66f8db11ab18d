"""Batched Daigle & Kulkarni (2013) Li-ion electrochemistry model of one 18650 cell.

Public API: :func:`simulate` (current in A), :func:`simulate_constant_power`
(power in W), :class:`SimulationResult`, :class:`BatteryState`, :func:`full_charge`.
"""

from .parameters import DEFAULT_CELL, DEFAULT_EOD_V, DEFAULT_Q_MAX, DEFAULT_R0, CellParameters
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
    "EOD_RANGE", "Q_MAX_RANGE", "R0_RANGE", "STATE_NAMES", "SimulationResult", "full_charge",
    "rest_voltage", "simulate", "simulate_constant_power",
]
