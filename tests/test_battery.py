"""Behaviour of the batched electrochemistry model (no reference library needed)."""

import numpy as np
import pytest

from uam_studio.battery import (
    BatteryState,
    full_charge,
    rest_voltage,
    simulate,
    simulate_constant_power,
)
from uam_studio.battery.parameters import DEFAULT_CELL, VTC6_PARAMS
from uam_studio.battery.solver import output_voltage, step
from uam_studio.errors import InputError
from uam_studio.flight import leg_current


def _stepwise_voltage(current, q_max, r0, dt=1.0, cell=DEFAULT_CELL):
    """Plain step-by-step numpy Euler loop: the naive reference for the compiled kernel."""
    q = np.atleast_1d(float(q_max))
    x = full_charge(q, cell)
    q_total = cell.q_total(q)
    out = []
    for i in current:
        x = step(x, np.atleast_1d(i), q_total, np.atleast_1d(r0), dt, cell)
        out.append(output_voltage(x.__dict__, q_total, cell)[0])
    return np.array(out)


def flight_profile():
    return np.concatenate([leg_current(40.0, 1000, 13), leg_current(30.0, 500, -26), np.zeros(30)])


@pytest.mark.parametrize("q_max,r0,cell", [(5000, 0.017, DEFAULT_CELL), (8000, 0.3, DEFAULT_CELL),
                                          (6500, 0.25, DEFAULT_CELL), (10900, 0.021, VTC6_PARAMS)])
def test_the_kernel_equals_stepwise_euler(q_max, r0, cell):
    """The kernel against the plain numpy Euler loop; the VTC6 set's R0 and rate constants
    follow the cell's temperature (the Arrhenius terms inside each step)."""
    cur = flight_profile()[:2500]
    res = simulate(cur, q_max=q_max, r0=r0, cell=cell)
    ref = _stepwise_voltage(cur, q_max, r0, cell=cell)
    n = int(res.valid.sum())
    assert n > 100
    assert np.max(np.abs(res.voltage_v[:n] - ref[:n])) < 1e-9


def test_fresh_cell_rest_voltage_and_constant_discharge():
    assert rest_voltage() == pytest.approx(4.19135, abs=1e-4)
    res = simulate(np.full(6000, 2.0))
    # Published progpy figure for this case: EOD at 3572 s (DESIGN.md section 3).
    assert res.eod_s == pytest.approx(3572.0, abs=1.0)
    assert res.eod_reached
    assert not res.valid[-1] and res.valid[0]


def test_batch_equals_individual_runs():
    rng = np.random.default_rng(0)
    cur = rng.uniform(0.5, 3.0, size=(5, 3000))
    q = rng.uniform(5000, 8000, 5)
    r = rng.uniform(0.017, 0.45, 5)
    batch = simulate(cur, q_max=q, r0=r)
    for b in range(5):
        single = simulate(cur[b], q_max=q[b], r0=r[b])
        np.testing.assert_allclose(batch.voltage_v[b], single.voltage_v, atol=1e-12)
        assert np.array_equal(batch.valid[b], single.valid)
        assert (np.isnan(batch.eod_s[b]) and np.isnan(single.eod_s)) or batch.eod_s[b] == single.eod_s


def test_continuation_from_saved_state_is_exact():
    cur = flight_profile()
    whole = simulate(cur, q_max=6000, r0=0.2)
    cut = 1700
    first = simulate(cur[:cut], q_max=6000, r0=0.2)
    second = simulate(cur[cut:], q_max=6000, r0=0.2, initial_state=first.final_state)
    joined = np.concatenate([first.voltage_v, second.voltage_v])
    n = int(whole.valid.sum())
    np.testing.assert_allclose(joined[:n], whole.voltage_v[:n], atol=1e-9)


def test_recharge_resets_to_full():
    res = simulate(np.full(500, 2.5))
    again = simulate(np.zeros(1), initial_state=full_charge(7600.0))
    assert res.voltage_v[-1] < 4.0
    assert again.voltage_v[0] == pytest.approx(rest_voltage(), abs=1e-9)


def test_no_nan_or_inf_after_eod_and_mask_is_monotone():
    cur = np.full((3, 20000), 3.0)
    res = simulate(cur, q_max=[5000, 6500, 8000], r0=[0.45, 0.2, 0.017])
    assert np.all(np.isfinite(res.voltage_v))
    assert np.all(res.eod_reached)
    # once invalid, always invalid
    assert np.all(np.diff(res.valid.astype(int), axis=1) <= 0)
    assert np.all(res.voltage_v[res.valid] >= 3.0)
    assert np.all(np.isfinite(res.final_state.as_array()))


def test_eod_nan_when_profile_ends_first():
    res = simulate(np.full(100, 1.0))
    assert np.isnan(res.eod_s) and not res.eod_reached and res.valid.all()


def test_degradation_shortens_discharge():
    cur = np.full(8000, 1.5)
    eods = simulate(np.broadcast_to(cur, (4, 8000)), q_max=[8000, 6000, 8000, 8000],
                    r0=[0.117, 0.117, 0.25, 0.45]).eod_s
    assert eods[1] < eods[0]  # less lithium -> earlier EOD
    assert eods[0] > eods[2] > eods[3]  # more resistance -> earlier EOD


def test_constant_power_draws_more_current_as_voltage_sags():
    res = simulate_constant_power(np.full(4000, 6.0))
    i = res.current_a[res.valid]
    assert i[0] == pytest.approx(6.0 / rest_voltage(), rel=1e-9)
    assert i[-1] > i[0] * 1.2
    # Equivalent current profile gives the same voltages.
    same = simulate(res.current_a)
    n = int(res.valid.sum())
    np.testing.assert_allclose(same.voltage_v[:n], res.voltage_v[:n], atol=1e-9)


@pytest.mark.parametrize(
    "kwargs,field",
    [
        ({"current_a": [1.0, float("nan")]}, "current_a"),
        ({"current_a": []}, "current_a"),
        ({"current_a": [1.0], "q_max": 0.0}, "q_max"),
        ({"current_a": [1.0], "q_max": -5.0}, "q_max"),
        ({"current_a": [1.0], "r0": -0.1}, "r0"),
        ({"current_a": [1.0], "dt_s": 0.0}, "dt_s"),
        ({"current_a": [1.0], "eod_v": 9.0}, "eod_v"),
        ({"current_a": [[1.0], [1.0]], "q_max": [7000, 7000, 7000]}, "q_max"),
        ({"current_a": [1.0], "initial_state": "full"}, "initial_state"),
    ],
)
def test_bad_input_names_field(kwargs, field):
    with pytest.raises(InputError) as err:
        simulate(**kwargs)
    msg = str(err.value)
    assert msg.startswith(field) and "\n" not in msg


def test_state_round_trip():
    s = full_charge([5000.0, 7000.0])
    assert isinstance(s[1], BatteryState) and s[1].batch_size == 1
    np.testing.assert_array_equal(BatteryState.from_array(s.as_array()).qns, s.qns)


def test_temperature_factors_follow_arrhenius_with_the_right_signs():
    """R0 falls and the rate constants rise as the cell warms (VTC6 set); the published NASA set has none."""
    assert DEFAULT_CELL.r0_factor(330.0) == 1.0 and DEFAULT_CELL.rate_factor(330.0) == 1.0
    assert not DEFAULT_CELL.temperature_dependent and VTC6_PARAMS.temperature_dependent
    p = VTC6_PARAMS
    t_ref = p.t_reference_k
    assert p.r0_factor(t_ref) == pytest.approx(1.0) and p.rate_factor(t_ref) == pytest.approx(1.0)
    for t in (t_ref - 15.0, t_ref + 10.0, t_ref + 30.0):
        x = 1.0 / t - 1.0 / t_ref  # < 0 above the reference temperature
        assert np.log(p.r0_factor(t)) == pytest.approx(p.r0_activation_k * x, rel=1e-12)
        assert np.log(p.rate_factor(t)) == pytest.approx(-p.k_activation_k * x, rel=1e-12)
    warm = t_ref + 20.0
    assert p.r0_factor(warm) < 1.0 < p.rate_factor(warm)
    assert p.r0_factor(t_ref - 20.0) > 1.0 > p.rate_factor(t_ref - 20.0)


def test_constant_power_starts_from_the_given_state_and_draws_more_current_as_the_voltage_sags():
    power = np.full(600, 8.0)  # W per cell
    fresh = simulate_constant_power(power, q_max=7000.0, r0=0.1)
    used = simulate(np.full(1500, 2.0), q_max=7000.0, r0=0.1).final_state
    later = simulate_constant_power(power, q_max=7000.0, r0=0.1, initial_state=used)
    assert later.voltage_v[0] < fresh.voltage_v[0] - 0.05  # it started from the used cell
    assert later.current_a[0] > fresh.current_a[0]
    np.testing.assert_allclose(fresh.current_a[1:] * fresh.voltage_v[:-1], 8.0, rtol=0.02)  # I = P / V
    assert np.all(np.diff(fresh.current_a[5:]) >= -1e-9)  # the voltage falls, the current rises
