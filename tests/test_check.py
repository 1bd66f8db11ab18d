"""Physics check of plans: safe plans, the failing leg of unsafe ones, empty and malformed routes."""

from __future__ import annotations

import numpy as np
import pytest

from uam_studio.battery import simulate
from uam_studio.errors import InputError
from uam_studio.flight import leg_profile
from uam_studio.planning.missions.check import Plan, check_plan, make_plan
from uam_studio.planning.missions.mission import Battery, Destination, Mission, Vertiport


def bay(q_max=6000.0, r0=0.15) -> Mission:
    return Mission(
        "bay",
        Vertiport(0.0, 0.0, 10.0),
        (
            Destination("Richmond", 25.0, 0.0, 2, 20.0),
            Destination("Oakland", 25.0, 30.0, 1, -13.0),
            Destination("Napa", -10.0, 40.0, 3, 39.0, dwell_s=120.0),
        ),
        "single_charge",
        Battery(q_max, r0),
    )


def test_safe_plan():
    m = bay(7600.0, 0.05)
    c = check_plan(m, ["Richmond", "vertiport"], [500.0, 1000.0])
    assert c.safe and c.fail_leg is None and c.fail_to is None and c.fail_time_s is None
    assert c.margin_v == pytest.approx(c.min_voltage_v - 3.0) and c.margin_v > 0
    assert c.message.startswith("safe: minimum") and c.sim.charging_cycles == 1


def test_unsafe_plan_names_the_failing_leg():
    m = bay()
    route = ["Richmond", "Oakland", "Napa", "vertiport"]
    alts = [500.0, 1000.0, 2000.0, 500.0]
    c = check_plan(m, route, alts)
    assert not c.safe
    # independent reference: one simulate call on the concatenated leg currents
    nodes = ["vertiport", *route]
    currents = [leg_profile(m.distance_km(a, b), h, m.leg_wind(b), 1.0, getattr(m.node(b), "dwell_s", 0.0)).current_a
                for a, b, h in zip(nodes, nodes[1:], alts)]
    ref = simulate(np.concatenate(currents), 1.0, m.battery.q_max, m.battery.r0, m.eod_v)
    assert ref.eod_reached
    ends = np.cumsum([len(x) for x in currents])
    leg = int(np.searchsorted(ends, ref.eod_s, side="left"))  # eod_s = index + 1 on the 1 s grid
    assert (c.fail_leg, c.fail_to) == (leg, route[leg])
    assert c.fail_time_s == pytest.approx(ref.eod_s)
    assert c.margin_v < 0 and c.min_voltage_v < 3.0
    assert c.message == f"unsafe: voltage falls below 3.00 V at {ref.eod_s:.0f} s on leg {leg + 1} to {route[leg]}"


def test_recharge_resets_the_cell():
    m = bay()
    # the same two legs fail without a landing in between and pass with one
    assert not check_plan(m, ["Napa", "Richmond", "Napa"], [500.0] * 3).safe
    c = check_plan(m, ["Napa", "vertiport", "Richmond", "vertiport"], [500.0] * 4)
    assert c.safe and c.sim.charging_cycles == 2


def test_overrides_battery_and_cut_off():
    m = bay(7600.0, 0.05)
    assert check_plan(m, ["Napa", "vertiport"], [500.0, 500.0]).safe
    assert not check_plan(m, ["Napa", "vertiport"], [500.0, 500.0], q_max=5000.0, r0=0.33).safe
    assert not check_plan(m, ["Napa", "vertiport"], [500.0, 500.0], eod_v=3.7).safe


def test_empty_and_malformed_routes():
    c = check_plan(bay(), [], [])
    assert c.safe and c.sim is None and c.message.startswith("empty plan")
    with pytest.raises(InputError, match="unknown node"):
        check_plan(bay(), ["Sacramento"], [500.0])
    with pytest.raises(InputError, match="altitudes"):
        check_plan(bay(), ["Napa"], [500.0, 500.0])


def test_make_plan_reads_reached_and_cycles_from_physics():
    m = bay()
    p = make_plan(m, "test", ["Richmond", "Oakland", "Napa", "vertiport"], [500.0, 1000.0, 2000.0, 500.0])
    assert isinstance(p, Plan) and not p.stats["safe"] and p.messages[-1].startswith("unsafe")
    c = check_plan(m, p.route, p.altitudes_m)
    assert len(p.reached) == c.fail_leg and p.charging_cycles == 0
    ok = make_plan(bay(7600.0, 0.05), "test", ["Napa", "vertiport", "Oakland", "vertiport"], [500.0] * 4)
    assert ok.reached == ("Napa", "Oakland") and ok.reached_priority == 4 and ok.charging_cycles == 2
    assert ok.to_dict()["route"] == ["Napa", "vertiport", "Oakland", "vertiport"]


def test_each_override_alone_changes_the_flight():
    """q_max, R0 and the cut-off each reach the physics on their own (none is dropped or swapped)."""
    m = bay(7600.0, 0.05)
    route, alts = ["Napa", "vertiport"], [500.0, 500.0]
    base = check_plan(m, route, alts)
    same = check_plan(m, route, alts, q_max=7600.0, r0=0.05, eod_v=m.eod_v)
    assert same.min_voltage_v == base.min_voltage_v and same.safe is base.safe is True
    weak_q = check_plan(m, route, alts, q_max=6000.0)
    weak_r = check_plan(m, route, alts, r0=0.2)
    assert weak_q.min_voltage_v < base.min_voltage_v - 0.01
    assert weak_r.min_voltage_v < base.min_voltage_v - 0.05
    assert weak_q.min_voltage_v != weak_r.min_voltage_v
    high_cut = check_plan(m, route, alts, eod_v=3.7)
    assert high_cut.safe is False and high_cut.margin_v == pytest.approx(high_cut.min_voltage_v - 3.7)
    assert base.margin_v == pytest.approx(base.min_voltage_v - m.eod_v) and base.margin_v > 0


def test_check_messages_count_legs_and_landings():
    m = bay(7600.0, 0.05)
    one = check_plan(m, ["Napa"], [500.0])
    assert one.message.endswith("(1 leg, 0 landings at the vertiport)"), one.message
    two = check_plan(m, ["Napa", "vertiport"], [500.0, 500.0])
    assert two.message.endswith("(2 legs, 1 landing at the vertiport)"), two.message
    assert two.message.startswith(f"safe: minimum {two.min_voltage_v:.2f} V, {two.margin_v:.2f} V above the "
                                  f"{m.eod_v:.2f} V cut-off")
    bad = check_plan(bay(5000.0, 0.4), ["Napa", "vertiport"], [500.0, 500.0])
    assert bad.safe is False and bad.fail_leg == 0 and bad.fail_to == "Napa"
    assert bad.message == f"unsafe: voltage falls below {m.eod_v:.2f} V at {bad.fail_time_s:.0f} s on leg 1 to Napa"


def test_altitudes_without_a_route_are_refused():
    with pytest.raises(InputError, match="route"):
        check_plan(bay(), [], [500.0])


def test_make_plan_stats_and_check():
    m = bay(7600.0, 0.05)
    p = make_plan(m, "greedy", ["Napa", "vertiport"], [500.0, 500.0], messages=["note"], stats={"x": 1})
    c = p.check
    assert p.policy == "greedy" and c is not None and c.safe is True
    assert p.stats == {"x": 1, "flight_time_s": float(c.sim.time_s[-1]), "safe": True,
                       "min_voltage_v": c.min_voltage_v, "margin_v": c.margin_v}
    assert p.stats["flight_time_s"] > 600.0 and p.messages == ("note",)  # a safe plan adds no message
    assert p.reached == ("Napa",) and p.reached_priority == 3 and p.charging_cycles == 1
    empty = make_plan(m, "greedy", [], [])
    assert empty.charging_cycles == 0 and empty.reached == () and empty.reached_priority == 0
    assert empty.stats == {"safe": True, "min_voltage_v": None, "margin_v": None}


def test_plan_holds_tuples_of_floats():
    p = Plan("x", ["Napa", "vertiport"], [500, 1000], ["Napa"], 3, 1, ["a"])
    assert p.route == ("Napa", "vertiport") and p.reached == ("Napa",) and p.messages == ("a",)
    assert p.altitudes_m == (500.0, 1000.0) and all(type(a) is float for a in p.altitudes_m)
