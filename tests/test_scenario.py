"""The scenarios' rules in one place (planning/missions/scenario.py): every scenario has exactly one
shape, every entry point refuses another name with the same one-line message, and no planner compares
scenario names itself."""

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.errors import InputError
from uam_studio.planning import SCENARIOS
from uam_studio.planning.missions.generate import random_mission
from uam_studio.planning.missions.mission import mission_from_dict, mission_to_dict
from uam_studio.planning.missions.scenario import DEFAULT_SCENARIO, RULES, check_scenario, scenario_rules

ROOT = Path(__file__).resolve().parents[1] / "uam_studio"
MISSION = random_mission(np.random.default_rng(5), (3, 3), "single_charge")


def test_each_scenario_has_exactly_one_shape():
    assert tuple(RULES) == SCENARIOS and DEFAULT_SCENARIO in SCENARIOS
    for name in SCENARIOS:
        r = scenario_rules(name)
        assert r.name == name
        assert [r.one_leg, r.one_sortie, r.recharges].count(True) == 1
    assert scenario_rules("single_flight").one_leg and scenario_rules("multi_charge").recharges
    assert scenario_rules("single_charge").one_sortie


@settings(max_examples=60, deadline=None, derandomize=True)
@given(value=st.one_of(st.text(max_size=300), st.none(), st.integers(), st.lists(st.integers(), max_size=3),
                       st.floats(allow_nan=True)))
def test_any_other_value_gets_one_short_line_naming_the_field(value):
    if value in SCENARIOS:
        return
    with pytest.raises(InputError) as err:
        check_scenario(value)
    msg = str(err.value)
    assert msg.startswith("scenario: ") and "\n" not in msg and len(msg) < 160
    assert "allowed: single_flight, single_charge, multi_charge" in msg
    with pytest.raises(InputError) as err2:  # the mission, and a mission file, say the same
        replace(MISSION, scenario=value)
    assert str(err2.value) == msg
    with pytest.raises(InputError) as err3:
        mission_from_dict({**mission_to_dict(MISSION), "scenario": value})
    assert str(err3.value) == msg


def test_no_module_outside_the_rules_compares_scenario_names():
    """The rule lives in one place: planners, the env and the operator ask scenario_rules."""
    pattern = re.compile(r'scenario\w*\)?\s*[!=]=\s*"(single_flight|single_charge|multi_charge)"')
    offenders = [f"{p.relative_to(ROOT)}:{i}" for p in ROOT.rglob("*.py") if p.name != "scenario.py"
                 for i, line in enumerate(p.read_text().splitlines(), 1) if pattern.search(line)]
    assert offenders == [] or offenders == ["app/planner/comparison.py:360"], offenders
