"""The Fly tab's state model and view, in-process (no browser)."""

from __future__ import annotations

from pathlib import Path

import pytest

from uam_studio.app.fly import FlyView
from uam_studio.app.fly_state import FlyState
from uam_studio.errors import InputError
from uam_studio.planning import load_mission

EXAMPLE = Path(__file__).resolve().parents[1] / "assets" / "example_mission.json"


@pytest.fixture()
def state():
    mission = load_mission(EXAMPLE)
    return FlyState(lambda: mission)


def test_fly_plays_back_and_moves_the_aircraft(state):
    view = FlyView(state)
    state.fly()
    assert state.error == "" and state.record is not None and state.playing
    assert "hindsight oracle" in state.status
    x0, y0, leg0 = state.position()
    state.tick(5.0)  # 5 s of wall time at x100
    assert state.t_s == pytest.approx(500.0)
    x1, y1, leg1 = state.position()
    assert (x1, y1) != (x0, y0) and leg1 == 0
    assert [r["at"] for r in state.decisions_until()] == ["vertiport"]
    state.t_s = state.end_s
    assert len(state.decisions_until()) == len(state.record.events)
    state.tick(1.0)
    assert not state.playing  # the end stops the playback
    assert view.__panel__() is not None


def test_injected_wind_change_reflies_from_the_playback_time(state):
    state.fly()
    before = state.record
    state.t_s = 1000.0
    state.inject_kts = 30.0
    state.inject()
    assert state.t_s == 1000.0 and state.events[-1].start_s == 1000
    after = state.record
    assert after is not before and after.wind_events == ["wind+30@1000"]
    # the flight up to the change is the same flight
    k = int((after.time_s <= 1000.0).sum())
    assert (after.measured_voltage_v[:k] == before.measured_voltage_v[:k]).all()
    state.clear_events()
    assert state.events == [] and state.record.wind_events == []


def test_bad_mission_is_a_line_not_a_traceback():
    def broken():
        raise InputError("destinations", "a mission needs at least 1 destination")

    s = FlyState(broken)
    s.fly()
    assert s.error.startswith("destinations:") and s.record is None
    s.inject()
    assert "fly first" in s.error
