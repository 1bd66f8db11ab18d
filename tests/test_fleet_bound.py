"""The hindsight bound on a fleet's day (uam_studio.fleet.hindsight): no dispatcher serves more."""

from __future__ import annotations

import copy

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from uam_studio.errors import InputError
from uam_studio.fleet.day import END_S, Fleet, hindsight_bound, simulate_day
from uam_studio.fleet.demand import poisson_demand
from uam_studio.fleet.dispatch import DISPATCHERS
from uam_studio.fleet.hindsight import Job, day_bound


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**31), spread=st.floats(0.0, 1500.0), far=st.floats(8.0, 100.0),
       rate=st.floats(0.5, 8.0), chargers=st.integers(1, 3), aircraft=st.integers(1, 5),
       law=st.sampled_from(["nasa", "vtc6"]))
@example(seed=3, spread=300.0, far=60.0, rate=8.0, chargers=1, aircraft=5, law="vtc6")  # the one charger binds
@example(seed=3, spread=50.0, far=60.0, rate=8.0, chargers=1, aircraft=5, law="nasa")
def test_no_dispatcher_serves_more_than_the_bound_from_the_same_fleet(seed, spread, far, rate, chargers, aircraft,
                                                                       law):
    """Drawn over the documented ranges (pack ages, distances, demand, chargers, fleet sizes): each
    dispatcher's day from one fleet state serves at most the day's bound."""
    fleet = Fleet.new(aircraft, seed, spread, law=law)
    demand = poisson_demand(seed, rate, day_s=6 * 3600.0, max_km=far)
    bound = hindsight_bound(copy.deepcopy(fleet), demand, seed, chargers)
    assert 0 <= bound <= sum(r.priority for r in demand)
    for d in DISPATCHERS:
        day = simulate_day(copy.deepcopy(fleet), demand, d, seed, chargers)
        assert day.priority <= bound, (d, day.priority, bound)
        assert day.bound == (bound if d == "hindsight" else None)


def test_the_bound_counts_chargers_and_leaves_out_what_no_pack_can_fly():
    """Where one charger cannot turn the fleet round, the bound is below the day's stars; a far day on
    worn packs leaves out the requests no pack flies safely."""
    fleet = Fleet.new(6, 0, 450.0, law="vtc6")  # ages within the VTC6 law's life (80% near 490 cycles)
    demand = poisson_demand(100, 4.0, max_km=70.0)
    total = sum(r.priority for r in demand)
    one, two = (hindsight_bound(copy.deepcopy(fleet), demand, 100, c) for c in (1, 2))
    assert one < two <= total
    worn = Fleet.new(3, 0, 1900.0, law="vtc6")
    far = poisson_demand(7, 4.0, max_km=100.0)
    assert hindsight_bound(worn, far, 7, 50) < sum(r.priority for r in far)


def _job(request: int, flight_s: float = 1000.0, charge_s: float = 2000.0, priority: int = 1, **kw) -> Job:
    base = dict(request=request, aircraft=0, port=0, earliest_s=0.0, latest_s=100.0, flight_s=flight_s,
                charge_s=charge_s, priority=priority)
    return Job(**{**base, **kw})


def test_day_bound_is_the_fractional_knapsack_of_charger_and_aircraft_time():
    # one aircraft, one charger, windows closing at 100 s: the charger has 1 x (100 - 1000)+ = 0 s before
    # the last window closes, plus one last recharge of 2000 s: one job's worth, the 3-star one
    jobs = [_job(0, priority=1), _job(1, priority=3), _job(2, priority=2)]
    assert day_bound(jobs, [1], [1], END_S) == 3
    # two aircraft: two last recharges
    assert day_bound(jobs, [1], [2], END_S) == 5
    # a job that cannot land before the end counts for nothing; no job, no stars
    assert day_bound([_job(0, flight_s=END_S + 1.0, priority=3)], [1], [1], END_S) == 0
    assert day_bound([], [1], [1], END_S) == 0
    # the same request by two aircraft counts once, at its shortest times
    assert day_bound([_job(0, priority=2), _job(0, aircraft=1, priority=2)], [5], [2], END_S) == 2


def test_day_bound_refuses_a_job_at_a_vertiport_without_counts():
    with pytest.raises(InputError, match="chargers"):
        day_bound([_job(0, port=1)], [1], [1], END_S)
