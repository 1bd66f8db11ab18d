"""The catalogue of planners (uam_studio.planning.planners): every entry resolves, and a planner added
there alone is planned with, checked on physics and refused options as its entry says."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from uam_studio.errors import InputError
from uam_studio.planning import load_mission, plan_mission
from uam_studio.planning.missions.check import Plan
from uam_studio.planning.planners import IN_FLIGHT_PLANNERS, LEARNED_POLICIES, PLANNERS, POLICIES, PlannerInfo
from uam_studio.planning.solvers.setup import destination_limit


def test_every_entry_names_a_plan_function_and_the_lists_follow_the_entries():
    for name, info in PLANNERS.items():
        assert info.name == name
        assert callable(info.plan_function()), name
    assert POLICIES[0] == "attention"  # the default first
    assert set(LEARNED_POLICIES) == {n for n, p in PLANNERS.items() if p.agent_file}
    assert IN_FLIGHT_PLANNERS[0] == "attention" and "dqn" not in IN_FLIGHT_PLANNERS
    assert PLANNERS["dqn"].bundled_file("multi_charge") == "dqn_multi_charge.zip"
    assert PLANNERS["oracle"].bundled_file("multi_charge") is None
    assert destination_limit("dqn") == 8 and destination_limit("greedy") == 20


def _home_only(mission, **kwargs) -> Plan:
    """A planner that visits the first destination at 500 m and comes home (a test's own)."""
    _home_only.calls.append(kwargs)
    first = mission.destinations[0].name
    return Plan("home_only", (first, "vertiport"), (500.0, 500.0), messages=("home-only plan",))


_home_only.calls = []


@pytest.fixture
def home_only(monkeypatch):
    info = PlannerInfo(name="home_only", label="Home only", plan=f"{__name__}:_home_only", max_destinations=3)
    monkeypatch.setitem(PLANNERS, "home_only", info)
    _home_only.calls.clear()
    return info


def test_a_planner_added_to_the_catalogue_alone_is_planned_with_and_checked_on_physics(home_only):
    from uam_studio.classroom import asset_path

    mission = load_mission(asset_path("example_mission.json"))
    res = plan_mission(mission, "home_only", predictor=False).to_dict()
    assert res["route"] == [mission.destinations[0].name, "vertiport"]
    assert "home-only plan" in res["messages"]
    assert res["physics"]["voltage_v"] and res["exact"] is None  # flown on the physics model
    assert _home_only.calls == [{}]  # no agent, predictor or lookahead: its entry takes none
    assert destination_limit("home_only") == 3
    with pytest.raises(InputError, match="agent_path"):
        plan_mission(mission, "home_only", agent_path="x.pt", predictor=False)
    with pytest.raises(InputError, match="lookahead"):
        plan_mission(mission, "home_only", lookahead=2, predictor=False)


def test_an_unknown_policy_names_the_field_and_every_allowed_one():
    from uam_studio.classroom import asset_path

    with pytest.raises(InputError) as err:
        plan_mission(load_mission(asset_path("example_mission.json")), "astar", predictor=False)
    assert err.value.field == "policy"
    for name in POLICIES:
        assert name in str(err.value)


def test_the_entries_are_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        PLANNERS["oracle"].max_destinations = 9  # type: ignore[misc]


class _Flat:
    """A stand-in predictor: 3.7 V everywhere, no band and no health fit of its own."""

    def predict(self, context_current_a, context_voltage_v, current_a, dt_s=1.0, **kwargs):
        return np.full(np.asarray(current_a).shape[-1], 3.7)


def test_a_predictor_is_what_the_protocol_asks_and_its_extras_are_used_only_when_present():
    from uam_studio.classroom import asset_path
    from uam_studio.dynaformer import load_pretrained
    from uam_studio.planning.voltage_predictor import BandPredictor, HealthFittingPredictor, VoltagePredictor

    dyn = load_pretrained()
    assert isinstance(dyn, BandPredictor) and isinstance(dyn, HealthFittingPredictor)
    flat = _Flat()
    assert isinstance(flat, VoltagePredictor) and not isinstance(flat, BandPredictor)
    mission = load_mission(asset_path("example_mission.json"))
    res = plan_mission(mission, "greedy", predictor=flat)
    assert set(res.predicted["voltage_v"]) == {3.7} and res.band is None
    with pytest.raises(InputError) as err:
        plan_mission(mission, "greedy", predictor=object())
    assert err.value.field == "predictor"
