"""Batched Daigle & Kulkarni (2013) Li-ion electrochemistry model of one 18650 cell.

Public API: :func:`simulate` (current in A), :func:`simulate_constant_power`
(power in W), :class:`SimulationResult`, :class:`BatteryState`, :func:`full_charge`; health from
measured current and voltage (:mod:`uam_studio.battery.health`): :func:`fit_health` ->
:class:`HealthEstimate` (q_max in C, R0 in ohm, covariance; :mod:`uam_studio.battery.health.estimate`),
:func:`eod_interval_s`, :func:`voltage_band` (:mod:`uam_studio.battery.health.intervals`).
"""

from uam_studio.battery.health.estimate import HealthEstimate
from uam_studio.battery.health.fit import fit_health, fit_health_batch
from uam_studio.battery.health.intervals import eod_interval_s, eod_intervals, voltage_band
from uam_studio.battery.parameters import (
    DEFAULT_CELL,
    DEFAULT_EOD_V,
    DEFAULT_Q_MAX,
    DEFAULT_R0,
    PAPER_Q_RANGE,
    PAPER_R0_RANGE,
    CellParameters,
)
from uam_studio.battery.simulate import (
    EOD_RANGE,
    Q_MAX_RANGE,
    R0_RANGE,
    SimulationResult,
    rest_voltage,
    simulate,
    simulate_constant_power,
)
from uam_studio.battery.state import STATE_NAMES, BatteryState, full_charge
from uam_studio.lazy_exports import lazy_getattr

__all__ = [
    "BatteryState", "CellParameters", "DEFAULT_CELL", "DEFAULT_EOD_V", "DEFAULT_Q_MAX", "DEFAULT_R0",
    "EOD_RANGE", "HealthEstimate", "PAPER_Q_RANGE", "PAPER_R0_RANGE", "Q_MAX_RANGE", "R0_RANGE", "STATE_NAMES",
    "SimulationResult", "eod_interval_s", "eod_intervals", "fit_health", "fit_health_batch", "full_charge",
    "rest_voltage", "simulate", "simulate_constant_power", "voltage_band",
]

# sweeps over the model, real cells (CMU VTC6 and NASA PCoE): imported when first used
_LAZY = {
    "curves": "uam_studio.battery.sweeps",
    "eod_grid": "uam_studio.battery.sweeps",
    "simulate_profiles": "uam_studio.battery.sweeps",
    "max_leg_distance_km": "uam_studio.battery.sweeps",
    "data_folder": "uam_studio.battery.real.cmu_data",
    "load_cell_log": "uam_studio.battery.real.cmu_data",
    "mission_cycle": "uam_studio.battery.real.cmu_data",
    "NASA_18650": "uam_studio.battery.parameters",
    "VTC6": "uam_studio.battery.parameters",
    "VTC6_CELL_HELD_OUT": "uam_studio.battery.parameters",
    "replay_mission": "uam_studio.battery.real.cmu_replay",
    "NasaDataError": "uam_studio.battery.real.nasa_data",
    "load_nasa_folder": "uam_studio.battery.real.nasa_data",
    "nasa_folder": "uam_studio.battery.real.nasa_data",
    "available_cells": "uam_studio.battery.real.nasa_data",
    "sample_note": "uam_studio.battery.real.places",
    "score_cell": "uam_studio.battery.real.nasa_eval",
    "summarise": "uam_studio.battery.real.nasa_eval",
    "model_for": "uam_studio.battery.real.nasa_replay",
    "replay_discharge": "uam_studio.battery.real.nasa_replay",
}
__all__ += sorted(_LAZY)
__getattr__ = lazy_getattr(__name__, _LAZY)
