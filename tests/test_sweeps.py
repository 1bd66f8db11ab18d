"""Sweep helpers of the flight and battery layers (used by the classroom notebooks)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uam_studio.battery import simulate
from uam_studio.battery.sweeps import curves, eod_grid, max_leg_distance_km, simulate_profiles
from uam_studio.errors import InputError
from uam_studio.flight import leg_feasible, leg_profile
from uam_studio.flight.sweeps import (
    altitude_profiles,
    breakeven_distance_km,
    charge_line,
    charge_table,
    wind_profiles,
)


def test_curves_cut_after_first_sample_below_cutoff():
    res = simulate(np.full(9000, 2.0), 1.0, q_max=[5000.0, 8000.0], r0=0.117)
    out = curves(res, [5000.0, 8000.0], 0.117)
    for k, c in enumerate(out):
        assert c.eod_s == pytest.approx(float(res.eod_s[k]))
        assert c.voltage_v[-1] < 3.0 and np.all(c.voltage_v[:-1] >= 3.0)
        assert c.time_s.size == c.voltage_v.size == c.current_a.size
    assert out[0].q_max == 5000.0 and out[1].r0 == 0.117
    assert out[0].eod_s < out[1].eod_s


def test_curves_without_eod_keep_the_whole_profile():
    (c,) = curves(simulate(np.full(100, 1.0), 1.0))
    assert c.eod_s is None and c.voltage_v.size == 100


def test_simulate_profiles_matches_one_by_one():
    a = leg_profile(30.0, 500.0, 0.0).current_a
    b = np.concatenate([leg_profile(60.0, 1000.0, 39.0).current_a] * 3)
    got = simulate_profiles([a, b], q_max=[7000.0, 6000.0], r0=[0.1, 0.2])
    for cur, q, r, c in zip((a, b), (7000.0, 6000.0), (0.1, 0.2), got):
        ref = simulate(cur, 1.0, q, r)
        n = c.voltage_v.size
        np.testing.assert_allclose(c.voltage_v, ref.voltage_v[:n], atol=1e-9)
        assert (c.eod_s is None) == (not ref.eod_reached)
    assert got[0].eod_s is None and got[0].voltage_v.size == a.size
    assert got[1].eod_s is not None


def test_simulate_profiles_rejects_empty():
    with pytest.raises(InputError):
        simulate_profiles([])
    with pytest.raises(InputError):
        simulate_profiles([np.zeros(0)])


def test_eod_grid_shape_and_values():
    cur = np.full(8000, 2.0)
    q, r = [5000.0, 8000.0], [0.017, 0.2, 0.45]
    grid = eod_grid(cur, q, r)
    assert grid.shape == (3, 2)
    for i, rr in enumerate(r):
        for j, qq in enumerate(q):
            assert grid[i, j] == pytest.approx(float(simulate(cur, 1.0, qq, rr).eod_s))
    assert np.isnan(eod_grid(np.full(50, 1.0), q, r)).all()
    with pytest.raises(InputError):
        eod_grid(np.ones((2, 5)), q, r)


def test_max_leg_distance_is_the_safe_unsafe_boundary():
    d = max_leg_distance_km(500.0, 39.0, tol_km=0.5)
    assert 50.0 < d < 200.0
    assert not simulate(leg_profile(d, 500.0, 39.0).current_a, 1.0).eod_reached
    assert simulate(leg_profile(d + 1.0, 500.0, 39.0).current_a, 1.0).eod_reached
    assert max_leg_distance_km(3000.0, 0.0) < max_leg_distance_km(500.0, 0.0)
    assert max_leg_distance_km(500.0, 0.0, r0=0.45) == 0.0  # cannot even finish the climb


def test_altitude_and_wind_profiles():
    by_alt = altitude_profiles(15.0)
    assert set(by_alt) == {500.0, 1000.0}  # 15 km is too short for 2000 m and 3000 m
    by_wind = wind_profiles(55.56, 1000.0, [-39.0, 39.0])
    assert by_wind[39.0].duration_s > by_wind[-39.0].duration_s


@pytest.mark.parametrize("h,w,d", [(500.0, 0.0, 30.0), (1000.0, 13.0, 60.0), (3000.0, -39.0, 80.5),
                                   (2000.0, 26.0, 17.0)])
def test_charge_line_is_exact(h, w, d):
    fixed, per_km = charge_line(h, w)
    assert fixed + per_km * d == pytest.approx(leg_profile(d, h, w).charge_c, rel=1e-9)


def test_charge_table_nan_where_infeasible():
    t = charge_table([10.0, 30.0], [500.0, 3000.0], wind_kts=13.0)
    assert not leg_feasible(10.0, 3000.0) and np.isnan(t[0, 1])
    assert t[1, 0] == pytest.approx(leg_profile(30.0, 500.0, 13.0).charge_c)


def test_breakeven_distance():
    d = breakeven_distance_km(500.0, 1000.0, 39.0)
    assert math.isfinite(d) and d > 100.0
    lo = charge_table([d - 5.0, d + 5.0], [500.0, 1000.0], 39.0)
    assert lo[0, 1] > lo[0, 0] and lo[1, 1] < lo[1, 0]
    assert breakeven_distance_km(500.0, 3000.0, -39.0) == math.inf  # tailwind: never cheaper higher up
    with pytest.raises(InputError):
        breakeven_distance_km(1000.0, 500.0)
