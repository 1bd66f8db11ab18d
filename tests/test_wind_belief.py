"""The operator's wind belief (Bayesian online change-point detection over the flown legs' residuals):
it finds a change of the weather, does not see one in noise at more than the rate it states, predicts
with the change, and the operator keeps its weather reserve."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.planning.operations.wind_belief import (
    CHANGE_P,
    FALSE_ALARM_RATE,
    HAZARD,
    WindBelief,
)

NODES = [f"D{k}" for k in range(12)]


def _belief(sigma: float, forecast: list[float] | None = None) -> WindBelief:
    forecast = forecast or [0.0] * len(NODES)
    return WindBelief(dict(zip(NODES, forecast)), sigma)


@settings(max_examples=60, deadline=None)
@given(sigma=st.floats(1.0, 20.0), before=st.integers(1, 4), after=st.integers(3, 6),
       size_sd=st.floats(5.0, 8.0), sign=st.sampled_from([-1.0, 1.0]),
       forecast=st.lists(st.floats(-39.0, 39.0), min_size=10, max_size=10),
       noise=st.lists(st.floats(-1.0, 1.0), min_size=10, max_size=10))
def test_the_belief_finds_a_change(sigma, before, after, size_sd, sign, forecast, noise):
    """A change of 5-8 std of the forecast's error, after 1-4 legs, seen on 3-6 legs: with each leg's own
    error within one std (any pattern hypothesis finds), the belief holds the change (p >= CHANGE_P), at
    the right leg, of about the right size, and predicts the next leg with it."""
    size = sign * size_sd * sigma
    b = _belief(sigma, forecast + [0.0, 0.0])
    for k in range(before + after):
        b.observe(NODES[k], forecast[k] + (size if k >= before else 0.0) + noise[k] * sigma)
    ch = b.change()
    assert ch.detected and ch.p >= CHANGE_P, ch
    assert ch.since_leg == before and ch.since_node == NODES[before], ch
    assert abs(ch.size_kt - size) <= 2.5 * sigma, ch
    mean, sd = b.predict(NODES[11])  # an unflown leg (forecast 0): predicted with the change
    assert abs(mean - size) <= 2.0 * sigma and math.isfinite(sd) and sd > 0, (mean, sd, size)


def test_noise_alone_is_not_a_change_at_more_than_the_stated_rate():
    """On residuals that are the forecast's error alone (no change), seeded: the share of legs after which
    the belief holds a change is at most FALSE_ALARM_RATE, and the mean probability of a change it gives
    is at most the prior's (a Bayesian posterior under the null averages below its prior)."""
    rng = np.random.default_rng(5656)
    for sigma in (5.0, 13.0, 25.0):
        legs = alarms = 0
        p_sum = 0.0
        flights, n = 600, 6
        for _ in range(flights):
            b = _belief(sigma)
            for k in range(n):
                b.observe(NODES[k], rng.normal(0.0, sigma))
                if k >= 1:
                    legs += 1
                    alarms += b.change().detected
            p_sum += b.change_p()
        prior = 1.0 - (1.0 - HAZARD) ** (n - 1)
        assert alarms / legs <= FALSE_ALARM_RATE, (sigma, alarms / legs)
        assert p_sum / flights <= prior, (sigma, p_sum / flights, prior)


@settings(max_examples=40, deadline=None)
@given(sigma=st.floats(0.0, 60.0), winds=st.lists(st.floats(-39.0, 39.0), min_size=1, max_size=12),
       forecast=st.lists(st.floats(-39.0, 39.0), min_size=12, max_size=12))
def test_the_belief_stays_finite_over_the_documented_range(sigma, winds, forecast):
    b = _belief(sigma, forecast)
    for k, w in enumerate(winds):
        r, _ = b.observe(NODES[k], w)
        assert math.isfinite(r)
        assert 0.0 <= b.change_p() <= 1.0
        for node in NODES:
            mean, sd = b.predict(node)
            assert math.isfinite(mean) and math.isfinite(sd) and sd > 0
    assert np.isclose(np.exp(b.log_w[np.isfinite(b.log_w)]).sum(), 1.0)


def test_a_node_flown_again_is_predicted_from_its_measured_wind():
    b = _belief(13.0)
    b.observe(NODES[0], 10.0)
    mean, sd = b.predict(NODES[0])
    assert mean == pytest.approx(10.0) and sd < b.predict(NODES[1])[1] / 2  # its own error is known


def test_the_operator_turns_home_when_the_reserve_would_be_broken():
    """The README's demo (example mission, seed 0, +25 kt from 300 s, the pack its model): with the default 25 kt
    reserve the operator turns home with a destination left and lands safe, where with none it flies on to more
    destinations and breaches; the record then says the change exceeded the (zero) reserve, not a
    decision error."""
    from uam_studio.classroom import asset_path
    from uam_studio.planning import load_mission
    from uam_studio.planning.missions.mission import VERTIPORT
    from uam_studio.planning.operations import WEATHER_RESERVE_KT, WindEvent, fly_mission

    mission = load_mission(asset_path("example_mission.json"))
    event = [WindEvent(300.0, 25.0)]
    kept = fly_mission(mission, seed=0, events=event, references=False, world="model")
    none = fly_mission(mission, seed=0, events=event, references=False, reserve_kt=0.0, world="model")
    assert kept.reserve_kt == WEATHER_RESERVE_KT and not kept.breached and kept.breach_cause == ""
    assert none.breached and none.breach_cause.startswith("the change exceeded the reserve (+25 kt against a 0 kt")
    visited = [n for n in kept.route if n != VERTIPORT]
    assert kept.route[-1] == VERTIPORT and len(visited) < len(mission.destinations)
    # it turned home from a destination: the decision there sent it home, not on
    home = [d for d in kept.events if d.node != VERTIPORT and d.next_to == VERTIPORT]
    assert home and not home[-1].reason.startswith("no way home"), kept.events
    assert len([n for n in none.route if n != VERTIPORT]) > len(visited)
    assert all(d.reserve_kt == WEATHER_RESERVE_KT for d in kept.events)
