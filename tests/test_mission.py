"""Tests for uam_studio.planning: mission format, validation, atomic save, route simulation."""

from __future__ import annotations

import copy
import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from uam_studio.battery import rest_voltage, simulate
from uam_studio.errors import InputError
from uam_studio.flight import leg_profile
from uam_studio.planning import (
    Battery,
    Destination,
    Mission,
    Vertiport,
    load_mission,
    mission_from_dict,
    mission_to_dict,
    save_mission,
    simulate_route,
)

EXAMPLE = Path(__file__).resolve().parents[1] / "assets" / "example_mission.json"


def small_dict() -> dict:
    return {
        "name": "Test",
        "vertiport": {"x_km": 0.0, "y_km": 0.0, "wind_kts": 5.0},
        "destinations": [
            {"name": "A", "x_km": 20.0, "y_km": 0.0, "priority": 1, "wind_kts": -13.0},
            {"name": "B", "x_km": 20.0, "y_km": 30.0, "priority": 3, "wind_kts": 26.0, "dwell_s": 120.0},
            {"name": "C", "x_km": 0.0, "y_km": 8.0, "priority": 2, "wind_kts": 0.0},
        ],
        "scenario": "multi_charge",
        "battery": {"q_max": 7600.0, "r0": 0.117215},
        "eod_v": 3.0,
    }


@pytest.fixture
def mission() -> Mission:
    return mission_from_dict(small_dict())


# --------------------------------------------------------------------------- format


def test_example_mission_loads_and_is_realistic():
    m = load_mission(EXAMPLE)
    assert len(m.destinations) == 4 and m.scenario == "single_charge"
    assert m.battery == Battery(7600.0, 0.117215) and m.eod_v == 3.0
    dists = [m.distance_km("vertiport", d.name) for d in m.destinations]
    assert all(20.0 <= x <= 60.0 for x in dists), dists
    assert len({d.priority for d in m.destinations}) > 1


def test_dict_round_trip(mission):
    d = mission_to_dict(mission)
    assert json.loads(json.dumps(d)) == d  # plain JSON types only
    assert mission_from_dict(d) == mission
    assert d["destinations"][0]["dwell_s"] == 0.0  # optional field defaults and is written out
    assert mission.destinations[1].dwell_s == 120.0


def test_file_round_trip(mission, tmp_path):
    path = tmp_path / "m.json"
    save_mission(mission, path)
    assert load_mission(path) == mission
    assert json.loads(path.read_text()) == mission_to_dict(mission)


def test_zero_destinations_allowed():
    d = small_dict()
    d["destinations"] = []
    m = mission_from_dict(d)
    assert m.destinations == () and m.node_names == ("vertiport",)


def test_at_most_twenty_destinations_in_a_file(tmp_path):
    d = small_dict()
    d["destinations"] = [{"name": f"P{k}", "x_km": -150.0 + 8 * k, "y_km": 10.0, "priority": 1, "wind_kts": 0.0}
                         for k in range(21)]
    with pytest.raises(InputError) as err:
        mission_from_dict(d)
    assert str(err.value) == "destinations: 21 destinations; allowed 1 to 20"
    path = tmp_path / "many.json"
    path.write_text(json.dumps(d))
    with pytest.raises(InputError, match=r"^destinations: 21 destinations; allowed 1 to 20$"):
        load_mission(path)
    d["destinations"].pop()
    assert len(mission_from_dict(d).destinations) == 20


@pytest.mark.parametrize("n", [21, 25, 60])
def test_a_mission_itself_holds_at_most_twenty_destinations(n):
    """The limit lives in Mission: built directly (not from a file), 21 or more are refused the same way."""
    dests = tuple(Destination(f"P{k}", -150.0 + 5 * k, 10.0, 1, 0.0) for k in range(n))
    with pytest.raises(InputError) as err:
        Mission("many", Vertiport(0.0, 0.0), dests)
    assert str(err.value) == f"destinations: {n} destinations; allowed 1 to 20"
    assert len(Mission("twenty", Vertiport(0.0, 0.0), dests[:20]).destinations) == 20


def test_generator_draws_up_to_twenty_destinations_and_keeps_small_draws():
    from uam_studio.planning import held_out_missions, random_mission
    from uam_studio.planning.missions.generate import MIN_SEPARATION_KM

    (m,) = held_out_missions(1, 9494, n_dest=(20, 20), scenario="multi_charge")
    pts = [(d.x_km, d.y_km) for d in m.destinations]
    assert len(pts) == 20 and min(math.dist(a, b) for i, a in enumerate(pts) for b in pts[:i]) >= MIN_SEPARATION_KM
    with pytest.raises(InputError, match=r"^n_dest: .*<= 20$"):
        random_mission(np.random.default_rng(0), (1, 21))
    # draws of 6-8 destinations are those from before the limit was 20 (values from that version)
    (small,) = held_out_missions(1, 20261121)
    assert len(small.destinations) == 7 and small.battery == Battery(6976.6, 0.08817)
    assert [(d.name, d.x_km, d.y_km, d.priority) for d in small.destinations[:2]] == [
        ("D1", 7.5, -43.1, 2), ("D2", -42.0, -11.5, 1)]


def test_integral_float_priority_accepted():
    d = small_dict()
    d["destinations"][0]["priority"] = 2.0
    p = mission_from_dict(d).destinations[0].priority
    assert p == 2 and isinstance(p, int)


def _set(path: str, value):
    """Return an editor that sets (or with value=KeyError deletes) a dotted/indexed path."""

    def edit(d):
        keys = [int(k) if k.isdigit() else k for k in path.replace("[", ".").replace("]", "").split(".")]
        obj = d
        for k in keys[:-1]:
            obj = obj[k]
        if value is KeyError:
            del obj[keys[-1]]
        else:
            obj[keys[-1]] = value

    return edit


@pytest.mark.parametrize(
    ("path", "value", "field", "text"),
    [
        ("destinations[2].priority", 4, "destinations[2].priority", "4 is out of range; allowed [1, 3]"),
        ("destinations[2].priority", 0, "destinations[2].priority", "allowed [1, 3]"),
        ("destinations[2].priority", 1.5, "destinations[2].priority", "integer"),
        ("destinations[2].priority", True, "destinations[2].priority", "integer"),
        ("destinations[0].wind_kts", 39.5, "destinations[0].wind_kts", "[-39, 39]"),
        ("vertiport.wind_kts", -40, "vertiport.wind_kts", "[-39, 39]"),
        ("destinations[1].x_km", 200.5, "destinations[1].x_km", "[-200, 200]"),
        ("vertiport.y_km", -201, "vertiport.y_km", "[-200, 200]"),
        ("destinations[1].y_km", "30", "destinations[1].y_km", "expected a number"),
        ("destinations[1].dwell_s", -1, "destinations[1].dwell_s", "out of range"),
        ("destinations[1].name", "", "destinations[1].name", "empty"),
        ("destinations[1].name", "A", "destinations[1].name", "unique"),
        ("destinations[1].name", "vertiport", "destinations[1].name", "reserved"),
        ("destinations[1].name", "A,B", "destinations[1].name", "comma"),
        ("destinations[1].name", 7, "destinations[1].name", "string"),
        ("destinations[1].y_km", KeyError, "destinations[1].y_km", "missing"),
        ("destinations[0].dwel_s", 5, "destinations[0].dwel_s", "unknown field"),
        ("destinations[0]", "A", "destinations[0]", "JSON object"),
        ("destinations", {}, "destinations", "list"),
        ("vertiport", KeyError, "vertiport", "missing"),
        ("name", "", "name", "empty"),
        ("scenario", "round_trip", "scenario", "single_flight, single_charge, multi_charge"),
        ("battery.q_max", 0, "battery.q_max", "out of range"),
        ("battery.q_max", -5.0, "battery.q_max", "out of range"),
        ("battery.q_max", float("nan"), "battery.q_max", "out of range"),
        ("battery.r0", None, "battery.r0", "expected a number"),
        ("battery.r0", 6.0, "battery.r0", "out of range"),
        ("battery", KeyError, "battery", "missing"),
        ("eod_v", 4.5, "eod_v", "out of range"),
        ("eod_v", KeyError, "eod_v", "missing"),
    ],
)
def test_validation_names_the_path(path, value, field, text):
    d = small_dict()
    _set(path, value)(d)
    with pytest.raises(InputError) as info:
        mission_from_dict(d)
    assert info.value.field == field
    msg = str(info.value)
    assert msg.startswith(f"{field}: ") and text in msg and "\n" not in msg


def test_top_level_must_be_object():
    with pytest.raises(InputError, match="^mission: expected a JSON object"):
        mission_from_dict([1, 2])


def test_dataclasses_validate_directly():
    with pytest.raises(InputError, match="^priority:"):
        Destination("A", 1.0, 1.0, 5)
    with pytest.raises(InputError, match="^q_max:"):
        Battery(q_max=0.0)
    with pytest.raises(InputError, match=r"^destinations\[1\]\.name: .*unique"):
        Mission("m", Vertiport(0, 0), (Destination("A", 1, 1, 1), Destination("A", 2, 2, 1)))


def test_mission_accessors(mission):
    assert mission.distance_km("vertiport", "B") == pytest.approx(math.hypot(20.0, 30.0))
    assert mission.distance_km("A", "B") == pytest.approx(30.0)
    assert mission.distance_km("B", "A") == mission.distance_km("A", "B")
    assert mission.leg_wind("A") == -13.0
    assert mission.leg_wind("vertiport") == 5.0
    assert mission.node("B").dwell_s == 120.0
    with pytest.raises(InputError, match="valid names: vertiport, A, B, C"):
        mission.node("Z")
    m2 = mission.with_battery(q_max=6000.0)
    assert m2.battery == Battery(6000.0, mission.battery.r0) and mission.battery.q_max == 7600.0
    assert mission.with_battery(r0=0.2).battery.r0 == 0.2
    with pytest.raises(InputError, match="^r0:"):
        mission.with_battery(r0=-1.0)


# --------------------------------------------------------------------------- files


def test_malformed_json_names_line_and_column(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text('{\n  "name": "x",\n  "eod_v": 3.0,,\n}\n')
    with pytest.raises(InputError) as info:
        load_mission(path)
    assert info.value.field == "file"
    assert "line 3, column 16" in str(info.value)


def test_missing_file_and_duplicate_keys(tmp_path):
    with pytest.raises(InputError, match="^file: .*does not exist"):
        load_mission(tmp_path / "nope.json")
    path = tmp_path / "dup.json"
    path.write_text('{"name": "a", "name": "b"}')
    with pytest.raises(InputError, match="^file: duplicate key 'name'"):
        load_mission(path)


def test_save_is_atomic_and_leaves_no_temp_files(mission, tmp_path, monkeypatch):
    path = tmp_path / "m.json"
    save_mission(mission, path)
    save_mission(mission.with_battery(q_max=5000.0), path)  # overwrite in place
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.json"]
    assert load_mission(path).battery.q_max == 5000.0

    # A failure before the rename keeps the old file intact and removes the temp file.
    def boom(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        save_mission(mission, path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.json"]
    assert load_mission(path).battery.q_max == 5000.0


# --------------------------------------------------------------------------- route simulation


def _leg_current(mission: Mission, frm: str, to: str, alt: float, dt: float = 1.0) -> np.ndarray:
    node = mission.node(to)
    return leg_profile(mission.distance_km(frm, to), alt, mission.leg_wind(to), dt,
                       getattr(node, "dwell_s", 0.0)).current_a


def test_route_without_recharge_equals_one_simulate_call(mission):
    route, alts = ["A", "B", "C"], [1000.0, 2000.0, 500.0]
    sim = simulate_route(mission, route, alts)
    cur = np.concatenate([_leg_current(mission, f, t, a) for f, t, a in
                          zip(["vertiport", *route[:-1]], route, alts, strict=True)])
    ref = simulate(cur, 1.0, 7600.0, 0.117215, 3.0)
    assert not ref.eod_reached and sim.safe and sim.eod_s is None
    np.testing.assert_array_equal(sim.current_a, cur)
    np.testing.assert_allclose(sim.voltage_v, ref.voltage_v, rtol=0, atol=1e-9)
    np.testing.assert_allclose(sim.time_s, ref.time_s, rtol=0, atol=1e-9)
    assert sim.valid.all() and sim.charging_cycles == 0
    # Legs tile the timeline and their minima come from their own samples.
    assert sim.legs[0].start_s == 0.0 and sim.legs[-1].end_s == pytest.approx(sim.time_s[-1])
    for a, b in zip(sim.legs, sim.legs[1:]):
        assert a.end_s == b.start_s
    for leg in sim.legs:
        mask = (sim.time_s > leg.start_s) & (sim.time_s <= leg.end_s)
        assert leg.reached and leg.min_voltage_v == pytest.approx(sim.voltage_v[mask].min())
    # B's dwell is flown at zero current after landing.
    b_end = int(round(sim.legs[1].end_s))
    assert np.all(sim.current_a[b_end - 119:b_end] == 0.0)


def test_recharge_at_vertiport_resets_the_cell(mission):
    sim = simulate_route(mission, ["B", "vertiport", "A"], [1000.0, 1000.0, 500.0])
    assert sim.charging_cycles == 1 and sim.safe
    leg3 = sim.legs[2]
    k0 = int(round(leg3.start_s))  # index of the first sample of leg 3
    v_before, v_first = sim.voltage_v[k0 - 1], sim.voltage_v[k0]
    assert v_before < 3.8
    # One 1 s step of take-off current after a full recharge: ~0.06 V under the 4.19 V rest voltage.
    assert v_first == pytest.approx(rest_voltage(7600.0), abs=0.1)
    assert v_first - v_before > 0.3
    # With a fine step the first sample after the recharge is the rest voltage itself.
    fine = simulate_route(mission, ["C", "vertiport", "C"], [500.0] * 3, dt_s=0.01)
    k = int(round(fine.legs[2].start_s / 0.01))
    assert fine.voltage_v[k - 1] < 4.0
    assert fine.voltage_v[k] == pytest.approx(rest_voltage(7600.0), abs=2e-3)
    # Leg 3 is exactly a fresh-cell simulation of its own current.
    fresh = simulate(_leg_current(mission, "vertiport", "A", 500.0), 1.0, 7600.0, 0.117215, 3.0)
    np.testing.assert_allclose(sim.voltage_v[k0:], fresh.voltage_v, rtol=0, atol=1e-9)


def test_eod_stops_the_flight_and_reports_remaining_legs(mission):
    route = ["B", "A", "B", "A", "vertiport"]
    sim = simulate_route(mission, route, [500.0] * 5, q_max=5000.0)
    assert not sim.safe and sim.eod_s is not None
    assert sim.eod_s == pytest.approx(sim.time_s[-1])  # arrays stop at the EOD sample
    assert sim.voltage_v[-1] < 3.0 and np.all(sim.voltage_v[:-1] >= 3.0)
    assert sim.valid[:-1].all() and not sim.valid[-1]
    assert len(sim.legs) == 5
    eod_leg = next(i for i, g in enumerate(sim.legs) if not g.reached)
    g = sim.legs[eod_leg]
    assert g.start_s is not None and g.end_s is None and g.min_voltage_v < 3.0
    assert g.start_s < sim.eod_s
    for g in sim.legs[eod_leg + 1:]:
        assert (g.start_s, g.end_s, g.min_voltage_v, g.reached) == (None, None, None, False)
    assert sim.charging_cycles == 0
    # Same EOD as one simulate call over the whole (unrecharged) route.
    cur = np.concatenate([_leg_current(mission, f, t, 500.0) for f, t in
                          zip(["vertiport", *route[:-1]], route, strict=True)])
    ref = simulate(cur, 1.0, 5000.0, 0.117215, 3.0)
    assert ref.eod_reached and ref.eod_s == pytest.approx(sim.eod_s)


def test_overrides_and_dt(mission):
    base = simulate_route(mission, ["A", "vertiport"], [500.0, 500.0])
    worn = simulate_route(mission, ["A", "vertiport"], [500.0, 500.0], q_max=6000.0, r0=0.3)
    assert worn.min_voltage_v < base.min_voltage_v - 0.05
    late = simulate_route(mission, ["A", "vertiport"], [500.0, 500.0], eod_v=3.7)
    assert not late.safe
    fine = simulate_route(mission, ["A", "vertiport"], [500.0, 500.0], dt_s=0.5)
    assert fine.time_s[1] - fine.time_s[0] == 0.5
    assert fine.legs[-1].end_s == pytest.approx(base.legs[-1].end_s, abs=1.0)
    assert fine.min_voltage_v == pytest.approx(base.min_voltage_v, abs=2e-3)


def test_to_dict_is_plain_json(mission):
    sim = simulate_route(mission, ["A", "vertiport"], [500.0, 1000.0])
    d = sim.to_dict()
    assert list(d) == ["time_s", "current_a", "voltage_v", "eod_s", "safe", "complete", "legs"]
    assert d["eod_s"] is None and d["safe"] is True and d["complete"] is True
    for key in ("time_s", "current_a", "voltage_v"):
        assert isinstance(d[key], list) and len(d[key]) == len(sim.time_s)
        assert all(type(x) is float for x in d[key])
    assert d["voltage_v"][5] == round(float(sim.voltage_v[5]), 6)
    assert [set(g) for g in d["legs"]] == [{"to", "altitude_m", "start_s", "end_s", "min_voltage_v"}] * 2
    assert d["legs"][1]["to"] == "vertiport" and d["legs"][1]["altitude_m"] == 1000.0
    assert json.loads(json.dumps(d, allow_nan=False)) == d

    unsafe = simulate_route(mission, ["B", "A", "B", "A"], [500.0] * 4, q_max=5000.0).to_dict()
    assert isinstance(unsafe["eod_s"], float)
    assert unsafe["legs"][-1]["start_s"] is None and unsafe["legs"][-1]["end_s"] is None
    json.dumps(unsafe, allow_nan=False)


@pytest.mark.parametrize(
    ("route", "alts", "field", "text"),
    [
        (["A", "Z"], [500, 500], "route", "unknown node 'Z'; valid names: vertiport, A, B, C"),
        ([], [], "route", "empty"),
        ("A", [500], "route", "list"),
        (["A", "A"], [500, 500], "route", "leg 2 (A -> A) has zero length"),
        (["vertiport"], [500], "route", "leg 1 (vertiport -> vertiport) has zero length"),
        (["A", "B"], [500], "altitudes", "has 1 value but the route has 2 legs"),
        (["A"], [499], "altitudes[0]", "[500, 3000]"),
        (["A", "B"], [500, "high"], "altitudes[1]", "expected a number"),
        (["C"], [1000], "altitudes[0]", "leg 1 (vertiport -> C) is 8.0 km, too short to cruise at 1000 m"),
    ],
)
def test_route_validation(mission, route, alts, field, text):
    with pytest.raises(InputError) as info:
        simulate_route(mission, route, alts)
    assert info.value.field == field and text in str(info.value)


def test_colocated_nodes_are_a_zero_length_leg():
    d = small_dict()
    d["destinations"][2].update(x_km=20.0, y_km=0.0)  # C on top of A
    m = mission_from_dict(copy.deepcopy(d))
    with pytest.raises(InputError, match="^route: leg 2 .*same place"):
        simulate_route(m, ["A", "C"], [500, 500])


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [({"q_max": 0.0}, "q_max"), ({"r0": -0.1}, "r0"), ({"eod_v": 2.0}, "eod_v"), ({"dt_s": 0.0}, "dt_s"),
     ({"dt_s": 0.001}, "dt_s")],
)
def test_simulation_parameter_validation(mission, kwargs, field):
    route = ["B", "A", "B", "A", "vertiport"] * 3 if kwargs.get("dt_s") == 0.001 else ["A"]
    with pytest.raises(InputError) as info:
        simulate_route(mission, route, [500.0] * len(route), **kwargs)
    assert info.value.field == field


def test_a_route_that_does_not_return_is_not_complete(mission):
    part = simulate_route(mission, ["A"], [500.0])
    assert part.safe and not part.complete and part.to_dict()["complete"] is False
    assert simulate_route(mission, ["A", "vertiport", "A"], [500.0] * 3).complete is False
    assert simulate_route(mission, ["A", "vertiport"], [500.0] * 2).complete is True
