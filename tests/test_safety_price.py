"""The price of safety (uam_studio.planning.operations.safety_price): the study's flights, its per-risk sums."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import binomtest

from uam_studio.errors import InputError
from uam_studio.planning.operations import fly_mission, parse_event
from uam_studio.planning.operations.safety_price import (
    CHANGE_CLIP_KT,
    CHANGE_WINDOW_S,
    RiskFlight,
    format_levels,
    group_tests,
    price_of_safety,
    risk_flights,
    risk_levels,
)


def test_the_study_flights_are_seeded_half_single_charge_with_changes_in_the_envelope():
    a, b = risk_flights(12), risk_flights(12)
    assert [(m.name, s, e) for m, s, e in a] == [(m.name, s, e) for m, s, e in b]
    assert [m.scenario for m, _, _ in a] == ["single_charge"] * 6 + ["multi_charge"] * 6
    assert len({s for _, s, _ in a}) == 12
    for _, _, text in a:
        ev = parse_event(text)
        assert abs(ev.delta_kts) <= CHANGE_CLIP_KT and CHANGE_WINDOW_S[0] <= ev.start_s <= CHANGE_WINDOW_S[1]
    assert [m.scenario for m, _, _ in risk_flights(1)] == ["multi_charge"]
    for bad in (0, 5001, math.nan):
        with pytest.raises(InputError):
            risk_flights(bad)


flight = st.builds(RiskFlight, risk=st.sampled_from([0.01, 0.05, 0.2]),
                   scenario=st.sampled_from(["single_charge", "multi_charge"]), priority=st.integers(0, 20),
                   blind=st.integers(0, 20), hindsight=st.integers(0, 20), breached=st.booleans(),
                   blind_breached=st.booleans())


@settings(max_examples=80, deadline=None)
@given(st.lists(flight, min_size=1, max_size=40))
def test_the_levels_sum_each_risk_with_its_binomial_interval_and_test(flights):
    levels = risk_levels(flights)
    assert [v.risk for v in levels] == list(dict.fromkeys(f.risk for f in flights))
    for v in levels:
        sub = [f for f in flights if f.risk == v.risk]
        k = sum(f.breached for f in sub)
        assert (v.flights, v.breaches, v.rate) == (len(sub), k, k / len(sub))
        assert 0.0 <= v.rate_low <= v.rate <= v.rate_high <= 1.0
        assert v.p_at_most == pytest.approx(binomtest(k, len(sub), v.risk, alternative="greater").pvalue)
        hind = sum(f.hindsight for f in sub)
        assert (math.isnan(v.priority_ratio) if hind == 0 else
                v.priority_ratio == pytest.approx(sum(f.priority for f in sub) / hind))
        assert v.blind_breaches == sum(f.blind_breached for f in sub)
    assert format_levels(levels).count("\n") == len(levels) + 1
    groups = group_tests(flights).splitlines()
    assert len(groups) == len({(f.risk, f.scenario) for f in flights})
    assert sum(int(line.split(": ")[1].split(" of ")[0]) for line in groups) == sum(f.breached for f in flights)


def test_the_study_flies_what_fly_mission_flies():
    """Two flights at one risk: each is fly_mission on its mission, world, pack and change, at that risk."""
    flights = price_of_safety([0.1], 2)
    for (m, seed, event), got in zip(risk_flights(2), flights):
        try:
            rec = fly_mission(m, seed=seed, pack=seed, risk=0.1, events=[parse_event(event)])
        except InputError:
            rec = fly_mission(m, seed=seed, pack=seed, risk=0.1)
        assert (got.priority, got.blind, got.hindsight, got.breached) == (
            rec.reached_priority, rec.static.priority, rec.hindsight.priority, rec.breached)
    with pytest.raises(InputError, match="risk"):
        price_of_safety([0.5], 2)
