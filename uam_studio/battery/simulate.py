"""Public battery simulation API: current (A) in, voltage (V) and end of discharge (s) out."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uam_studio.battery import kernel
from uam_studio.battery.electrochem import model_constants
from uam_studio.battery.parameters import (
    DEFAULT_CELL,
    DEFAULT_EOD_V,
    DEFAULT_Q_MAX,
    DEFAULT_R0,
    Q_MAX_RANGE,
    Cell,
    CellParameters,
)
from uam_studio.battery.solver import output_voltage
from uam_studio.battery.state import BatteryState, full_charge
from uam_studio.errors import InputError, check_range

R0_RANGE = (0.0, 5.0)  # ohm; the paper trains on 0.017-0.45
EOD_RANGE = (2.5, 4.0)  # V
CURRENT_LIMIT_A = 50.0  # |current| above this is treated as a unit error (A given as mA, kW...)
DT_RANGE = (1e-3, 60.0)  # s


@dataclass(frozen=True)
class SimulationResult:
    """Result of :func:`simulate`. Arrays have the shape of the input profile ([T] or [B, T]).

    time_s: end time of each step (s), shape [T]; sample k is the state after
        ``current_a[k]`` has flowed for ``dt_s``.
    voltage_v: terminal voltage (V). Never NaN: samples after EOD hold the
        first sub-cut-off value (clipped to >= 0) and are flagged by ``valid``.
    valid: False from the first sample below ``eod_v`` onwards.
    eod_s: time of the first sample below ``eod_v`` (s); NaN where the profile
        ends first. Scalar for a [T] input, shape [B] otherwise.
    final_state: state after the last valid sample of each trajectory (to continue
        a mission leg by leg), a :class:`BatteryState` of batch B.
    eod_reached: bool, scalar or [B].
    current_a: the current actually drawn (A), the input in current mode and P/V
        in constant-power mode.
    """

    time_s: np.ndarray
    voltage_v: np.ndarray
    valid: np.ndarray
    eod_s: float | np.ndarray
    final_state: BatteryState
    eod_reached: bool | np.ndarray
    current_a: np.ndarray

    @property
    def min_voltage_v(self) -> float | np.ndarray:
        """Lowest valid voltage (V) of each trajectory (the cut-off sample included)."""
        v = np.where(self.valid, self.voltage_v, np.inf)
        m = v.min(axis=-1)
        first_bad = np.take_along_axis(
            np.atleast_2d(self.voltage_v), np.atleast_1d(_first_invalid(np.atleast_2d(self.valid)))[:, None].clip(
                max=self.voltage_v.shape[-1] - 1), axis=1)[:, 0]
        m2 = np.where(np.atleast_1d(self.eod_reached), np.minimum(np.atleast_1d(m), first_bad), np.atleast_1d(m))
        return float(m2[0]) if self.voltage_v.ndim == 1 else m2


def _first_invalid(valid: np.ndarray) -> np.ndarray:
    """Index of the first False per row (T where none)."""
    t = valid.shape[-1]
    any_bad = ~valid.all(axis=-1)
    return np.where(any_bad, np.argmin(valid, axis=-1), t)


def _as_batch(name: str, value, batch: int | None, lo: float, hi: float, unit: str) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if arr.ndim != 1:
        raise InputError(name, f"expected a scalar or shape [B], got shape {arr.shape}")
    bad = ~np.isfinite(arr) | (arr < lo) | (arr > hi)
    if bad.any():
        check_range(name, arr[bad][0], lo, hi, unit)
    if batch is not None and arr.shape[0] not in (1, batch):
        raise InputError(name, f"has {arr.shape[0]} values but the batch has {batch}")
    return arr


def _check_profile(name: str, profile, limit: float, unit: str) -> np.ndarray:
    try:
        arr = np.asarray(profile, dtype=float)
    except (TypeError, ValueError):
        raise InputError(name, "expected an array of numbers") from None
    if arr.ndim not in (1, 2) or arr.shape[-1] == 0:
        raise InputError(name, f"expected shape [T] or [B, T] with T >= 1, got {arr.shape}")
    if arr.size == 0 or (-limit <= arr.min() and arr.max() <= limit):  # two passes, no temporaries; NaN fails
        return arr
    if not np.all(np.isfinite(arr)):
        raise InputError(name, "contains NaN or inf; every sample must be finite")
    raise InputError(name, f"|{name}| must be <= {limit:g}{unit}, got {np.abs(arr).max():g}")


def check_step(dt_s: float, cell: CellParameters) -> float:
    """``dt_s`` (s) if it is in :data:`DT_RANGE` and below the cell's fastest time constant (explicit Euler
    is unstable beyond it), else :class:`InputError`."""
    dt = check_range("dt_s", dt_s, *DT_RANGE, " s")
    fastest = cell.fastest_time_constant_s
    if dt >= fastest:
        raise InputError("dt_s", f"{dt:g} s must be below the cell's fastest time constant, {fastest:.3g} s")
    return dt


def _prepare(profile: np.ndarray, q_max, r0, initial_state: BatteryState | None, cell: CellParameters):
    batch_hint = profile.shape[0] if profile.ndim == 2 else None
    q = _as_batch("q_max", q_max, batch_hint, *Q_MAX_RANGE, " C")
    r = _as_batch("r0", r0, batch_hint, *R0_RANGE, " ohm")
    sizes = {profile.shape[0] if profile.ndim == 2 else 1, q.shape[0], r.shape[0]}
    if initial_state is not None:
        if not isinstance(initial_state, BatteryState):
            raise InputError("initial_state", "expected a BatteryState (e.g. a result's final_state)")
        sizes.add(initial_state.batch_size)
    sizes.discard(1)
    if len(sizes) > 1:
        raise InputError("batch", f"inconsistent batch sizes {sorted(sizes)} across current, q_max, r0, state")
    b = sizes.pop() if sizes else 1
    prof2 = np.broadcast_to(np.atleast_2d(profile), (b, profile.shape[-1]))
    q = np.broadcast_to(q, (b,)).astype(float)
    r = np.broadcast_to(r, (b,)).astype(float)
    if initial_state is None:
        x0 = full_charge(q, cell).as_array()
    else:
        if initial_state.batch_size not in (1, b):
            raise InputError("initial_state", f"batch {initial_state.batch_size} does not match {b}")
        x0 = initial_state.as_array()
        if not np.isfinite(x0).all():
            raise InputError("initial_state", "contains NaN or inf")
        if x0.shape[0] != b:
            x0 = np.repeat(x0, b, axis=0)
    squeeze = profile.ndim == 1 and b == 1 and np.ndim(q_max) == 0 and np.ndim(r0) == 0
    return prof2, q, r, x0, squeeze


def _finish(time_s, voltage, k_eod, final_state_arr, current, squeeze) -> SimulationResult:
    """The result from the kernel's arrays (which already hold the first sub-cut-off value, finite and
    >= 0, from each row's cut-off sample on); squeeze a single trajectory."""
    t = voltage.shape[1]
    valid = np.arange(t)[None, :] < k_eod[:, None]
    eod_reached = k_eod < t
    eod_s = np.where(eod_reached, time_s[np.minimum(k_eod, t - 1)], np.nan)
    final_state = BatteryState.from_array(final_state_arr)
    if squeeze:
        return SimulationResult(time_s, voltage[0], valid[0], float(eod_s[0]), final_state,
                                bool(eod_reached[0]), current[0])
    return SimulationResult(time_s, voltage, valid, eod_s, final_state, eod_reached, current)


def simulate(
    current_a,
    dt_s: float = 1.0,
    q_max=DEFAULT_Q_MAX,
    r0=DEFAULT_R0,
    eod_v: float = DEFAULT_EOD_V,
    initial_state: BatteryState | None = None,
    cell: CellParameters = DEFAULT_CELL,
) -> SimulationResult:
    """Simulate one 18650 cell under a current profile (discharge positive).

    :param current_a: per-cell current (A), shape [T] or [B, T]; ``current_a[k]``
        flows during [k dt, (k+1) dt).
    :param dt_s: step (s).
    :param q_max: mobile Li charge (C), scalar or [B] (progpy's ``qMobile``).
    :param r0: ohmic resistance (ohm), scalar or [B] (progpy's ``Ro``).
    :param eod_v: end-of-discharge cut-off (V).
    :param initial_state: continue from this state (e.g. ``result.final_state``);
        default: fully charged and rested.
    :return: :class:`SimulationResult`.
    :raises InputError: on bad input, naming the field and its allowed range.
    """
    dt = check_step(dt_s, cell)
    eod = check_range("eod_v", eod_v, *EOD_RANGE, " V")
    profile = _check_profile("current_a", current_a, CURRENT_LIMIT_A, " A")
    current, q, r, x0, squeeze = _prepare(profile, q_max, r0, initial_state, cell)
    current = np.ascontiguousarray(current)
    voltage, k_eod, final = kernel.integrate_to_cutoff(current, x0, cell.q_total(q), r, dt,
                                                       model_constants(cell), eod)
    time_s = dt * np.arange(1, current.shape[1] + 1)
    return _finish(time_s, voltage, k_eod, final, current, squeeze)


def simulate_cell(current_a, cell: Cell, dt_s: float = 1.0,
                  initial_state: BatteryState | None = None) -> SimulationResult:
    """:func:`simulate` of one :class:`~uam_studio.battery.parameters.Cell`: its parameter set, its health
    (q_max C, R0 ohm) and its cut-off (V), under ``current_a`` (A, steps of ``dt_s`` s)."""
    return simulate(current_a, dt_s, cell.q_max, cell.r0, cell.eod_v, initial_state=initial_state, cell=cell.params)


def simulate_constant_power(
    power_w,
    dt_s: float = 1.0,
    q_max=DEFAULT_Q_MAX,
    r0=DEFAULT_R0,
    eod_v: float = DEFAULT_EOD_V,
    initial_state: BatteryState | None = None,
    cell: CellParameters = DEFAULT_CELL,
) -> SimulationResult:
    """Like :func:`simulate`, but the load is a per-cell power (W): current = P / V.

    The current of step k is P[k] divided by the terminal voltage at the start of
    the step, so the cell draws more current as its voltage sags (a realistic
    constant-power load; the paper's setting is the constant-current scaling). The
    result's ``current_a`` is 0 after a trajectory's cut-off sample.
    """
    dt = check_step(dt_s, cell)
    eod = check_range("eod_v", eod_v, *EOD_RANGE, " V")
    profile = _check_profile("power_w", power_w, CURRENT_LIMIT_A * 4.2, " W")
    power, q, r, x0, squeeze = _prepare(profile, q_max, r0, initial_state, cell)
    volts, current, k_eod, final = kernel.integrate_power(power, x0, cell.q_total(q), r, dt,
                                                          model_constants(cell), eod)
    time_s = dt * np.arange(1, power.shape[1] + 1)
    return _finish(time_s, volts, k_eod, final, current, squeeze)


def rest_voltage(q_max=DEFAULT_Q_MAX, cell: CellParameters = DEFAULT_CELL) -> float | np.ndarray:
    """Open-circuit voltage (V) of a fully charged, rested cell."""
    q = np.atleast_1d(np.asarray(q_max, dtype=float))
    x = full_charge(q, cell)
    v = output_voltage(x.__dict__, cell.q_total(q), cell)
    return float(v[0]) if np.ndim(q_max) == 0 else v

