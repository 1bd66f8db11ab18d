"""Tests for uam_studio.flight: table reproduction, interpolation, sampling, validation."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from uam_studio.errors import InputError
from uam_studio.flight import (
    CRUISE_TABLE_DISTANCE_KM,
    PHASES,
    TABLE_PHASES,
    InfeasibleLegError,
    cruise_duration_s,
    cruise_power_kw,
    cruise_rows,
    leg_current,
    leg_feasible,
    leg_profile,
    min_leg_distance_km,
    phase_duration_s,
    phase_power_kw,
    phase_rows,
    power_kw_to_cell_current_a,
)

ALTS = (500.0, 750.0, 1000.0, 1500.0, 2000.0, 2500.0, 3000.0)
FINE_WIND = np.linspace(-39.0, 39.0, 781)  # 0.1 kt steps


def test_tables_have_full_grid():
    assert len(phase_rows()) == 24 and len(cruise_rows()) == 24


@pytest.mark.parametrize(
    "row", cruise_rows(), ids=lambda r: f"{r.altitude_m:g}m{r.wind_kts:+g}kt"
)
def test_cruise_table_rows_reproduced(row):
    assert cruise_power_kw(row.altitude_m, row.wind_kts) == pytest.approx(
        row.power_kw, abs=1e-9
    )
    assert cruise_duration_s(
        CRUISE_TABLE_DISTANCE_KM, row.altitude_m, row.wind_kts
    ) == pytest.approx(row.duration_s, abs=1e-9)


# Cruise rows of the phase table: see test_phase_table_cruise_only_known_discrepancy.
NON_CRUISE_PHASE_ROWS = [r for r in phase_rows() if r.phase != "cruise"]


@pytest.mark.parametrize(
    "row", NON_CRUISE_PHASE_ROWS, ids=lambda r: f"{r.altitude_m:g}m-{r.phase}"
)
def test_phase_table_rows_reproduced(row):
    assert phase_power_kw(row.phase, row.altitude_m) == pytest.approx(
        row.power_kw, abs=1e-12
    )
    assert phase_duration_s(row.phase, row.altitude_m) == pytest.approx(
        row.duration_s, abs=1e-12
    )


def test_phase_table_cruise_only_known_discrepancy():
    # The phase table is a 13 kt tailwind flight; cruise comes from the wind table.
    mismatches = []
    for r in (r for r in phase_rows() if r.phase == "cruise"):
        assert cruise_duration_s(
            CRUISE_TABLE_DISTANCE_KM, r.altitude_m, -13
        ) == pytest.approx(r.duration_s)
        if abs(cruise_power_kw(r.altitude_m, -13) - r.power_kw) > 1e-9:
            mismatches.append(
                (r.altitude_m, r.power_kw, cruise_power_kw(r.altitude_m, -13))
            )
    assert mismatches == [(2000.0, 145.68, pytest.approx(148.68))]


def test_leg_profile_matches_phase_table_at_30nm():
    for h in (500, 1000, 2000, 3000):
        prof = leg_profile(CRUISE_TABLE_DISTANCE_KM, h, -13)
        names = [p[0] for p in prof.phases]
        assert tuple(names) == PHASES
        table = {r.phase: r for r in phase_rows() if r.altitude_m == h}
        keys = (
            "vertical_takeoff",
            "climb",
            "cruise",
            "descent_45deg",
            "approach_8deg",
            "vertical_landing",
        )
        for (_, start, end, _), key in zip(prof.phases, keys):
            assert end - start == pytest.approx(table[key].duration_s)
        assert prof.duration_s == pytest.approx(
            sum(r.duration_s for r in table.values())
        )


@pytest.mark.parametrize("h", ALTS)
def test_cruise_monotone_and_continuous_in_wind(h):
    power = np.array([cruise_power_kw(h, w) for w in FINE_WIND])
    dur = np.array(
        [cruise_duration_s(CRUISE_TABLE_DISTANCE_KM, h, w) for w in FINE_WIND]
    )
    assert np.all(np.diff(power) >= 0)
    assert np.all(np.diff(dur) > 0)
    assert np.max(np.abs(np.diff(power))) < 0.5  # kW per 0.1 kt
    assert np.max(np.abs(np.diff(dur))) < 2.0  # s per 0.1 kt


def test_zero_wind_lies_between_plus_minus_13():
    for h in ALTS:
        lo, hi = cruise_power_kw(h, -13), cruise_power_kw(h, 13)
        assert cruise_power_kw(h, 0) == pytest.approx((lo + hi) / 2)
        d0 = cruise_duration_s(CRUISE_TABLE_DISTANCE_KM, h, 0)
        assert (
            cruise_duration_s(CRUISE_TABLE_DISTANCE_KM, h, -13)
            < d0
            < cruise_duration_s(CRUISE_TABLE_DISTANCE_KM, h, 13)
        )


@pytest.mark.parametrize(
    "h,lo,hi",
    [(750, 500, 1000), (1500, 1000, 2000), (2500, 2000, 3000), (2900, 2000, 3000)],
)
def test_altitude_interpolation_between_neighbours(h, lo, hi):
    def between(f):
        a, b, x = f(lo), f(hi), f(h)
        assert min(a, b) - 1e-12 <= x <= max(a, b) + 1e-12

    for phase in TABLE_PHASES:
        between(lambda alt, ph=phase: phase_power_kw(ph, alt))
        between(lambda alt, ph=phase: phase_duration_s(ph, alt))
    for w in (-39, -20, -13, 0, 5, 13, 30, 39):
        between(lambda alt, w=w: cruise_power_kw(alt, w))
        between(lambda alt, w=w: cruise_duration_s(40.0, alt, w))
    between(min_leg_distance_km)


@pytest.mark.parametrize(
    "d,h,w", [(55.56, 1000, 0), (30.0, 2500, 17.3), (100.0, 750, -31.0)]
)
def test_charge_conserved_across_dt(d, h, w):
    ref = leg_profile(d, h, w, dt_s=1.0, dwell_s=33.3)
    exact_kj = sum(p * (end - start) for _, start, end, p in ref.phases)
    for dt in (0.1, 1.0, 2.5, 7.0, 60.0):
        prof = leg_profile(d, h, w, dt_s=dt, dwell_s=33.3)
        assert prof.charge_c == pytest.approx(ref.charge_c, rel=1e-9)
        assert prof.energy_kwh * 3600 == pytest.approx(exact_kj, rel=1e-9)
        assert (
            len(prof.time_s)
            == len(prof.power_kw)
            == len(prof.current_a)
            == int(np.ceil(prof.duration_s / dt - 1e-9))
        )
        assert prof.time_s[1] == pytest.approx(dt)
    assert np.sum(leg_current(d, h, w, dt_s=2.5)) * 2.5 == pytest.approx(
        ref.charge_c, rel=1e-9
    )


def test_sampling_is_time_average():
    prof = leg_profile(55.56, 1000, -13, dt_s=1.0)
    # step 15 spans take-off (ends 15.51 s) and climb
    assert prof.power_kw[15] == pytest.approx(0.51 * 264.94 + 0.49 * 272.66)
    assert prof.power_kw[0] == pytest.approx(264.94)
    assert prof.current_a[0] == pytest.approx(power_kw_to_cell_current_a(264.94))


def test_scaling_and_peak_current():
    assert power_kw_to_cell_current_a(273.53) == pytest.approx(2.957, abs=1e-3)
    for d, h, w in itertools.product(
        (25.0, 55.56, 200.0), (500, 1000, 2000, 2500, 3000), (-39, 0, 39)
    ):
        assert leg_current(d, h, w).max() <= 3.0


def test_30nm_at_1000m_uses_about_a_third_of_a_fresh_cell():
    for w in (-13, 0, 13):
        assert 2000.0 < leg_profile(55.56, 1000, w).charge_c < 3800.0


def test_min_leg_distance_and_infeasible():
    assert min_leg_distance_km(500) == pytest.approx(6.108, abs=1e-3)
    assert min_leg_distance_km(3000) == pytest.approx(22.798, abs=1e-3)
    assert leg_feasible(23.0, 3000) and not leg_feasible(12.0, 3000)
    with pytest.raises(
        InfeasibleLegError, match=r"distance_km.*3000 m.*22\.8 km"
    ) as exc:
        leg_profile(12.0, 3000, 0)
    assert isinstance(exc.value, InputError) and exc.value.field == "distance_km"
    leg_profile(6.2, 500, 0)  # just feasible


@pytest.mark.parametrize(
    "kwargs,field",
    [
        ({"distance_km": 0}, "distance_km"),
        ({"distance_km": -5}, "distance_km"),
        ({"distance_km": 501}, "distance_km"),
        ({"distance_km": float("nan")}, "distance_km"),
        ({"distance_km": "far"}, "distance_km"),
        ({"altitude_m": 499}, "altitude_m"),
        ({"altitude_m": 3001}, "altitude_m"),
        ({"wind_kts": -40}, "wind_kts"),
        ({"wind_kts": 39.5}, "wind_kts"),
        ({"dt_s": 0}, "dt_s"),
        ({"dt_s": 61}, "dt_s"),
        ({"dwell_s": -1}, "dwell_s"),
    ],
)
def test_bad_input_names_field(kwargs, field):
    args = {
        "distance_km": 50.0,
        "altitude_m": 1000.0,
        "wind_kts": 0.0,
        "dt_s": 1.0,
        "dwell_s": 0.0,
    } | kwargs
    with pytest.raises(InputError) as exc:
        leg_profile(**args)
    assert (
        exc.value.field == field
        and field in str(exc.value)
        and "\n" not in str(exc.value)
    )
    assert not isinstance(exc.value, InfeasibleLegError)


def test_profile_arrays_read_only_and_leg_current_copy():
    prof = leg_profile(40.0, 1000, 0)
    with pytest.raises(ValueError):
        prof.current_a[0] = 0.0
    cur = leg_current(40.0, 1000, 0)
    cur[0] = 0.0  # caller's own copy
    assert np.array_equal(cur[1:], prof.current_a[1:])


@pytest.mark.parametrize("args", [(30.0, 1000.0, 13.0, 0.0), (55.5, 500.0, -39.0, 300.0), (100.0, 3000.0, 39.0, 0.0)])
def test_leg_charge_matches_the_sampled_profile(args):
    from uam_studio.flight import leg_charge_c

    d, h, w, dwell = args
    for dt in (1.0, 0.5, 7.0):
        assert leg_charge_c(d, h, w, dwell) == pytest.approx(leg_profile(d, h, w, dt, dwell).charge_c, rel=1e-12)
    with pytest.raises(InfeasibleLegError):
        leg_charge_c(2.0, 3000.0, 0.0)


def test_leg_charges_vectorised_equals_scalar_bit_for_bit():
    from uam_studio.errors import InputError
    from uam_studio.flight import leg_charge_c, leg_charges_c

    rng = np.random.default_rng(3)
    d = rng.uniform(25.0, 500.0, (7, 5))
    w = rng.choice([-39.0, -13.0, 0.0, 7.5, 39.0], (1, 5))
    hs = (500.0, 1000.0, 1750.0, 3000.0)
    got = leg_charges_c(d, hs, w)
    assert got.shape == (*d.shape, len(hs))
    for k, h in enumerate(hs):
        want = np.array([[leg_charge_c(d[i, j], h, w[0, j]) for j in range(5)] for i in range(7)])
        assert np.array_equal(got[..., k], want)  # exactly: the same sums in the same order
    for field, args in (("altitude_m", (d, 3100.0, w)), ("distance_km", (d + 400.0, 500.0, w)),
                        ("wind_kts", (d, 500.0, w + 50.0)), ("distance_km", (d * np.nan, 500.0, w))):
        with pytest.raises(InputError, match=field):
            leg_charges_c(*args)
