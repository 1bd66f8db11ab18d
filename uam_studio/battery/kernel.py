"""The compiled battery kernel: explicit-Euler integration of the cell model, batched over trajectories.

Each trajectory is integrated step by step in one compiled pass (numba, ``nopython``): the eight states
stay in registers, the temperature couples into the same step as in progpy's Euler, and no Python runs
per step. The arithmetic is :func:`uam_studio.battery.electrochem.step_at` and
:func:`~uam_studio.battery.electrochem.voltage_at`, the same functions the numpy reference
(:func:`uam_studio.battery.solver.step`, through ``euler_step``) runs on arrays, so the kernel cannot drift
from the equations.

Four entry points, each on a batch [B] of trajectories with their own total charge q_total (C) and R0
(ohm), from states ``x0`` [B, 8] (order of :data:`~uam_studio.battery.state.STATE_NAMES`), steps of
``dt_s`` (s):

* :func:`integrate` - a known current (A) [B, T]: the voltage (V) and every state at steps 1..T;
* :func:`integrate_to_cutoff` - the same, each trajectory stopped at its first sample below the cut-off
  (or NaN): the voltage up to it, its index and the state after the last sample above it;
* :func:`integrate_power` - a known power (W) [B, T], current = P / V at the start of each step, stopped
  likewise;
* :func:`fly_rows` - currents of many lengths from many states of one cell, each stopped likewise: whether
  it held, its end state, its lowest voltage (what a planner's search asks of a leg).

The compiled loops themselves (``run_*``) live in :mod:`~uam_studio.battery.electrochem` beside the
equations, so numba's disk cache (``cache=True``: ``__pycache__`` next to that file, or numba's user cache
where it is read-only), keyed on that one source file, is renewed by any change to the equations. A
process pays the compilation once per install; :func:`warm_up` loads it.
"""

from __future__ import annotations

import numpy as np

from uam_studio.battery.electrochem import ModelConstants, run_current, run_rows, run_to_cutoff

__all__ = ["fly_rows", "integrate", "integrate_power", "integrate_to_cutoff", "warm_up"]


def fly_rows(currents, x0: np.ndarray, q_total: float, r0: float, dt_s: float, k: ModelConstants, eod_v: float,
             split: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fly B current profiles (A) of any lengths from states ``x0`` [B, 8] of one cell (``q_total`` C,
    ``r0`` ohm), each until its end or its first sample below ``eod_v`` (V) or NaN.

    :return: ``(ok [B], x_end [B, 8], v_min [B], x_split [B, 8])``: no sample below the cut-off; the state
        after the last sample (``x0``'s row where not ok); the lowest voltage (V) up to the first sample
        below the cut-off, that sample included (NaN where that sample is NaN, inf for an empty row); the
        state after ``split[b]`` samples where none of them was below the cut-off (``x0``'s row otherwise,
        and where ``split`` is None).
    """
    n_rows = len(currents)
    lengths = np.fromiter((len(c) for c in currents), dtype=np.int64, count=n_rows)
    starts = np.zeros(n_rows, dtype=np.int64)
    np.cumsum(lengths[:-1], out=starts[1:])
    flat = _f64(np.concatenate([np.asarray(c, dtype=float).ravel() for c in currents]) if n_rows else np.zeros(0))
    cut = np.zeros(n_rows, dtype=np.int64) if split is None else np.require(split, np.int64, ("C", "W"))
    ok = np.empty(n_rows, dtype=np.bool_)
    x_end, x_split = np.empty((n_rows, 8)), np.empty((n_rows, 8))
    v_min = np.empty(n_rows)
    run_rows(flat, starts, lengths, _f64(x0), float(q_total), float(r0), float(dt_s), k, float(eod_v), cut, ok, x_end,
             v_min, x_split)
    return ok, x_end, v_min, x_split


def integrate(current: np.ndarray, x0: np.ndarray, q_total: np.ndarray, r0: np.ndarray, dt_s: float,
              k: ModelConstants) -> tuple[np.ndarray, np.ndarray]:
    """Integrate a known current (A) [B, T] from states ``x0`` [B, 8]: (voltage V [B, T], states at
    steps 1..T [8, B, T] in the order of ``STATE_NAMES``). Nothing stops at the cut-off."""
    current = _f64(current)
    n_rows, n_steps = current.shape
    voltage = np.empty((n_rows, n_steps))
    states = np.empty((8, n_rows, n_steps))
    run_current(current, _f64(x0), _f64(q_total), _f64(r0), float(dt_s), k, voltage, states)
    return voltage, states


def _f64(a) -> np.ndarray:
    """``a`` as a C-ordered, writable float64 array (the one array type the kernel is compiled for)."""
    return np.require(a, dtype=np.float64, requirements=("C", "W"))


def _run_to_cutoff(load, power_mode, x0, q_total, r0, dt_s, k, eod_v):
    load = _f64(load)
    n_rows, n_steps = load.shape
    voltage = np.empty((n_rows, n_steps))
    current = np.empty((n_rows, n_steps) if power_mode else (0, 0))  # written in power mode only
    final = np.empty((n_rows, 8))
    k_eod = np.empty(n_rows, dtype=np.int64)
    run_to_cutoff(load, power_mode, _f64(x0), _f64(q_total), _f64(r0), float(dt_s), k, float(eod_v), voltage, current,
                  final, k_eod)
    return voltage, current, k_eod, final


def integrate_to_cutoff(current: np.ndarray, x0: np.ndarray, q_total: np.ndarray, r0: np.ndarray, dt_s: float,
                        k: ModelConstants, eod_v: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integrate a known current (A) [B, T], each trajectory until its first sample below ``eod_v`` (V) or
    NaN: (voltage V [B, T], valid up to and including that sample; its index per row, T where none; the
    state after the last sample at or above the cut-off [B, 8], ``x0``'s row where the first is below)."""
    voltage, _, k_eod, final = _run_to_cutoff(current, False, x0, q_total, r0, dt_s, k, eod_v)
    return voltage, k_eod, final


def integrate_power(power: np.ndarray, x0: np.ndarray, q_total: np.ndarray, r0: np.ndarray, dt_s: float,
                    k: ModelConstants, eod_v: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Integrate a known power (W) [B, T]: the current of step t is P[t] / V with V the terminal voltage at
    the step's start (0 A where V <= 0.5 V), each trajectory stopped as in :func:`integrate_to_cutoff`:
    (voltage V [B, T], current A [B, T] (0 after the cut-off), index of the cut-off sample, final state)."""
    return _run_to_cutoff(power, True, x0, q_total, r0, dt_s, k, eod_v)


def warm_up() -> None:
    """Compile (or load from the disk cache) every entry point on a one-step problem of the default cell."""
    from uam_studio.battery.electrochem import model_constants
    from uam_studio.battery.parameters import DEFAULT_CELL, DEFAULT_Q_MAX, DEFAULT_R0
    from uam_studio.battery.state import full_charge

    k = model_constants(DEFAULT_CELL)
    x0 = full_charge(DEFAULT_Q_MAX).as_array()
    q, r = np.array([DEFAULT_CELL.q_total(DEFAULT_Q_MAX)]), np.array([DEFAULT_R0])
    one = np.ones((1, 1))
    integrate(one, x0, q, r, 1.0, k)
    integrate_to_cutoff(one, x0, q, r, 1.0, k, 3.0)
    integrate_power(one, x0, q, r, 1.0, k, 3.0)
    fly_rows([one[0]], x0, q[0], r[0], 1.0, k, 3.0)
