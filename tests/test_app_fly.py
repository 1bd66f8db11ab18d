"""The Fly tab's state model and view, in-process (no browser)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from uam_studio.app.fly.state import FlyState
from uam_studio.app.fly.view import FlyView
from uam_studio.errors import InputError
from uam_studio.planning import load_mission
from uam_studio.planning.operations import fly_mission

EXAMPLE = Path(__file__).resolve().parents[1] / "assets" / "example_mission.json"


@pytest.fixture()
def state():
    mission = load_mission(EXAMPLE)
    return FlyState(lambda: mission)


def test_fly_plays_back_and_moves_the_aircraft(state):
    view = FlyView(state)
    state.fly()
    assert state.error == "" and state.record is not None and state.playing
    assert state.status.startswith("flying:") and "hindsight" not in state.status and "priority" not in state.status
    x0, y0, leg0 = state.position()
    state.tick(5.0)  # 5 s of wall time at x100
    assert state.t_s == pytest.approx(500.0)
    seen = state.series_until()  # nothing after the playback time
    for key in ("measured", "true", "predicted"):
        assert len(seen[key][0]) == int((state.record.time_s <= 500.0).sum()) and max(seen[key][0]) <= 500.0 / 60
    assert [round(t * 60) for t, _, _ in seen["decisions"]] == [20]
    x1, y1, leg1 = state.position()
    assert (x1, y1) != (x0, y0) and leg1 == 0
    assert [r["at"] for r in state.decisions_until()] == ["vertiport"]
    state.t_s = state.end_s
    assert len(state.decisions_until()) == len(state.record.events)
    assert "hindsight oracle" in state.status and "flown: priority" in state.status  # the result, at the landing
    state.tick(1.0)
    assert not state.playing  # the end stops the playback
    assert view.__panel__() is not None


def test_the_flight_shows_from_its_first_leg_and_before_its_references():
    """Served (background): the flight shows from its first leg on while the rest is flown; then the whole flight;
    its references, which only the landing shows, come after it, and a landing before them says so. A flight,
    a part of one or references no longer asked for are dropped."""
    mission = load_mission(EXAMPLE)
    held: list = []  # callbacks handed to the session's thread, run when the test says
    state = FlyState(lambda: mission, background=True, dispatch=held.append)

    def wait_for(n: int) -> None:
        deadline = time.monotonic() + 60.0
        while len(held) < n and time.monotonic() < deadline:
            time.sleep(0.01)
        assert len(held) >= n

    def deliver_next() -> None:
        wait_for(1)
        held.pop(0)()

    full = fly_mission(mission, seed=state.seed, risk=state.risk)
    state.fly()
    deliver_next()  # the first leg
    part = state.record
    assert not state.complete and not state.running and state.playing and part.route == full.route[:1]
    assert part.time_s[-1] == full.leg_end_s[0] and state.status.startswith("flying: 0.0 min")
    state.tick(100.0)  # past the legs shown: the clock waits at their end, the playback goes on
    assert state.t_s == state.end_s == full.leg_end_s[0] and state.playing and not state.landed
    assert "the results show at the landing" in state.status
    deliver_next()  # the whole flight
    first = state.record
    assert state.complete and first.route == full.route and not state.references and state.t_s == full.leg_end_s[0]
    assert first.static.route == [] and first.hindsight.route == []  # not flown yet
    state.t_s = state.end_s  # landed before the references came
    assert "being flown" in state.status and "hindsight oracle" not in state.status
    deliver_next()  # its references
    assert state.references and state.record is not first and state.record.time_s is first.time_s
    assert state.record.hindsight.route and "hindsight oracle" in state.status
    assert (state.record.static, state.record.hindsight) == (full.static, full.hindsight)
    state.seed = 1
    state.fly()
    wait_for(2)  # the second flight's first leg and whole flight
    state.seed = 2
    state.fly()  # a third flight meanwhile
    held.pop(0)()  # the second flight's first leg: dropped
    held.pop(0)()  # the second flight: dropped
    assert state.record.seed == 0 and state.running
    deliver_next()  # the third flight's first leg
    assert state.record.seed == 2 and not state.complete
    deliver_next()  # the third flight
    deliver_next()  # its references
    assert state.references and state.complete and state.record.seed == 2 and state.record.hindsight.route
    # a wind change: the flight until the landing of the leg in the air shows at once, the change marked
    state.t_s = 1000.5
    shown = state.record
    state.inject()
    now = state.record  # nothing delivered from the pool yet
    assert now is not shown and now.wind_events == ["wind+25@1000"] and not state.complete and state.t_s == 1000.5
    assert now.leg_end_s[-1] >= 1000.5 and state.series_until()["changes"] == [(1000 / 60, "wind +25 kt from the next "
                                                                                             "take-off")]
    deliver_next()  # the re-flown flight from the leg that reaches the playback time
    deliver_next()  # all of it
    assert state.complete and state.record.wind_events == ["wind+25@1000"] and state.t_s == 1000.5
    # a change injected while a newer flight is flown, before it shows: nothing of the shown one is taken for it
    deliver_next()  # the references
    state.seed = 3
    state.fly()
    state.inject()
    assert state.record.seed == 2 and state.running  # still the old flight, not a part passed off as the new one


def test_a_flight_stops_at_a_landing_once_a_newer_one_is_asked_for():
    """A flight whose request is no longer the newest stops at its next landing (a wind change asked for while the
    flight before it is computed need not wait for all of it); nothing of it is shown."""
    mission = load_mission(EXAMPLE)
    held: list = []
    state = FlyState(lambda: mission, background=True, dispatch=held.append)
    state.fly()
    asked = state._asked
    state._asked = None  # as if a newer flight had been asked for
    flight, rec, err = state._compute(asked)
    assert flight is asked and rec is None and err == "superseded"
    state._asked = asked
    _, rec, err = state._compute(asked)
    assert err == "" and rec.route and len(held) >= 1  # the newest runs to its end, its first leg handed over


def test_injected_wind_change_reflies_from_the_playback_time(state):
    state.fly()
    before = state.record
    state.t_s = 1000.0
    state.inject_kts = 30.0
    state.inject()
    assert state.t_s == 1000.0 and state.events[-1].start_s == 1000
    after = state.record
    assert after is not before and after.wind_events == ["wind+30@1000"]
    # marked where injected
    assert state.series_until()["changes"] == [(1000 / 60, "wind +30 kt from the next take-off")]
    # the flight up to the change is the same flight
    k = int((after.time_s <= 1000.0).sum())
    assert (after.measured_voltage_v[:k] == before.measured_voltage_v[:k]).all()
    state.t_s = 1500.7  # a change injected between two whole seconds is marked at once
    state.inject()
    assert state.series_until()["changes"][-1] == (1500 / 60, "wind +30 kt from the next take-off")
    state.clear_events()
    assert state.events == [] and state.record.wind_events == []


def test_a_redraw_sends_only_the_sources_that_changed(state):
    """A source set is sent to the browser and its figure drawn again there: the same flight drawn again (as at a
    flight's completion, or a wind change's, when the part shown is the same) sets no source; the playback moving
    on sets the ones that moved, and an injected change its mark."""
    from bokeh.document import Document

    view = FlyView(state)
    doc = Document()
    doc.add_root(view.__panel__().get_root(doc))  # in a document, as served: Bokeh then sends every set
    state.fly()
    state.t_s = 600.0
    sources = {"dests": view.dests, "vertiport": view.vertiport, "seen": view.seen, "pos": view.pos,
               "legs": view.leg_labels, "cutoff": view.cutoff, "marks": view.marks, "changes": view.changes,
               **{f"curve {k}": src for k, src in view.curves.items()}}
    sent: list[str] = []
    for name, src in sources.items():
        src.on_change("data", lambda _attr, _old, _new, name=name: sent.append(name))
    view._draw_record()
    assert sent == []
    state.t_s = 700.0
    assert {"pos", "curve measured", "curve true", "curve predicted"} <= set(sent)
    assert not {"dests", "vertiport", "cutoff", "changes"} & set(sent)
    sent.clear()
    state.inject_kts = 20.0
    state.inject()  # the flight before the change is the one shown: its mark, and the axes' growth, at most
    assert "changes" in sent and not {"dests", "vertiport", "seen", "pos"} & set(sent)


def test_bad_mission_is_a_line_not_a_traceback():
    def broken():
        raise InputError("destinations", "a mission needs at least 1 destination")

    s = FlyState(broken)
    s.fly()
    assert s.error.startswith("destinations:") and s.record is None
    s.inject()
    assert "fly first" in s.error


def test_the_record_and_the_plan_save_as_csv(state):
    from uam_studio.planning import plan_csv, plan_mission
    from uam_studio.planning.operations import record_csv

    state.fly()
    rows = record_csv(state.record).splitlines()
    assert rows[0].split(",")[:2] == ["time_s", "measured_voltage_v"] and "true_voltage_v" in rows[0]
    assert len(rows) == state.record.time_s.size + 1
    assert all(len(r.split(",")) == len(rows[0].split(",")) for r in rows)
    plan = plan_mission(load_mission(EXAMPLE), policy="greedy")
    lines = plan_csv(plan).splitlines()
    assert plan_csv(plan.to_dict()).splitlines() == lines
    legs = [r.split(",") for r in lines[1:]]
    assert [int(r[1]) for r in legs] == sorted(int(r[1]) for r in legs)  # legs in flying order
    assert {r[2] for r in legs} == set(plan.route) and len(legs) == len(plan.physics["time_s"])
    assert all(float(r[4]) >= 3.0 for r in legs)  # the safe plan's physics voltage


def test_the_cut_off_line_follows_the_missions_cut_off(state):
    """The voltage figure's cut-off line is the flown mission's, also when the axes stay as they were (two cut-offs
    above the flight's lowest voltage give the same axes)."""
    import dataclasses

    view = FlyView(state)
    state.fly()
    rec, mission = state.record, state.mission_flown
    low = float(rec.true_voltage_v.min())
    for eod in (low + 0.05, low + 0.1):
        other = dataclasses.replace(mission, eod_v=round(eod, 3))
        state.param.update(record=dataclasses.replace(rec, time_s=rec.time_s.copy()), mission_flown=other)
        assert list(view.cutoff.data["y"]) == [other.eod_v, other.eod_v]


def test_flown_legs_are_numbered_with_their_altitude_on_the_map(state):
    from uam_studio.app.fly.view import _leg_labels

    view = FlyView(state)
    state.fly()
    state.t_s = state.end_s
    labels = view.leg_labels.data
    n = len(state.record.route)
    assert labels["text"] == [f"#{k + 1} {a:g} m" for k, a in enumerate(state.record.altitudes_m)][:len(labels["text"])]
    assert n - 1 <= len(labels["text"]) <= n  # every leg flown (a leg ending where it began has no label)
    assert view.map_fig.toolbar.active_scroll is None  # the mouse wheel scrolls the page
    one = _leg_labels([(0.0, 0.0), (10.0, 0.0), (10.0, 0.0)], [500.0, 1000.0], state.mission_flown)
    assert one["text"] == ["#1 500 m"] and 0.0 <= one["x"][0] <= 10.0 and one["y"][0] != 0.0  # beside the leg
    # placed as the Planner's labels: clear of the places, their names and each other
    from uam_studio.app.planner.map_geometry import label_overlaps

    m = state.mission_flown
    assert label_overlaps(labels, [(m.vertiport.x_km, m.vertiport.y_km), *[(d.x_km, d.y_km) for d in m.destinations]],
                          ["", *[f"{d.name} {'*' * d.priority}" for d in m.destinations]]) == []


def test_the_world_choice_reaches_the_flight_and_the_summary_shows_the_first_leg(state):
    """The tab's world: a pack unlike its model by default, the teaching world on request (the same calls the CLI
    makes); the landed summary shows the first leg's believed interval, its model-error term and what the world
    gave."""
    view = FlyView(state)
    state.fly()
    varied = state.record
    assert varied.world == "varied" and view.world.value == state.world
    state.t_s = state.end_s
    assert "first leg's lowest voltage: believed" in state.status and "model error" in state.status
    view.world.value = "its model (teaching)"
    state.fly()
    assert state.record.world == "model" and state.record.route is not None
    assert state.record.takeoff_belief["first_leg_min_voltage_90_v"] != varied.takeoff_belief[
        "first_leg_min_voltage_90_v"]


def test_the_declared_risk_sets_the_cautions_and_a_hand_moved_reserve_declares_none(state):
    """Choosing a risk moves the reserve to the one that follows from it and the flight declares that risk; a reserve
    moved by hand keeps the risk's margins and the flight declares no risk."""
    from uam_studio.risk import caution

    view = FlyView(state)
    view.risk.value = 0.01
    assert state.risk == 0.01 and state.reserve_kt == caution(0.01).reserve_kt == view.reserve.value
    state.fly()
    assert state.record.risk == 0.01 and state.record.reserve_kt == caution(0.01).reserve_kt
    view.reserve.value = 10.0
    state.fly()
    assert state.record.risk is None and state.record.reserve_kt == 10.0


def test_many_flights_draw_the_price_of_safety_in_the_tabs_world(state):
    """The "many flights" view flies price_of_safety at the tab's risks in the tab's world and draws its levels."""
    from uam_studio.app.fly.many import ManyFlightsView
    from uam_studio.planning.operations.safety_price import RATE_FLOOR, price_of_safety, risk_levels

    many = state.many
    assert many.world == "varied" and many.risks == [0.01, 0.05, 0.1, 0.2]
    state.world = "its model (teaching)"
    assert many.world == "model"
    view = ManyFlightsView(many)
    assert "does the breach rate stay under the risk" in view.note.object
    many.param.update(per_level=2, risks=[0.05, 0.2])
    seen = []
    many.param.watch(lambda e: seen.append(e.new), "done")
    many.run()
    assert many.error == "" and not many.running and seen == [1, 2, 3, 4]
    assert many.levels == risk_levels(price_of_safety([0.05, 0.2], 2, world="model"))
    assert view.rates.data["risk"] == [0.05, 0.2] and min(view.rates.data["rate"]) >= RATE_FLOOR
    assert view.served.data["operator"] == [v.priority_ratio for v in many.levels]
    assert list(view.table.value["declared risk"]) == [0.05, 0.2]
    assert "2 flights per declared risk" in view.note.object and "'model'" in view.note.object
