"""Property-based tests: every valid mission, every policy (hypothesis).

Missions are drawn anywhere in the documented ranges, not from the generators that training and tuning
used: 1-20 destinations in a 70 km square around the vertiport, any spacing (near-duplicates and points
next to the vertiport included), winds -39..39 kt, priorities 1-3, dwell times, all three scenarios,
q_max and R0 over the paper's health box. For each policy the plan comes back or a one-line planning
error names a cause in the mission; a plan stays above the cut-off on the physics model; its JSON holds
no NaN; the exact oracle's priority is at least every other policy's.

CI runs the example counts below (``max_examples``, derandomized: the same examples each run);
``UAM_PROPERTY_SCALE=10`` runs ten times as many, freshly drawn. The failures hypothesis found are kept as
regular regression tests (tests/test_reference.py::test_destinations_closer_than_any_leg_never_end_a_plan,
tests/test_oracle.py::test_multi_charge_cover_when_not_every_reachable_destination_fits_one_partition).
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uam_studio.battery.parameters import PAPER_Q_RANGE, PAPER_R0_RANGE
from uam_studio.errors import InputError
from uam_studio.flight.tables import WIND_RANGE_KTS
from uam_studio.planning import plan_mission
from uam_studio.planning.legs import N_MAX
from uam_studio.planning.missions.check import check_plan
from uam_studio.planning.missions.mission import (
    MAX_DESTINATIONS,
    SCENARIOS,
    Battery,
    Destination,
    Mission,
    Vertiport,
)

HALF_SQUARE_KM = 35.0
SCALE = int(os.environ.get("UAM_PROPERTY_SCALE", "1"))  # more examples per test (a longer hunt than CI's)
_SETTINGS = dict(deadline=None, derandomize=SCALE == 1, suppress_health_check=[HealthCheck.too_slow])

coord = st.floats(-HALF_SQUARE_KM, HALF_SQUARE_KM, allow_nan=False).map(lambda v: round(v, 1))
wind = st.floats(*WIND_RANGE_KTS, allow_nan=False).map(lambda v: round(v, 1))


@st.composite
def missions(draw, max_dest: int = MAX_DESTINATIONS, scenarios=SCENARIOS) -> Mission:
    scenario = draw(st.sampled_from(scenarios))
    n = 1 if scenario == "single_flight" else draw(st.integers(1, max_dest))
    pts: list[tuple[float, float]] = []
    for _ in range(n):
        kind = draw(st.sampled_from(("anywhere", "anywhere", "near another", "near the vertiport")))
        if kind == "near another" and pts:
            x0, y0 = draw(st.sampled_from(pts))
            dx, dy = draw(st.floats(-2, 2)), draw(st.floats(-2, 2))
            pts.append((round(min(max(x0 + dx, -HALF_SQUARE_KM), HALF_SQUARE_KM), 1),
                        round(min(max(y0 + dy, -HALF_SQUARE_KM), HALF_SQUARE_KM), 1)))
        elif kind == "near the vertiport":
            pts.append((round(draw(st.floats(-3, 3)), 1), round(draw(st.floats(-3, 3)), 1)))
        else:
            pts.append((draw(coord), draw(coord)))
    dests = tuple(Destination(f"D{k + 1}", x, y, draw(st.integers(1, 3)), draw(wind),
                              draw(st.sampled_from((0.0, 0.0, 60.0, 600.0))))
                  for k, (x, y) in enumerate(pts))
    battery = Battery(round(draw(st.floats(*PAPER_Q_RANGE)), 1), round(draw(st.floats(*PAPER_R0_RANGE)), 5))
    return Mission("drawn", Vertiport(0.0, 0.0, draw(wind)), dests, scenario, battery, 3.0)


def _plan_or_one_line(mission: Mission, policy: str):
    """The plan, or None after a one-line planning error that names a field (never another exception)."""
    try:
        res = plan_mission(mission, policy=policy)
    except InputError as err:
        text = str(err)
        assert "\n" not in text and ": " in text, text
        return None
    text = json.dumps(res.to_dict(), allow_nan=False)  # no NaN or inf anywhere in the JSON
    assert text
    if res.route:
        assert res.safe, (policy, res.route, res.min_voltage_v)
        assert check_plan(mission, res.route, res.altitudes_m).safe
    return res


@pytest.mark.parametrize("policy, examples", [("attention", 40), ("greedy", 60)])
def test_fast_policies_plan_any_valid_mission(policy, examples):
    @settings(max_examples=examples * SCALE, **_SETTINGS)
    @given(missions())
    def check(mission):
        _plan_or_one_line(mission, policy)

    check()


@settings(max_examples=25 * SCALE, **_SETTINGS)
@given(missions(max_dest=N_MAX))
def test_dqn_plans_any_valid_mission_it_can_hold(mission):
    _plan_or_one_line(mission, "dqn")


@settings(max_examples=12 * SCALE, **_SETTINGS)
@given(missions(max_dest=MAX_DESTINATIONS, scenarios=("single_charge", "multi_charge")))
def test_oracle_reference_plans_any_valid_mission(mission):
    _plan_or_one_line(mission, "oracle")


@settings(max_examples=15 * SCALE, **_SETTINGS)
@given(missions(max_dest=6))
def test_exact_oracle_is_never_beaten(mission):
    oracle = _plan_or_one_line(mission, "oracle")
    if oracle is None or not oracle.exact:
        return
    for policy in ("attention", "greedy", "dqn"):
        other = _plan_or_one_line(mission, policy)
        if other is not None:
            assert oracle.reached_priority >= other.reached_priority, (policy, other.route, oracle.route)


@settings(max_examples=6 * SCALE, **_SETTINGS)
@given(missions(max_dest=N_MAX, scenarios=("single_charge", "multi_charge")), st.integers(0, 10_000))
def test_fly_any_valid_mission(mission, seed):
    """The operator flies any valid mission in a world it cannot see (forecast error, sensor noise):
    a record or a one-line error; never below the cut-off; no NaN in the flown series."""
    from uam_studio.planning.operations import fly_mission

    try:
        rec = fly_mission(mission, seed=seed, references=False)
    except InputError as err:
        assert "\n" not in str(err) and ": " in str(err)
        return
    if rec.breached:  # only a cell too weak for the take-off, and the record says so
        assert rec.route == [] and rec.events[0].kind == "abort" and "take-off check" in rec.events[0].reason
    else:
        assert not rec.route or rec.min_voltage_v >= mission.eod_v
    for series in (rec.time_s, rec.measured_voltage_v, rec.true_voltage_v, rec.true_current_a):
        assert np.all(np.isfinite(series))
    assert json.dumps(rec.to_dict(), allow_nan=False)  # the CLI's JSON
