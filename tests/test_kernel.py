"""The compiled battery kernel against the numpy references it replaced.

The equations are shared (``uam_studio.battery.electrochem``), so these tests hold the kernel's loops:
which samples it integrates, where it stops, which state it returns, the constant-power current. The
references are the plain numpy Euler loop (``solver.step``) and the time-vectorised numpy solver
(``solver.integrate_current_vectorised``), drawn over the whole documented input range.
"""

import json
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.battery import full_charge, simulate, simulate_constant_power
from uam_studio.battery.eod import first_below
from uam_studio.battery.parameters import (
    DEFAULT_CELL,
    NASA_IDENTIFIED_PARAMS,
    Q_MAX_RANGE,
    VTC6_PARAMS,
    Cell,
)
from uam_studio.battery.simulate import R0_RANGE
from uam_studio.battery.solver import integrate_current, integrate_current_vectorised, output_voltage, step
from uam_studio.planning.episode import fly_batch

CELLS = {"progpy": DEFAULT_CELL, "nasa_identified": NASA_IDENTIFIED_PARAMS, "vtc6": VTC6_PARAMS}


def _numpy_euler(load, q_max, r0, cell, x0=None, power=False, eod_v=3.0):
    """The plain numpy Euler loop over one trajectory: (voltage [T], current [T], state after each step [T, 8])."""
    q = np.atleast_1d(float(q_max))
    q_total = cell.q_total(q)
    x = full_charge(q, cell) if x0 is None else x0
    v = output_voltage(x.__dict__, q_total, cell)[0]
    volts, amps, states = [], [], []
    for p in load:
        i = (p / max(v, 0.5) if v > 0.5 else 0.0) if power else p
        x = step(x, np.atleast_1d(i), q_total, np.atleast_1d(r0), 1.0, cell)
        v = output_voltage(x.__dict__, q_total, cell)[0]
        volts.append(v)
        amps.append(i)
        states.append(x.as_array()[0])
        if not v >= eod_v:
            break
    return np.array(volts), np.array(amps), np.array(states)


def _profile(q_max, drain, wobble, n, seed):
    """``n`` samples (A) that draw ``drain`` times the cell's q_max (C) on average (a random walk of relative
    size ``wobble`` about it), within the kernel's current limit: most profiles reach the cut-off."""
    rng = np.random.default_rng(seed)
    base = drain * q_max / n
    walk = 1.0 + wobble * rng.standard_normal(n).cumsum() / np.sqrt(n)
    return np.clip(base * walk, -5.0, 20.0)


@settings(max_examples=40, deadline=None)
@given(cell=st.sampled_from(sorted(CELLS)), q_max=st.floats(500.0, Q_MAX_RANGE[1]), drain=st.floats(-0.2, 3.0),
       wobble=st.floats(0.0, 1.0), n=st.integers(1, 1500), seed=st.integers(0, 2**31 - 1),
       r0=st.one_of(st.floats(0.0, 0.3), st.floats(*R0_RANGE)), eod_v=st.floats(2.5, 3.9))
def test_simulate_equals_the_numpy_euler_loop(cell, q_max, drain, wobble, n, seed, r0, eod_v):
    """Every valid sample within 1e-9 V, the same cut-off sample, the same final state (R0 is drawn from
    its whole range and, half the time, from the aircraft's, where the voltage reaches the cut-off slowly
    enough for an off-by-one stop to show)."""
    params = CELLS[cell]
    cur = _profile(q_max, drain, wobble, n, seed)
    res = simulate(cur, q_max=q_max, r0=r0, eod_v=eod_v, cell=params)
    ref_v, _, ref_x = _numpy_euler(cur, q_max, r0, params, eod_v=eod_v)
    k = int(first_below(ref_v, eod_v))
    n = len(ref_v) if k < 0 else k
    assert int(res.valid.sum()) == n
    assert bool(res.eod_reached) == (k >= 0)
    np.testing.assert_allclose(res.voltage_v[:n], ref_v[:n], rtol=0, atol=1e-9)
    if n:
        np.testing.assert_allclose(res.final_state.as_array()[0], ref_x[n - 1], rtol=1e-12, atol=1e-9)
    assert np.all(np.isfinite(res.voltage_v)) and np.all(res.voltage_v >= 0.0)


@pytest.mark.parametrize("cell", sorted(CELLS))
def test_the_cut_off_sample_and_final_state_on_a_grid_of_discharges(cell):
    """Constant discharges over the aircraft's healths (the progpy agreement grid's q_max, R0 and currents,
    whose voltage nears the cut-off slowly): the same cut-off sample as the batched numpy loop, the same
    voltage and state up to it."""
    params = CELLS[cell]
    grid = np.array([(q, r, a) for q in (5000.0, 6500.0, 8000.0) for r in (0.017, 0.117, 0.3) for a in (1.0, 2.0, 3.0)])
    q, r, amps = grid.T
    if params is VTC6_PARAMS:
        q = q * 1.4  # the VTC6 fleet's capacities
    horizon, early = 12000, 300
    res = simulate(np.repeat(amps[:, None], horizon, axis=1), q_max=q, r0=r, cell=params)
    q_total = params.q_total(q)
    x = full_charge(q, params)
    volts = np.empty((len(q), horizon))
    for t in range(horizon):
        x = step(x, amps, q_total, r, 1.0, params)
        volts[:, t] = output_voltage(x.__dict__, q_total, params)
        if t == early:
            half = x.as_array()
    k_ref = first_below(volts, 3.0)
    assert np.all(k_ref > early)  # every row ends by its own cut-off, after the early state
    np.testing.assert_array_equal(np.argmin(res.valid, axis=1), k_ref)
    for b in range(len(q)):
        np.testing.assert_allclose(res.voltage_v[b, : k_ref[b]], volts[b, : k_ref[b]], rtol=0, atol=1e-9)
    mid = simulate(np.repeat(amps[:, None], early + 1, axis=1), q_max=q, r0=r, cell=params)
    np.testing.assert_allclose(mid.final_state.as_array(), half, rtol=1e-12, atol=1e-9)


@settings(max_examples=20, deadline=None)
@given(base=st.floats(0.0, 20.0), n=st.integers(1, 1200), cell=st.sampled_from(sorted(CELLS)),
       q_max=st.floats(2000.0, 12000.0), r0=st.floats(0.0, 0.5))
def test_constant_power_equals_the_numpy_loop(base, n, cell, q_max, r0):
    """Current P / V from the voltage before each step: the same voltages and currents up to the cut-off,
    no current after it."""
    params = CELLS[cell]
    power = np.full(n, base) * np.linspace(1.0, 0.5, n)
    res = simulate_constant_power(power, q_max=q_max, r0=r0, cell=params)
    ref_v, ref_i, _ = _numpy_euler(power, q_max, r0, params, power=True)
    m = len(ref_v)
    np.testing.assert_allclose(res.voltage_v[:m][res.valid[:m]], ref_v[res.valid[:m]], rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.current_a[:m], ref_i, rtol=1e-12, atol=1e-12)
    assert np.all(res.current_a[m:] == 0.0)


@pytest.mark.parametrize("cell", sorted(CELLS))
def test_integrate_current_equals_the_time_vectorised_solver(cell):
    """The kernel against the numpy solver it replaced, on a batch of varied currents and healths (the
    vectorised solver's temperature iteration stops within 1e-5 K, which moves a temperature-dependent
    cell's voltage by up to ~1e-7 V; the published cell has no such term)."""
    params = CELLS[cell]
    rng = np.random.default_rng(3)
    cur = rng.uniform(0.3, 4.0, (12, 1800))
    q, r = rng.uniform(5000, 9000, 12), rng.uniform(0.017, 0.3, 12)
    x0 = full_charge(q, params)
    v, seq = integrate_current(cur, x0, params.q_total(q), r, 1.0, params)
    v_ref, seq_ref = integrate_current_vectorised(cur, x0, params.q_total(q), r, 1.0, params)
    alive = np.cumprod(v_ref >= 3.0, axis=1).astype(bool)  # before the cut-off (past it the states run away)
    tol = 1e-9 if not params.temperature_dependent else 2e-7
    assert alive.sum() > 1000
    np.testing.assert_allclose(v[alive], v_ref[alive], rtol=0, atol=tol)
    for name in seq:
        np.testing.assert_allclose(seq[name][alive], seq_ref[name][alive], rtol=1e-9, atol=1e-6)


def test_fly_batch_equals_the_numpy_loop_row_by_row():
    """Ragged rows from their own states, some to the cut-off: the verdict, the lowest voltage (the cut-off
    sample included), the end state and the state after the split, each as the numpy loop gives it."""
    cell = Cell("test", NASA_IDENTIFIED_PARAMS, 6200.0, 0.03, 3.3)
    rng = np.random.default_rng(11)
    rows = [rng.uniform(0.5, a, n) for a, n in ((1.0, 50), (4.0, 3000), (2.0, 900), (6.0, 2500), (0.5, 1))]
    starts = [full_charge(np.atleast_1d(cell.q_max), cell.params)]
    warm = simulate(np.full(400, 2.0), q_max=cell.q_max, r0=cell.r0, cell=cell.params).final_state
    x0 = np.concatenate([(starts[0] if k % 2 else warm).as_array() for k in range(len(rows))])
    split = np.array([max(1, len(c) // 2) for c in rows])
    ok, x_end, v_min, x_split = fly_batch(rows, x0, cell, split=split)
    assert 0 < ok.sum() < len(rows)
    for k, c in enumerate(rows):
        start = starts[0] if k % 2 else warm
        ref_v, _, ref_x = _numpy_euler(c, cell.q_max, cell.r0, cell.params, x0=start, eod_v=cell.eod_v)
        failed = not ref_v[-1] >= cell.eod_v
        assert ok[k] == (not failed)
        assert v_min[k] == pytest.approx(ref_v.min(), abs=1e-9)
        np.testing.assert_allclose(x_end[k], x0[k] if failed else ref_x[-1], rtol=1e-12, atol=1e-9)
        held_to_split = len(ref_v) > split[k] or (len(ref_v) == split[k] and not failed)
        np.testing.assert_allclose(x_split[k], ref_x[split[k] - 1] if held_to_split else x0[k], rtol=1e-12,
                                   atol=1e-9)


def test_the_kernel_accepts_every_documented_health_without_nan():
    """The corners of the documented ranges (q_max, R0) and a current that empties the cell: no NaN out."""
    cur = np.full(4000, 8.0)
    for q in Q_MAX_RANGE:
        for r in R0_RANGE:
            res = simulate(cur, q_max=q, r0=r)
            assert np.all(np.isfinite(res.voltage_v)), (q, r)
            assert np.all(np.isfinite(res.final_state.as_array())), (q, r)


def test_a_new_process_loads_the_compiled_kernel_from_the_disk_cache():
    """Compilation is paid once: a second fresh process compiles nothing (numba's cache hits)."""
    code = ("import json; from uam_studio.battery import kernel, electrochem as e; kernel.warm_up(); "
            "print(json.dumps([[sum(f.stats.cache_hits.values()), sum(f.stats.cache_misses.values())] "
            "for f in (e.run_current, e.run_to_cutoff, e.run_rows)]))")
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    counts = json.loads(out.stdout.strip().splitlines()[-1])
    assert all(miss == 0 and hit >= 1 for hit, miss in counts), counts
