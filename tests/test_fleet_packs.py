"""A fleet's packs: the law of their cell type (NASA by default), and a retired pack replaced overnight."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.errors import InputError
from uam_studio.fleet.aging import AGING_LAW, END_OF_LIFE_FRACTION
from uam_studio.fleet.day import PACK_LAWS, Fleet, default_age_spread, simulate_life
from uam_studio.fleet.nasa_aging import NASA_AGING_LAW


def test_a_new_fleet_flies_nasa_packs_that_age_and_are_believed_to_age_by_the_nasa_law():
    fleet = Fleet.new(4, seed=3)
    assert fleet.law == "nasa" and fleet.aging_law is NASA_AGING_LAW
    assert all(t.law is NASA_AGING_LAW for t in fleet.truth)
    life = NASA_AGING_LAW.cycles_to(END_OF_LIFE_FRACTION)
    assert 80.0 < life < 100.0 < AGING_LAW.cycles_to(END_OF_LIFE_FRACTION)  # NASA cells fade five times faster
    assert all(t.efc <= default_age_spread() == round(0.6 * life) for t in fleet.truth)
    pack = fleet.truth[0]
    assert pack.after(pack.q_max0 * (life - pack.efc) * 1.01).retired
    assert not pack.after(pack.q_max0 * (life - pack.efc) * 0.99).retired
    # the belief ages by the same law (its mean moves as the truth's would, from the same start)
    b0 = fleet.belief(0)
    assert b0.config.aging is fleet.aging_law
    b1 = b0.aged(10.0 * b0.q_nominal_c)
    e0 = b0.delivered_c / b0.q_nominal_c
    expect = NASA_AGING_LAW.capacity_fraction(e0 + 10.0) / NASA_AGING_LAW.capacity_fraction(e0)
    assert b1.health.q_max_c / b0.health.q_max_c == pytest.approx(float(expect), rel=1e-9)


def test_an_unknown_cell_type_is_refused_in_one_line_naming_the_law():
    with pytest.raises(InputError, match=r"law.*allowed nasa, vtc6"):
        Fleet.new(2, seed=0, law="lfp")
    assert set(PACK_LAWS) == {"nasa", "vtc6"}


@settings(max_examples=4, deadline=None)
@given(n=st.integers(1, 6), seed=st.integers(0, 2**31), night=st.integers(0, 1000),
       law=st.sampled_from(["nasa", "vtc6"]))
def test_renewal_replaces_exactly_the_retired_packs_with_new_ones(n, seed, night, law):
    fleet = Fleet.new(n, seed, age_spread_efc=1.5 * PACK_LAWS[law].cycles_to(END_OF_LIFE_FRACTION), law=law)
    before = list(fleet.truth)
    grounded = [i for i, s in enumerate(fleet.in_service) if not s]
    assert fleet.renew_retired(seed, night) == grounded and all(fleet.in_service)
    for i, (old, new) in enumerate(zip(before, fleet.truth)):
        if i in grounded:
            assert new.delivered_c == 0.0 and new.law is PACK_LAWS[law] and 7300.0 <= new.q_max <= 7900.0
            assert fleet.belief(i).delivered_c == 0.0 and len(fleet.logbooks[i]) == 0
        else:
            assert new is old


def test_a_life_of_worn_nasa_packs_replaces_them_and_serves_more_than_one_left_grounded():
    kw = dict(rate_per_h=3.0, age_spread_efc=200.0)  # most packs past the NASA law's 80% (about 90 cycles)
    renewed = simulate_life(3, 2, 11, "aware", **kw)
    grounded = simulate_life(3, 2, 11, "aware", renew=False, **kw)
    at_start = grounded["retired_day"].count(0)
    assert at_start >= 1 and renewed["retired_day"].count(0) == at_start  # retired before day 1
    assert renewed["retired_day"].count(None) == 3  # every aircraft flies a pack in service at the end
    assert grounded["retired_day"].count(None) == 3 - sum(d is not None for d in grounded["retired_day"])
    served = [sum(d["served"] for d in life["days"]) for life in (renewed, grounded)]
    assert served[0] > served[1]


def test_the_fleet_package_exports_the_names_of_a_fleet_study():
    import uam_studio.fleet as fleet

    assert {"Fleet", "simulate_day", "simulate_life", "poisson_demand", "fleet_study", "summarize",
            "NASA_AGING_LAW", "PACK_LAWS"} <= set(fleet.__all__)
    assert all(getattr(fleet, name) is not None for name in fleet.__all__)
    assert fleet.Fleet is Fleet and fleet.PACK_LAWS["nasa"] is NASA_AGING_LAW


def test_a_fleets_packs_are_not_their_model_by_default_and_keep_their_own_set():
    """Each pack of a new fleet has its own parameter set (the varied world), the same for the same seed, kept as it
    ages; a renewed pack gets its own too; ``world="model"`` flies the cell type's set. The dispatchers' beliefs are
    the same in both worlds before any flight (they never see the set)."""
    from uam_studio.battery.parameters import DEFAULT_CELL

    varied, again, model = Fleet.new(4, seed=5), Fleet.new(4, seed=5), Fleet.new(4, seed=5, world="model")
    sets = [t.params for t in varied.truth]
    assert all(p is not None and p != DEFAULT_CELL for p in sets) and len({repr(p) for p in sets}) == 4
    assert [t.params for t in again.truth] == sets and all(t.params is None for t in model.truth)
    assert [(t.q_max, t.r0) for t in varied.truth] == [(t.q_max, t.r0) for t in model.truth]
    assert varied.truth[0].after(1000.0).params == sets[0]
    assert varied.beliefs == model.beliefs
    worn = Fleet.new(3, seed=1, age_spread_efc=1.5 * PACK_LAWS["nasa"].cycles_to(END_OF_LIFE_FRACTION))
    for i in worn.renew_retired(1, 2):
        assert worn.truth[i].params is not None and worn.truth[i].params not in sets
    with pytest.raises(InputError, match="^world: "):
        Fleet.new(2, seed=0, world="real")
    # the world flies each pack on its own set: the same requests land at other voltages
    from uam_studio.fleet.day import simulate_day
    from uam_studio.fleet.demand import poisson_demand

    demand = poisson_demand(3)[:4]
    v = simulate_day(Fleet.new(2, seed=5), demand, "hindsight", seed=1).log
    m = simulate_day(Fleet.new(2, seed=5, world="model"), demand, "hindsight", seed=1).log
    assert v and m and [e[3] for e in v] != [e[3] for e in m]
